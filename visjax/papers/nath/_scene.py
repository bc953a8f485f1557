"""The scene of Nath et al., *Euclidean position estimation of static features using a moving
uncalibrated camera* as visjax simulates it: the platform's motion, the features, the
nominal camera (`visjax.papers.nath` says what is the paper's and what is chosen)."""

import functools
from typing import final

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from ...estimators import (
    StaticPointsEstimator,
    Stream,
    static_points_stream,
)
from ...geometry import camera_parameters, intrinsics_from_camera, so3_exp
from ...sim import (
    CameraRig,
    Trajectory,
    add_pixel_noise,
    points_in_camera,
    sample_times,
    view,
)


@final
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


def scenario(
    duration: float = 20.0,
    rate_hz: float = 1000.0,
    *,
    noise_px: float = 0.0,
    key: PRNGKeyArray | None = None,
    exciting: bool = True,
) -> UncalibratedScenario:
    """The project's scenario (module docstring), sampled at `rate_hz`."""
    if noise_px > 0 and key is None:
        raise ValueError("`key` is required when `noise_px > 0`.")
    ts = sample_times(duration, rate_hz)
    R_b, x_b, p_s, p_c, omega_c, omega_s, A, R_c, x_c, t1, t2 = _scenario(ts, exciting)
    if noise_px > 0:
        k1, k2 = jax.random.split(key)
        p_s = add_pixel_noise(k1, p_s, noise_px)
        p_c = add_pixel_noise(k2, p_c, noise_px)
    return UncalibratedScenario(ts, R_b, x_b, p_s, p_c, omega_c, omega_s, A, R_c, x_c, t1, t2)


# the scene's arrays, compiled once per length (not one compiled operation per line)
@functools.partial(jax.jit, static_argnums=1)
def _scenario(ts, exciting):
    A = intrinsics_from_camera(0.008, 1e5, 1e5, jnp.deg2rad(88.0), 320.0, 240.0)
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
    # the camera on the platform (eq. (5)); the scene's poses only (no twist is needed)
    body = Trajectory(ts=ts, R=R_b, x=x_b, twist=jnp.zeros((ts.shape[0], 6), ts.dtype))
    rig = CameraRig(A=A, R_c=R_c, x_c=x_c, image_size=None)

    p_s = view(rig, points_in_camera(rig, omega_s, body))
    p_c = view(rig, points_in_camera(rig, omega_c, body))
    t1, t2 = camera_parameters(A, R_c, x_c)
    return R_b, x_b, p_s, p_c, omega_c, omega_s, A, R_c, x_c, t1, t2


def nominal_camera() -> tuple[Float[Array, "3 3"], Float[Array, "3 3"], Float[Array, "3"]]:
    """The camera as an engineer would know it before running (fixed with the scenario,
    before any result; the estimator never sees the simulation's truth): the data sheet's
    focal length +10% (8.8 mm), no skew assumed (90 degrees, the truth is 88), the principal
    point at (340, 225) px (the truth (320, 240)); the mounting measured with a ruler: the
    rotation 3 degrees off about the optical axis, `x_c` = (0.07, -0.05, 0.12) m (2 cm off
    on each axis). The same offsets as version 1's initial estimates, now stated here.

    **Returns:** `(A_nominal, R_c_nominal, x_c_nominal)`.
    """
    A = intrinsics_from_camera(0.008 * 1.1, 1e5, 1e5, jnp.deg2rad(90.0), 340.0, 225.0)
    R_c = so3_exp(jnp.deg2rad(3.0) * jnp.array([0.0, 0.0, 1.0])) @ so3_exp(
        jnp.deg2rad(5.0) * jnp.array([0.6, -0.8, 0.0])
    )
    return A, R_c, jnp.array([0.07, -0.05, 0.12])


# Overrides of the gains that `StaticPointsEstimator.from_nominal` derives from the
# scene's scale (its docstring states the rule): none. Version 1's hand settings (alpha_c =
# alpha = 100, eta0 = 1e-5, eta1 = 1e-7, gamma_s0 = 1e-5, eps = 0.2 m, on raw pixels) are
# gone with the pixel normalisation (their units changed).
DEFAULT_GAINS: dict = {}


@final
class StaticPointsRun(eqx.Module):
    """Times, estimated and true unknown feature positions (m), prediction errors (px), the
    PE measure, depth estimates, the minimum eigenvalue of Gamma_c and the reset count."""

    ts: Float[Array, " N"]
    omega_s: Float[Array, "N n 3"]
    omega_true: Float[Array, "n 3"]
    p_tilde_c: Float[Array, "N m"]
    p_tilde_s: Float[Array, "N n"]
    pe: Float[Array, "N n"]
    depth_s: Float[Array, "N n"]
    depth_c: Float[Array, "N m"]
    lambda_min_gamma_c: Float[Array, " N"]
    resets: Float[Array, " N"]


def initial_estimator(
    sc: UncalibratedScenario, gains=None, *, dt: float | None = None
) -> StaticPointsEstimator:
    """The estimator from the nominal camera (`nominal_camera`) and the measurements only
    (`StaticPointsEstimator.from_nominal`): each unknown feature guessed on its
    nominal ray at the median depth of the known features (2-9 cm off here), the gains
    derived from the scene's scale for the step `dt` (`None`: the sample interval);
    `gains` overrides any of them."""
    A0, R_c0, x_c0 = nominal_camera()
    return StaticPointsEstimator.from_nominal(
        stream(sc), A0, R_c0, x_c0, dt=dt, gains=dict(DEFAULT_GAINS, **(gains or {}))
    )


def stream(sc: UncalibratedScenario) -> Stream:
    """The estimator's stream of the scenario's measurements (platform pose, pixels)."""
    return static_points_stream(sc.ts, sc.R_b, sc.x_b, sc.p_s, sc.p_c, sc.omega_c)
