"""The EKF baseline of the point-depth problem (Spica, Robuffo Giordano and Chaumette,
*Active Structure from Motion*): `InverseDepthModel`, one point's image coordinates and
inverse depth under the camera's known twist, for `extended_kalman_filter`."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..estimators import point_depth_rate, point_model
from ._ekf import AbstractEKFModel


class InverseDepthModel(AbstractEKFModel):
    """The EKF baseline's model of one point (planar projection), state $(x, y, \\chi)$:
    the transition is an Euler step of the model (`visjax.estimators.point_model`) under the held
    camera twist `u` (6,), the measurement is $(x, y)$. `q_s`, `q_chi`: the process noise
    densities of the image coordinates and of the inverse depth (per second); `r` the
    measurement variance (normalized coordinates squared)."""

    q_s: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    q_chi: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    r: Float[Array, ""] = eqx.field(converter=jnp.asarray)

    def transition(self, x, u, dt):
        s, chi = x[:2], x[2]
        f_m, omega = point_model(s, u, "planar")
        s_dot = f_m + omega * chi
        return jnp.concatenate([s + dt * s_dot, (chi + dt * point_depth_rate(s, chi, u))[None]])

    def process_noise(self, x, u, dt):
        return jnp.diag(jnp.stack([self.q_s, self.q_s, self.q_chi])) * dt

    def measure(self, x, u):
        return x[:2]

    def measurement_noise(self, x, u):
        return self.r * jnp.eye(2, dtype=x.dtype)

    def valid(self, x, u):
        return x[2] > 0
