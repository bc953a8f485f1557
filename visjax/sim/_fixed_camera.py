"""The simulation of seed 000, section 6: a planar object moving in front of a fixed camera.

Exactly as the paper states it: velocity $v_i = 0.2 \\sin t$ on all six degrees of freedom,
expressed in the camera frame (eq. (59)); $s_1 = [-0.1, 0.1, 0.01]$; $x_f^* = [0, 0, 2]$
(eq. (60)); $R^* = \\mathrm{diag}(1, -1, -1)$ (eq. (61)); $A$ of eq. (62); 1 kHz. The object
starts at the reference pose.

What the paper leaves open, chosen here:

- The other three features: $s_2 = [0.1, 0.1, 0]$, $s_3 = -s_1 = [0.1, -0.1, -0.01]$,
  $s_4 = -s_2$. The four are the corners of a 0.2 m square, coplanar with the object-frame
  origin at the intersection of its diagonals; the plane is tilted so that $s_1$ has
  $z = 0.01$ (object-frame normal $\\propto [0.05, -0.05, 1]$). The origin's image is then the
  intersection of the image diagonals, which makes $z_1^*$ recoverable from $s_1$ (see
  `visjax.estimators.depth_from_known_length`).
- The pose is integrated with an 8th-order solver at tolerance 1e-12; for eq. (59) it also
  has the closed form $x_f = x_f^* + 0.2(1 - \\cos t)\\mathbf 1$,
  $R = \\exp(0.2(1 - \\cos t)[1, 1, 1]^\\wedge) R^*$ (a test compares the two).
- Pixel noise, if asked for, is i.i.d. Gaussian on every coordinate of every frame,
  including the reference frame 0.
"""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from ..geometry import project
from ..kinematics import integrate_pose

A_EQ62 = ((1268.16, 0.0, 257.49), (0.0, 1267.50, 253.10), (0.0, 0.0, 1.0))
R_STAR_EQ61 = ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0))
X_F_STAR_EQ60 = (0.0, 0.0, 2.0)
FEATURES = (
    (-0.1, 0.1, 0.01),  # s_1, section 6
    (0.1, 0.1, 0.0),
    (0.1, -0.1, -0.01),
    (-0.1, -0.1, 0.0),
)
K_EQ63 = (300.0, 300.0, 200.0, 15.0, 15.0, 15.0)
RHO_EQ63 = (100.0, 100.0, 10.0, 1.0, 1.0, 1.0)


class FixedCameraScenario(eqx.Module):
    """Sampled measurements and ground truth of a fixed-camera scenario.

    **Fields:** `ts` (N,); `pixels` (N, 4, 2), feature 1 first, frame 0 the reference
    image; `velocity` (N, 6) true $[v_e, \\omega_e]$; `x_f` (N, 3) and `R` (N, 3, 3) true
    poses; `A`; `R_star`; `x_f_star`; `s` (4, 3) features in the object frame; `n_star` the
    true plane normal; `z1_star` the true reference depth of feature 1.
    """

    ts: Float[Array, " N"]
    pixels: Float[Array, "N 4 2"]
    velocity: Float[Array, "N 6"]
    x_f: Float[Array, "N 3"]
    R: Float[Array, "N 3 3"]
    A: Float[Array, "3 3"]
    R_star: Float[Array, "3 3"]
    x_f_star: Float[Array, "3"]
    s: Float[Array, "4 3"]
    n_star: Float[Array, "3"]
    z1_star: Float[Array, ""]


def section6_velocity(t: Array) -> Array:
    """Eq. (59): $v_i = 0.2 \\sin t$ for all six degrees of freedom."""
    return 0.2 * jnp.sin(t) * jnp.ones(6, dtype=jnp.result_type(t, float))


def fixed_camera_scenario(
    duration: float = 10.0,
    rate_hz: float = 1000.0,
    *,
    noise_px: float = 0.0,
    key: PRNGKeyArray | None = None,
    velocity: Callable[[Array], Array] = section6_velocity,
) -> FixedCameraScenario:
    """The section-6 simulation: N = round(duration * rate_hz) samples at t_k = k / rate_hz.

    **Arguments:**

    - `duration`: seconds (10 in the paper).
    - `rate_hz`: the sample rate (1000 in the paper).
    - `noise_px`: standard deviation of pixel noise (0: noise-free, as in the paper).
    - `key`: PRNG key for the noise (required when `noise_px > 0`).
    - `velocity`: $t \\mapsto [v_e, \\omega_e]$; eq. (59) by default.
    """
    n = int(round(duration * rate_hz))
    if n < 2:
        raise ValueError(f"duration * rate_hz must give at least 2 samples; got {n}.")
    if noise_px > 0 and key is None:
        raise ValueError("`key` is required when `noise_px > 0`.")
    dtype = jnp.result_type(float)
    ts = jnp.arange(n, dtype=dtype) / rate_hz
    A = jnp.array(A_EQ62, dtype)
    R_star = jnp.array(R_STAR_EQ61, dtype)
    x_f_star = jnp.array(X_F_STAR_EQ60, dtype)
    s = jnp.array(FEATURES, dtype)
    x_f, R = integrate_pose(velocity, x_f_star, R_star, ts)
    points = x_f[:, None, :] + jnp.einsum("nij,kj->nki", R, s)  # eq. (5)
    pixels = jax.vmap(lambda P: project(P, A))(points)
    if noise_px > 0:
        pixels = pixels + noise_px * jax.random.normal(key, pixels.shape, dtype)
    v = jax.vmap(velocity)(ts)
    n_obj = jnp.cross(s[0], s[1])
    n_cam = R_star @ n_obj
    m1_star = x_f_star + R_star @ s[0]
    n_cam = jnp.where(n_cam @ m1_star > 0, n_cam, -n_cam)  # d* > 0, eq. (4)
    return FixedCameraScenario(
        ts=ts,
        pixels=pixels,
        velocity=v,
        x_f=x_f,
        R=R,
        A=A,
        R_star=R_star,
        x_f_star=x_f_star,
        s=s,
        n_star=n_cam / jnp.linalg.norm(n_cam),
        z1_star=m1_star[2],
    )
