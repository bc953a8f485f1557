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

import equinox as eqx
import numpy as np


@dataclass(frozen=True)
class TuningProblem:
    """An estimator set up for `studies.sweep` and `studies.tune`.

    **Fields:** `name`; `factory` (`(params, key) -> Solution`, `throw=False`: a diverging
    gain is a result code); `metrics` (`solution -> {name: array}`); `metric` (the
    headline metric, to minimise, a key of `metrics`); `loss` (`solution -> scalar`, what
    `tune` minimises: the headline metric); `paper` (the multipliers of the reference
    gains, all 1); `grid` (the default `parse_grid` spec); `gains` (multipliers -> the
    absolute gains, JSON-able); `label` (the metric with its units, for figures);
    `settings` (every stated setting)."""

    name: str
    factory: Callable[[dict, Any], Any]
    metrics: Callable[[Any], dict]
    metric: str
    loss: Callable[[Any], Any]
    paper: dict
    grid: str
    gains: Callable[[dict], dict]
    label: str = ""
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
    adjoint=None,
    chunk: int = 256,
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
    the loss is `rms_worst`. `adjoint`: the runner's (default `DirectAdjoint()`;
    `CheckpointAdjoint()` for reverse-mode tuning of many gains, e.g. per-axis multipliers:
    `K` and `rho` may be (6,) arrays). `chunk`: frames per fused chunk of the stream
    (`fixed_camera_stream`; with `CheckpointAdjoint` its blocks are the chunks). Fastest on a
    2-core CPU at about 16,000 frames per chunk call, chunk x the vmapped batch: 256 for
    batches of 64 (`sweep`'s default), 16 for batches of 1,024.
    """
    import jax
    import jax.numpy as jnp

    from ..estimators import (
        DirectAdjoint,
        SaveAt,
        VelocityEstimator,
        WindowRMS,
        fixed_camera_stream,
        run,
    )
    from ..papers.chitrakaran import window
    from ._problems import velocity_source

    if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
        raise ValueError(f"`chunk` must be a positive int (frames per chunk); got {chunk!r}.")
    adj = DirectAdjoint() if adjoint is None else adjoint
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
            chunk=chunk,
        )
        est = VelocityEstimator(K=params["K"] * K0, rho=params["rho"] * rho0)
        return run(
            est, stream, saveat=SaveAt(outputs=False), reducer=reducer, adjoint=adj, throw=False
        )

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
        label="worst-axis RMS over the window (m/s, rad/s)",
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
            "chunk": chunk,
        },
    )


def structure_tuning(
    *,
    set_name: str = "I.1",
    noise_px: float = 0.1,
    duration: float = 20.0,
    adjoint=None,
) -> TuningProblem:
    """The unknown input observer of Jang's thesis (eq. (3.5)) on the simulated analogue of
    a thesis set, with gains $K = k_K K_{pub}$, $Y = k_Y Y_{pub}$ (the set's published
    gains, chapter 5), parameters `K` ($k_K$) and `Y` ($k_Y$).

    Each run adds `noise_px` of Gaussian pixel noise to the 30 Hz frames, holds them at the
    observer's 1 kHz (as the thesis' logger did; `ThesisScenario.held_stream`) and runs
    the observer; the metrics are scored at 1 kHz against the true position over the
    second half of the run, as `papers.jang.structure_experiment` does: `rms` (3,) per
    axis in metres and `rms_worst`, its largest component (the depth's, in practice). The
    loss is `rms_worst`. `TuningProblem.settings["lmi"]` gives the set's $A$, $C$, $D$ for
    `visjax.design.certified_lipschitz`, the check of tuned gains against the LMI of
    section 3.6.
    """
    import jax
    import jax.numpy as jnp

    from ..estimators import DirectAdjoint, SaveAt, WindowRMS, moving_camera_stream, run
    from ..papers import jang

    if set_name not in jang.SETS:
        raise ValueError(f"unknown set {set_name!r}; choose from {list(jang.SETS)}.")
    adj = DirectAdjoint() if adjoint is None else adjoint
    s = jang.SETS[set_name]
    sc = jang.scenario(set_name, duration)
    k = sc.frame_index
    K0, Y0 = jnp.asarray(s.K, float), jnp.asarray(s.Y, float)
    truth_cm = sc.position * 100.0  # the observer's units (the thesis' centimetres)
    reducer = WindowRMS(duration / 2, duration + 1.0, field="position")

    def factory(params, key):
        noise = noise_px * jax.random.normal(key, sc.frame_pixels.shape, sc.frame_pixels.dtype)
        pixels = sc.frame_pixels + noise
        stream = moving_camera_stream(
            sc.ts, pixels[k], sc.frame_velocities[k], sc.Kc_observer, truth=truth_cm
        )
        obs = jang.observer(set_name, K=params["K"] * K0, Y=params["Y"] * Y0)
        return run(
            obs, stream, saveat=SaveAt(outputs=False), reducer=reducer, adjoint=adj, throw=False
        )

    def metrics(sol):
        rms = _rms_of(sol.summary) / 100.0  # cm -> m
        return {"rms_worst": jnp.max(rms), "rms": rms}

    def gains(params):
        return {
            "K": (np.asarray(K0) * params["K"]).tolist(),
            "Y": (np.asarray(Y0) * params["Y"]).tolist(),
        }

    return TuningProblem(
        name=f"unknown input observer (Jang's thesis), set {set_name} (simulated), "
        f"{duration:g} s, {noise_px:g} px noise",
        factory=factory,
        metrics=metrics,
        metric="rms_worst",
        loss=lambda sol: metrics(sol)["rms_worst"],
        paper={"K": 1.0, "Y": 1.0},
        grid="K=0.1:10:7,Y=0.1:10:7",
        gains=gains,
        label="worst-axis RMS position, second half (m)",
        settings={
            "set": set_name,
            "noise_px": noise_px,
            "duration_s": duration,
            "reference_gains": "the thesis' published K and Y of the set (chapter 5)",
            "scoring": "1 kHz against the true position, second half of the run (metres)",
            "thesis_rms_m": list(s.thesis_rms),
            "lmi": {
                "A": [list(r) for r in s.A],
                "C": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                "D": [[x] for x in s.D],
            },
        },
    )


def euclidean_tuning(
    *,
    noise_px: float = 0.1,
    duration: float = 20.0,
    rate_hz: float = 100.0,
    data=None,
    adjoint=None,
) -> TuningProblem:
    """The adaptive least-squares estimator of Nath et al. (eqs. (37)-(51)) from nominal
    values (`AdaptiveStructureEstimator.from_nominal`, derived per run from that run's
    noisy stream), with its adaptation gains scaled: `alpha` multiplies $\\alpha_c$ and
    $\\alpha$ (eqs. (37), (41)), `gamma` multiplies the initial gains $\\eta_0$, $\\eta_1$
    and $\\gamma_{s0}$ (eqs. (39), (45)); at 1, 1 the derived gains.

    Each run adds `noise_px` of Gaussian pixel noise to the project's scene
    (`papers.nath.scenario`, `duration` at `rate_hz`) or to a `EuclideanData` file's pixels
    and integrates at 1 kHz on the held samples. Metrics: `error` (n,), each unknown
    feature's final position error (m), and `error_worst`, the largest; the loss is
    `error_worst`.
    """
    import jax
    import jax.numpy as jnp

    from ..estimators import (
        AdaptiveStructureEstimator,
        DirectAdjoint,
        SaveAt,
        Stream,
        integration_step,
        platform_stream,
        run,
    )
    from ._problems import euclidean_source

    ts, R_b, x_b, omega_c, clean, n_known, truth, nominal, source = euclidean_source(
        data, duration, rate_hz
    )
    if truth is None:
        raise ValueError(f"{data}: tuning needs the file's true feature positions.")
    adj = DirectAdjoint() if adjoint is None else adjoint
    # 1 kHz on held samples; `from_nominal` derives its gains for that step (no bound here)
    dt = integration_step(Stream(ts=ts, ys=ts), max_step=1e-3)

    def factory(params, key):
        noisy = clean + noise_px * jax.random.normal(key, clean.shape, clean.dtype)
        stream = platform_stream(ts, R_b, x_b, noisy[:, n_known:], noisy[:, :n_known], omega_c)
        est = AdaptiveStructureEstimator.from_nominal(stream, *nominal, dt=dt)
        est = eqx.tree_at(
            lambda e: (e.alpha_c, e.alpha, e.eta0, e.eta1, e.gamma_s0),
            est,
            (
                params["alpha"] * est.alpha_c,
                params["alpha"] * est.alpha,
                params["gamma"] * est.eta0,
                params["gamma"] * est.eta1,
                params["gamma"] * est.gamma_s0,
            ),
        )
        sol = run(est, stream, dt=dt, saveat=SaveAt(outputs=False), adjoint=adj, throw=False)
        last = jax.tree_util.tree_map(lambda x: x[-1], stream.ys)
        omega_s = est.output(ts[-1], sol.final_state, last).omega_s
        return _WithFinal(sol.result, sol.failed_sample, omega_s)

    def metrics(sol):
        error = jnp.linalg.norm(sol.omega_s - truth, axis=-1)
        return {"error_worst": jnp.max(error), "error": error}

    return TuningProblem(
        name=f"adaptive structure estimator (Nath et al.), {source}, {noise_px:g} px noise",
        factory=factory,
        metrics=metrics,
        metric="error_worst",
        loss=lambda sol: metrics(sol)["error_worst"],
        paper={"alpha": 1.0, "gamma": 1.0},
        grid="alpha=0.1:10:5,gamma=0.1:10:5",
        gains=lambda params: {k: float(v) for k, v in params.items()},
        label="worst final position error (m)",
        settings={
            "source": source,
            "noise_px": noise_px,
            "reference_gains": "from_nominal's derived gains (Nath et al. give none for "
            "this scene)",
            "integration_step_s": dt,
            "metric": "worst final position error of the unknown features (m)",
        },
    )


class _WithFinal(eqx.Module):
    """A result code plus the final structure estimate (what the Nath metrics read)."""

    result: Any
    failed_sample: Any
    omega_s: Any
