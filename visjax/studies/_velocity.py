"""The seed-000 experiment: simulate section 6, estimate, and summarise; and a noise study."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..estimators import VelocityEstimator, fixed_camera_stream, run, window_rms_reducer
from ..estimators._base import summary_rms
from ..sim import K_EQ63, RHO_EQ63, fixed_camera_scenario

DOF_NAMES = ("vx", "vy", "vz", "wx", "wy", "wz")


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


def velocity_experiment(
    duration: float = 10.0,
    rate_hz: float = 1000.0,
    noise_px: float = 0.0,
    *,
    K=K_EQ63,
    rho=RHO_EQ63,
    seed: int = 0,
    progress=None,
) -> VelocityRun:
    """Simulate section 6 of seed 000, measure n* and z1*, run the estimator (eqs. 39-40).

    `progress`, if given, is called with the name of each stage as it starts.
    """
    progress = progress or (lambda stage: None)
    progress("simulate section 6")
    key = jax.random.key(seed) if noise_px > 0 else None
    sc = fixed_camera_scenario(duration, rate_hz, noise_px=noise_px, key=key)
    progress("reconstruct every frame")
    stream, n_star, z1_star = fixed_camera_stream(sc.ts, sc.pixels, sc.A, sc.R_star, sc.s[0])
    progress("estimate")
    est = VelocityEstimator(K=jnp.asarray(K, float), rho=jnp.asarray(rho, float))
    sol = run(est, stream)
    return VelocityRun(
        ts=sc.ts, velocity=sc.velocity, estimate=sol.outputs, n_star=n_star, z1_star=z1_star
    )


def summarise(r: VelocityRun, duration: float, rate_hz: float, noise_px: float) -> dict:
    """`summary.json` of `visjax velocity`: RMS and max error per DOF over 5-10 s."""
    a, b = window(duration)
    t = np.asarray(r.ts)
    inside = (t >= a) & (t < b)
    err = np.asarray(r.estimate)[inside] - np.asarray(r.velocity)[inside]
    return {
        "rms_5_10s": [float(x) for x in np.sqrt(np.mean(err**2, axis=0))],
        "max_5_10s": [float(x) for x in np.max(np.abs(err), axis=0)],
        "order": list(DOF_NAMES),
        "window_s": [a, b],
        "rate_hz": rate_hz,
        "noise_px": noise_px,
        "duration_s": duration,
        "z1_star_recovered": float(r.z1_star),
        "n_star_recovered": [float(x) for x in r.n_star],
    }


def velocity_noise_study(
    noise_levels=(0.0, 0.1, 0.5, 1.0),
    seeds: int = 8,
    duration: float = 10.0,
    rate_hz: float = 1000.0,
    *,
    K=K_EQ63,
    rho=RHO_EQ63,
) -> dict:
    """RMS velocity error over the window, per noise level, vmapped over `seeds` noise draws.

    The plane normal and $z_1^*$ are measured once from the noise-free scenario (they are
    constants of the set-up); the pixel noise enters every frame of the estimator's input.

    **Returns:** `{noise: array (seeds, 6)}` of RMS errors.
    """
    sc = fixed_camera_scenario(duration, rate_hz)
    _, n_star, z1_star = fixed_camera_stream(sc.ts, sc.pixels, sc.A, sc.R_star, sc.s[0])
    a, b = window(duration)
    red = window_rms_reducer(a, b)
    est = VelocityEstimator(K=jnp.asarray(K, float), rho=jnp.asarray(rho, float))

    @jax.jit
    def rms(key, sigma):
        pixels = sc.pixels + sigma * jax.random.normal(key, sc.pixels.shape)
        stream, _, _ = fixed_camera_stream(
            sc.ts,
            pixels,
            sc.A,
            sc.R_star,
            sc.s[0],
            n_star=n_star,
            z1_star=z1_star,
            truth=sc.velocity,
        )
        return summary_rms(run(est, stream, save_every=None, reducer=red).summary)

    keys = jax.random.split(jax.random.key(0), seeds)
    batched = jax.vmap(rms, in_axes=(0, None))
    return {float(s): np.asarray(batched(keys, jnp.asarray(s, float))) for s in noise_levels}
