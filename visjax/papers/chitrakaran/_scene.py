"""The constants, published gains and section-6 scenario of Chitrakaran, Dawson, Dixon, Chen,
*Identification of a moving object's velocity with a fixed camera* (what the paper leaves
open and how it is chosen: `visjax.papers.chitrakaran`)."""

from collections.abc import Callable
from typing import final

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from ..._util import as_float
from ...sim import (
    CameraRig,
    Sampler,
    add_pixel_noise,
    integrate_twist,
    object_points,
    points_in_camera,
    sinusoidal_trajectory,
    view,
)

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


@final
class Section6Scenario(eqx.Module):
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


def section6_scenario(
    duration: float = 10.0,
    rate_hz: float = 1000.0,
    *,
    noise_px: float = 0.0,
    key: PRNGKeyArray | None = None,
    velocity: Callable[[Array], Array] = section6_velocity,
) -> Section6Scenario:
    """The section-6 simulation: N = round(duration * rate_hz) samples at t_k = k / rate_hz.

    **Arguments:**

    - `duration`: seconds (10 in the paper).
    - `rate_hz`: the sample rate (1000 in the paper).
    - `noise_px`: standard deviation of pixel noise (0: noise-free, as in the paper).
    - `key`: PRNG key for the noise (required when `noise_px > 0`).
    - `velocity`: $t \\mapsto [v_e, \\omega_e]$; eq. (59) by default.
    """
    ts = Sampler(rate_hz=rate_hz).times(duration)
    dtype = ts.dtype
    A = jnp.array(A_EQ62, dtype)
    R_star = jnp.array(R_STAR_EQ61, dtype)
    x_f_star = jnp.array(X_F_STAR_EQ60, dtype)
    s = jnp.array(FEATURES, dtype)
    if velocity is section6_velocity:
        # eq. (59): 0.2 sin(t) on all six entries, a sinusoid of 1/(2 pi) Hz
        body = sinusoidal_trajectory(
            jnp.full(6, 0.2, dtype), jnp.full(6, 1.0 / (2.0 * jnp.pi), dtype), x_f_star, R_star, ts
        )
    else:
        body = integrate_twist(velocity, x_f_star, R_star, ts)
    camera = CameraRig(A=A, image_size=None)  # the camera frame is the fixed frame
    clean = view(camera, points_in_camera(camera, object_points(body, s)))  # eqs. (5), (15)
    pixels = add_pixel_noise(key, clean, noise_px)
    n_obj = jnp.cross(s[0], s[1])
    n_cam = R_star @ n_obj
    m1_star = x_f_star + R_star @ s[0]
    n_cam = jnp.where(n_cam @ m1_star > 0, n_cam, -n_cam)  # d* > 0, eq. (4)
    return Section6Scenario(
        ts=ts,
        pixels=pixels,
        velocity=body.twist,
        x_f=body.x,
        R=body.R,
        A=A,
        R_star=R_star,
        x_f_star=x_f_star,
        s=s,
        n_star=n_cam / jnp.linalg.norm(n_cam),
        z1_star=m1_star[2],
    )


DOF_NAMES = ("vx", "vy", "vz", "wx", "wy", "wz")


@final
class VelocityRun(eqx.Module):
    """One run of the section-6 experiment: times, true and estimated velocities."""

    ts: Float[Array, " N"]
    velocity: Float[Array, "N 6"]
    estimate: Float[Array, "N 6"]
    n_star: Float[Array, "3"]
    z1_star: Float[Array, ""]


def window(duration: float) -> tuple[float, float]:
    """The paper's evaluation window, 5 to 10 s, shrunk into shorter runs (second half)."""
    return (min(5.0, duration / 2.0), min(10.0, duration))


def eq56_matrix(m1_star, m1, alpha1, n_star, x_h, R_bar) -> Float[Array, "3 3"]:
    """The matrix $\\mathrm{diag}(\\bar\\gamma_1 - \\bar\\gamma_2) + \\bar R$ that eq. (56) inverts.

    Kept to document (and test) that it is singular; see
    `visjax.estimators.depth_from_known_length`.
    $\\bar\\gamma_1 = \\mathrm{diag}(m_1^*)^{-1} n^{*T} m_1^* \\bar x_h$,
    $\\bar\\gamma_2 = \\mathrm{diag}(m_1^*)^{-1} m_1/\\alpha_1$ (eq. (57)).
    """
    m1_star, m1, alpha1, n_star, x_h, R_bar = (
        as_float(x) for x in (m1_star, m1, alpha1, n_star, x_h, R_bar)
    )
    g1 = (n_star @ m1_star) * x_h / m1_star
    g2 = (m1 / alpha1) / m1_star
    return jnp.diag(g1 - g2) + R_bar
