"""The three estimators set up for `sweep` and `tune`: a factory `(params, key) ->
Solution` (per-seed pixel noise, everything downstream of the pixels recomputed per run),
the metrics, the loss, the published gains and a default grid.

The parameters are multipliers of a reference gain set (the paper's published gains, or
the gains `from_nominal` derives): `K = 0.01` means the paper's $K$ times 0.01. The table
and `summary.json` record the multipliers; `TuningProblem.gains` turns them into the
absolute gains.
"""

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class TuningProblem:
    """An estimator set up for `studies.sweep` and `studies.tune`.

    **Fields:** `name`; `factory` (`(params, key) -> Solution`, `throw=False`: a diverging
    gain is a result code); `metrics` (`solution -> {name: array}`); `metric` (the
    headline metric, to minimise, a key of `metrics`); `loss` (`solution -> scalar`, what
    `tune` minimises: the headline metric); `paper` (the multipliers of the reference
    gains, all 1); `grid` (the default `parse_grid` spec); `gains` (multipliers -> the
    absolute gains, JSON-able); `settings` (every stated setting)."""

    name: str
    factory: Callable[[dict, Any], Any]
    metrics: Callable[[Any], dict]
    metric: str
    loss: Callable[[Any], Any]
    paper: dict
    grid: str
    gains: Callable[[dict], dict]
    settings: dict = field(default_factory=dict)


def _rms_of(summary):
    """Per-component RMS of a `WindowSummary`."""
    import jax.numpy as jnp

    return jnp.sqrt(summary.sumsq / jnp.maximum(summary.count, 1.0))


def velocity_tuning(
    *,
    noise_px: float = 0.1,
    duration: float = 10.0,
    rate_hz: float = 1000.0,
    data=None,
) -> TuningProblem:
    """The velocity estimator of Chitrakaran et al. (eqs. (39)-(40)) with gains
    $K = k_K K_{63}$, $\\rho = k_\\rho \\rho_{63}$ (the published gains of eq. (63), or the
    file's), parameters `K` ($k_K$) and `rho` ($k_\\rho$).

    Each run adds `noise_px` of Gaussian pixel noise to the section-6 simulation
    (`duration` at `rate_hz`) or to a `VelocityData` file's pixels, and recomputes the
    homography, its decomposition and $J$ of every frame (`fixed_camera_stream`) from the
    noisy pixels; $n^*$ and $z_1^*$ are measured once, noise-free (the calibration before
    the run). Metrics: `rms` (6,), the RMS error per degree of freedom over the paper's
    window (5-10 s, the second half of a shorter run; `papers.chitrakaran.window`), and
    `rms_worst`, its largest component (m/s and rad/s mixed, as in the paper's Table I);
    the loss is `rms_worst`.
    """
    import jax
    import jax.numpy as jnp

    from ..estimators import SaveAt, VelocityEstimator, WindowRMS, fixed_camera_stream, run
    from ..papers.chitrakaran import window
    from ._problems import velocity_source

    v = velocity_source(data, duration, rate_hz)
    if v.truth is None:
        raise ValueError(f"{data}: tuning needs the file's true velocity (`velocity`).")
    ts, clean, A, R_star, s1, truth = v.ts, v.clean, v.A, v.R_star, v.s1, v.truth
    K0, rho0, p_ref, dropouts = v.K, v.rho, v.reference_pixels, v.dropouts
    n_star, z1_star, source = v.n_star, v.z1_star, v.source
    t0 = float(ts[0])
    a, b = window(float(ts[-1]) - t0)
    reducer = WindowRMS(t0 + a, t0 + b + 1e-9, field="v_hat")
    K0, rho0 = jnp.asarray(K0, float), jnp.asarray(rho0, float)

    def factory(params, key):
        noise = noise_px * jax.random.normal(key, clean.shape, dtype=clean.dtype)
        stream, _, _ = fixed_camera_stream(
            ts,
            clean + noise,
            A,
            R_star,
            s1,
            n_star=n_star,
            z1_star=z1_star,
            reference_pixels=p_ref,
            dropouts=dropouts,
            truth=truth,
            throw=False,
        )
        est = VelocityEstimator(K=params["K"] * K0, rho=params["rho"] * rho0)
        return run(est, stream, saveat=SaveAt(outputs=False), reducer=reducer, throw=False)

    def metrics(sol):
        rms = _rms_of(sol.summary)
        return {"rms_worst": jnp.max(rms), "rms": rms}

    def gains(params):
        return {
            "K": [float(x) for x in np.asarray(K0) * params["K"]],
            "rho": [float(x) for x in np.asarray(rho0) * params["rho"]],
        }

    return TuningProblem(
        name=f"velocity estimator (Chitrakaran et al.), {source}, {noise_px:g} px noise",
        factory=factory,
        metrics=metrics,
        metric="rms_worst",
        loss=lambda sol: metrics(sol)["rms_worst"],
        paper={"K": 1.0, "rho": 1.0},
        grid="K=1e-3:1e1:9,rho=1e-3:1e1:9",
        gains=gains,
        settings={
            "source": source,
            "noise_px": noise_px,
            "reference_gains": "eq. (63)" if data is None else "the file's (eq. (63) if none)",
            "K_reference": [float(x) for x in np.asarray(K0)],
            "rho_reference": [float(x) for x in np.asarray(rho0)],
            "window_s": [a, b],
            "metric": "worst-axis RMS over the window (m/s, rad/s)",
            "per_run": "pixel noise; homography, decomposition and J recomputed",
            "n_star_z1_star": "measured once from the noise-free pixels",
        },
    )
