"""A simulation for seed 004: a camera on a moving platform looking at static features.

The platform (an end effector) moves on an exciting trajectory: it translates on a
Lissajous figure and rotates about all three axes, while the camera, mounted with an
unknown rotation and offset, keeps several known and unknown static features in view.
The estimator is given the platform pose and the pixels; the truth is in the scenario.

Choices (the paper refers its simulation to [28]): camera $f = 8$ mm, $k_u = k_v = 10^5$
px/m, skew angle $\\phi = 88°$, principal point (320, 240); $R_c$ a 5° rotation, $x_c =
[0.05, -0.03, 0.10]$ m; six known features and four unknown ones on a 0.4 m x 0.3 m patch
about 1.5 m in front of the platform, with 0.25 m of relief; the platform moves by
up to 0.1 m and 0.1 rad at 0.2-0.5 Hz. `exciting=False` gives pure translation along the
optical axis (a trajectory that does not excite the regressors).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from ..geometry import (
    camera_parameters,
    feature_in_camera,
    intrinsics_eq4,
    project,
    so3_exp,
)


class UncalibratedScenario(eqx.Module):
    """Measured: `ts`, `R_b` (N,3,3), `x_b` (N,3), `p_s` (N,n,2), `p_c` (N,m,2), `omega_c`
    (m,3). Truth: `omega_s` (n,3), `A`, `R_c`, `x_c`, `theta_c1`, `theta_c2`."""

    ts: Float[Array, " N"]
    R_b: Float[Array, "N 3 3"]
    x_b: Float[Array, "N 3"]
    p_s: Float[Array, "N n 2"]
    p_c: Float[Array, "N m 2"]
    omega_c: Float[Array, "m 3"]
    omega_s: Float[Array, "n 3"]
    A: Float[Array, "3 3"]
    R_c: Float[Array, "3 3"]
    x_c: Float[Array, "3"]
    theta_c1: Float[Array, "12"]
    theta_c2: Float[Array, "4"]


def uncalibrated_scenario(
    duration: float = 20.0,
    rate_hz: float = 1000.0,
    *,
    noise_px: float = 0.0,
    key: PRNGKeyArray | None = None,
    exciting: bool = True,
) -> UncalibratedScenario:
    """The seed-004 scenario (module docstring), sampled at `rate_hz`."""
    if noise_px > 0 and key is None:
        raise ValueError("`key` is required when `noise_px > 0`.")
    n_samples = int(round(duration * rate_hz))
    ts = jnp.arange(n_samples, dtype=jnp.result_type(float)) / rate_hz
    A = intrinsics_eq4(0.008, 1e5, 1e5, jnp.deg2rad(88.0), 320.0, 240.0)
    R_c = so3_exp(jnp.deg2rad(5.0) * jnp.array([0.6, -0.8, 0.0]))
    x_c = jnp.array([0.05, -0.03, 0.10])
    omega_c = jnp.array(
        [
            [-0.2, -0.12, 1.5],
            [0.15, -0.15, 1.55],
            [0.15, 0.1, 1.45],
            [-0.2, 0.12, 1.6],
            [0.0, -0.05, 1.65],
            [0.05, 0.02, 1.4],
        ]
    )
    omega_s = jnp.array(
        [[-0.1, 0.03, 1.52], [0.1, -0.08, 1.6], [0.02, 0.1, 1.45], [-0.12, -0.07, 1.58]]
    )

    def pose(t):
        if exciting:
            x = jnp.array(
                [
                    0.08 * jnp.sin(0.4 * jnp.pi * t),
                    0.06 * jnp.sin(0.6 * jnp.pi * t),
                    0.1 * jnp.sin(0.4 * jnp.pi * t + 1.0),
                ]
            )
            w = jnp.array(
                [
                    0.06 * jnp.sin(0.5 * jnp.pi * t),
                    0.06 * jnp.cos(0.7 * jnp.pi * t) - 0.06,
                    0.1 * jnp.sin(jnp.pi * t),
                ]
            )
            return so3_exp(w), x
        return jnp.eye(3), jnp.array([0.0, 0.0, 0.2 * jnp.sin(0.5 * t)])

    R_b, x_b = jax.vmap(pose)(ts)

    def pixels(R_b, x_b, omega):
        m_bar = jax.vmap(lambda w: feature_in_camera(w, R_b, x_b, R_c, x_c))(omega)
        return project(m_bar, A)

    p_s = jax.vmap(pixels, in_axes=(0, 0, None))(R_b, x_b, omega_s)
    p_c = jax.vmap(pixels, in_axes=(0, 0, None))(R_b, x_b, omega_c)
    if noise_px > 0:
        k1, k2 = jax.random.split(key)
        p_s = p_s + noise_px * jax.random.normal(k1, p_s.shape)
        p_c = p_c + noise_px * jax.random.normal(k2, p_c.shape)
    t1, t2 = camera_parameters(A, R_c, x_c)
    return UncalibratedScenario(ts, R_b, x_b, p_s, p_c, omega_c, omega_s, A, R_c, x_c, t1, t2)
