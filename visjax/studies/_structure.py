"""The seed-003 experiments: simulated analogues of the thesis' seven sets, and their RMS."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..estimators import Stream, UnknownInputObserver, run
from ..sim import KC_REFINED, SETS, moving_camera_scenario


class StructureRun(eqx.Module):
    """One set: times, true and estimated positions (metres, camera frame), RMS window."""

    ts: Float[Array, " N"]
    position: Float[Array, "N 3"]
    estimate: Float[Array, "N 3"]
    rms: Float[Array, "3"]


def observer_for(set_name: str, K=None, Y=None, x3_guess_cm: float = 100.0) -> UnknownInputObserver:
    """The UIO of a thesis set, with the thesis' gains unless `K`, `Y` are given."""
    s = SETS[set_name]
    return UnknownInputObserver(
        A=jnp.array(s.A, float),
        D=jnp.array(s.D, float)[:, None],
        K=jnp.array(s.K if K is None else K, float),
        Y=jnp.array(s.Y if Y is None else Y, float),
        x3_guess=jnp.array(1.0 / x3_guess_cm),
    )


def structure_experiment(
    set_name: str,
    duration: float = 30.0,
    noise_px: float = 0.0,
    *,
    seed: int = 0,
    Kc_observer=KC_REFINED,
    K=None,
    Y=None,
) -> StructureRun:
    """Simulate a thesis set, run the UIO (eq. (3.5)) at 1 kHz, and the steady-state RMS
    position error (metres) over the second half of the run."""
    key = jax.random.key(seed) if noise_px > 0 else None
    sc = moving_camera_scenario(
        set_name, duration, noise_px=noise_px, key=key, Kc_observer=Kc_observer
    )
    sol = run(observer_for(set_name, K, Y), Stream(ts=sc.ts, ys=(sc.y, sc.u)), save_every=10)
    estimate = sol.outputs["position"] / 100.0  # cm -> m
    truth = sc.position[::10]
    steady = sol.ts >= duration / 2
    err = np.asarray(estimate - truth)[np.asarray(steady)]
    return StructureRun(
        ts=sol.ts, position=truth, estimate=estimate, rms=jnp.sqrt(jnp.mean(err**2, axis=0))
    )
