"""The reproduction report: each paper's experiment as figures, `summary.json` and the
printed tables, and `reproduce`, which runs them all. The command line calls these."""

import functools
import json
import math
import time
from pathlib import Path

import numpy as np


def _enable_x64():
    """The command line runs in float64 (the library itself never flips the flag)."""
    import jax

    jax.config.update("jax_enable_x64", True)


def _progress(total: int, desc: str, quiet: bool):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="stage", disable=quiet)


def geometry_report(
    scenes: int = 100, points: int = 4, noise: float = 0.0, seed: int = 0, out=None
) -> dict:
    """Chitrakaran et al., section 3: random planar scenes reconstructed by visjax and by
    OpenCV, both against ground truth (`summary.json`, `geometry.png`)."""
    _enable_x64()
    import jax

    from .baselines import opencv_reconstruction
    from .geometry import euclidean_reconstruction
    from .papers.chitrakaran import reconstruction_errors
    from .plots import plot_geometry
    from .sim import random_planar_scenes

    sc = random_planar_scenes(scenes, points, seed=seed, noise_px=noise)
    rng = np.random.default_rng(seed + 1)
    # A rough prior of the plane normal (about 1 degree off) picks between the two physical
    # decompositions; both pipelines get the same one.
    prior = sc.n_star + 0.02 * rng.normal(size=sc.n_star.shape)

    recon = jax.jit(jax.vmap(euclidean_reconstruction))
    t0 = time.perf_counter()
    jax.block_until_ready(recon(sc.p_ref, sc.p_cur, sc.A, prior))
    t_compile = time.perf_counter() - t0
    t0 = time.perf_counter()
    rec = jax.block_until_ready(recon(sc.p_ref, sc.p_cur, sc.A, prior))
    t_visjax = time.perf_counter() - t0
    ours = {k: np.asarray(getattr(rec, k)) for k in ("R_bar", "x_h", "n_star", "alpha", "H")}

    t0 = time.perf_counter()
    cv = [
        opencv_reconstruction(sc.p_ref[i], sc.p_cur[i], sc.A[i], prior[i]) for i in range(len(sc))
    ]
    t_cv = time.perf_counter() - t0
    theirs = {k: np.stack([c[k] for c in cv]) for k in cv[0]}

    errors = {
        "visjax": reconstruction_errors(ours, sc),
        "opencv": reconstruction_errors(theirs, sc),
    }
    summary = {
        "scenes": scenes,
        "points": points,
        "noise_px": noise,
        "seed": seed,
        "seconds": {"visjax_compile": t_compile, "visjax": t_visjax, "opencv": t_cv},
        "errors": {
            who: {
                k: {"median": float(np.median(v)), "max": float(np.max(v))} for k, v in errs.items()
            }
            for who, errs in errors.items()
        },
    }

    print(
        f"Euclidean reconstruction (seed 000, sec. 3): {scenes} random planar scenes, "
        f"{points} points, pixel noise {noise} px"
    )
    print(
        f"{'error vs ground truth':<22}{'visjax median':>15}{'visjax max':>13}"
        f"{'OpenCV median':>15}{'OpenCV max':>13}"
    )
    for k in errors["visjax"]:
        v, c = summary["errors"]["visjax"][k], summary["errors"]["opencv"][k]
        print(f"{k:<22}{v['median']:>15.3e}{v['max']:>13.3e}{c['median']:>15.3e}{c['max']:>13.3e}")
    s = summary["seconds"]
    print(
        f"time: visjax {s['visjax'] * 1e3:.2f} ms batched (+{s['visjax_compile']:.1f} s compile), "
        f"OpenCV {s['opencv'] * 1e3:.2f} ms loop"
    )
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "summary.json").write_text(json.dumps(summary, indent=2))
        plot_geometry(sc, ours, errors, path=out / "geometry.png")
        print(f"wrote {out / 'summary.json'} and {out / 'geometry.png'}")
    return summary


def velocity_report(
    duration: float = 10.0,
    rate: float = 1000.0,
    noise: float = 0.0,
    seed: int = 0,
    K=None,
    rho=None,
    out=None,
    quiet: bool = False,
) -> dict:
    """Chitrakaran et al., section 6: the velocity estimator on the paper's simulation
    (`velocity.png` like Fig. 2, `summary.json`, the RMS table)."""
    _enable_x64()
    from .papers.chitrakaran import (
        DOF_NAMES,
        K_EQ63,
        RHO_EQ63,
        summarise,
        velocity_experiment,
    )
    from .plots import plot_velocity

    K = list(K_EQ63) if K is None else list(K)
    rho = list(RHO_EQ63) if rho is None else list(rho)
    stages = _progress(4, "velocity", quiet)
    started = []

    def progress(stage):
        if started:
            stages.update()
        started.append(stage)
        stages.set_postfix_str(stage)

    r = velocity_experiment(duration, rate, noise, K=K, rho=rho, seed=seed, progress=progress)
    summary = summarise(r, duration, rate, noise)
    summary["K"], summary["rho"] = K, rho
    progress("figure")
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        title = f"seed 000, section 6: {rate:g} Hz, {duration:g} s, pixel noise {noise:g} px"
        plot_velocity(r.ts, r.velocity, r.estimate, title=title, path=out / "velocity.png")
        (out / "summary.json").write_text(json.dumps(summary, indent=2))
    stages.update()
    stages.close()

    a, b = summary["window_s"]
    print(
        f"Velocity estimator (seed 000, eqs. 39-40), section-6 simulation: {duration:g} s at "
        f"{rate:g} Hz, pixel noise {noise:g} px"
    )
    print(f"recovered z1* = {summary['z1_star_recovered']:.6f} m")
    print(f"{'DOF':<6}{f'RMS {a:g}-{b:g} s':>16}{f'max {a:g}-{b:g} s':>16}")
    for name, rms, mx in zip(DOF_NAMES, summary["rms_5_10s"], summary["max_5_10s"]):
        unit = "m/s" if name.startswith("v") else "rad/s"
        print(f"{name:<6}{rms:>16.5f}{mx:>16.5f}  {unit}")
    if out is not None:
        print(f"wrote {out / 'summary.json'} and {out / 'velocity.png'}")
    return summary


def _stable_dt(estimator, stream, y0=None):
    """`None` (integrate at the sample times) when every sample interval is within the
    Euler bound of the gains, else a step of half the bound (samples held between)."""

    y0 = stream.measurement(0) if y0 is None else y0
    bound = float(estimator.max_stable_dt(y0))
    longest = float(np.max(np.diff(np.asarray(stream.ts))))
    return None if longest <= bound else 0.5 * bound


def _last_half_rms(t, estimate, truth):
    t = np.asarray(t)
    half = t >= t[0] + 0.5 * (t[-1] - t[0])
    err = np.asarray(estimate)[half] - np.asarray(truth)[half]
    return [float(x) for x in np.sqrt(np.nanmean(err**2, axis=0))], [
        float(t[half][0]),
        float(t[-1]),
    ]


def velocity_data_report(path, out=None, quiet: bool = False, filter_hz=None) -> dict:
    """The velocity estimator of Chitrakaran et al. on a user's data file
    (`visjax.io.VelocityData`): $n^*$ from the frames, $z_1^*$ from the known length, the
    estimate in the camera and object frames (`estimate.npz`), `summary.json` with
    `z1_star` and, when the file has the true `velocity`, `rms_last_half` (6 floats over
    the second half of the run), and `velocity.png`."""
    _enable_x64()
    import jax.numpy as jnp

    from ._results import RESULTS
    from .estimators import (
        SaveAt,
        VelocityEstimator,
        fixed_camera_stream,
        lowpass,
        lowpass_delay,
        run,
    )
    from .io import VelocityData
    from .papers.chitrakaran import DOF_NAMES, K_EQ63, RHO_EQ63
    from .plots import plot_velocity

    data = VelocityData.load(path)
    stages = _progress(3, "velocity", quiet)
    stages.set_postfix_str("reconstruct every frame")
    stream, n_star, z1_star = fixed_camera_stream(
        data.t,
        data.pixels,
        data.A,
        data.R_star,
        data.s1,
        known_length=data.length,
        reference_pixels=data.reference_pixels,
        dropouts=True,
    )
    stages.update()
    stages.set_postfix_str("estimate")
    K = K_EQ63 if data.K is None else data.K
    rho = RHO_EQ63 if data.rho is None else data.rho
    est = VelocityEstimator(K=K, rho=rho)
    dt = _stable_dt(est, stream)
    sol = run(est, stream, dt=dt, saveat=SaveAt(), throw=False)
    stages.update()
    ok = sol.result == RESULTS.successful
    ts = np.asarray(sol.ts)
    v_hat = np.asarray(sol.outputs.v_hat)
    summary = {
        "z1_star": float(z1_star),
        "n_star": [float(x) for x in n_star],
        "result": "successful" if ok else str(sol.result),
        "order": list(DOF_NAMES),
        "samples": int(len(data.t)),
        "dropped_frames": int(np.sum(~np.asarray(stream.present))),
        "integration_step_s": dt,
        "K": [float(x) for x in np.asarray(K)],
        "rho": [float(x) for x in np.asarray(rho)],
    }
    estimates = {"t": ts, "v_hat": v_hat, "v_object": np.asarray(sol.outputs.v_object)}
    if filter_hz is not None:
        estimates["v_filtered"] = np.asarray(
            lowpass(jnp.asarray(ts), jnp.asarray(v_hat), filter_hz)
        )
        summary["filter_hz"] = filter_hz
        summary["filter_delay_s"] = lowpass_delay(filter_hz)
    truth = None
    if data.velocity is not None:
        # the truth at the integration grid: the sample held at each grid time
        k = np.searchsorted(np.asarray(data.t), ts + 1e-9, side="right") - 1
        truth = np.asarray(data.velocity)[k]
        shown = estimates.get("v_filtered", v_hat)
        summary["rms_last_half"], summary["window_s"] = _last_half_rms(ts, shown, truth)
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        np.savez(out / "estimate.npz", **estimates)
        plot_velocity(
            ts,
            truth,
            estimates.get("v_filtered", v_hat),
            title=f"velocity estimator (Chitrakaran et al.) on {Path(path).name}",
            path=out / "velocity.png",
        )
        (out / "summary.json").write_text(json.dumps(summary, indent=2))
    stages.update()
    stages.close()
    print(
        f"Velocity estimator (Chitrakaran et al., eqs. 39-40) on {path}: "
        f"{summary['samples']} frames"
    )
    print(f"recovered z1* = {summary['z1_star']:.6f} m; result: {summary['result']}")
    if "rms_last_half" in summary:
        a, b = summary["window_s"]
        print(
            f"RMS error {a:g}-{b:g} s: "
            + ", ".join(f"{n} {r:.4g}" for n, r in zip(DOF_NAMES, summary["rms_last_half"]))
        )
    if out is not None:
        print(f"wrote {out / 'summary.json'}, {out / 'estimate.npz'} and {out / 'velocity.png'}")
    if not ok:
        raise RuntimeError(
            f"the estimator stopped: {sol.result} at sample {int(sol.failed_sample)}"
        )
    return summary


def structure_data_report(path, out=None, quiet: bool = False) -> dict:
    """The unknown input observer of Jang's thesis (eq. (3.5)) on a user's data file
    (`visjax.io.StructureData`).

    The observer and its gains come from `visjax.studies.structure_observer_for_data`
    (gains designed by `design_uio_for_motion` for the file's camera motion; motion
    outside the design's model reported in `summary.json` as `unmodelled_motion`).
    Dropped frames (NaN pixels) are extrapolated from the last two seen. The observer
    runs at 1 kHz on the held frames. Writes `estimate.npz` (`t`, `position`, `x_hat`),
    `summary.json` (with the truth, `rms_last_half`, 3 floats, m, at the frame times of
    the second half) and `structure.png`."""
    _enable_x64()
    from ._results import RESULTS
    from .estimators import SaveAt, moving_camera_stream, run
    from .io import StructureData
    from .plots import plot_structure
    from .studies import structure_observer_for_data

    data = StructureData.load(path)
    t = np.asarray(data.t, float)
    stages = _progress(3, "structure", quiet)
    stages.set_postfix_str("design the gains (LMI)")
    observer, u, info = structure_observer_for_data(data)
    rate = info["design"]["convergence_rate_per_s"]
    frame_dt = float(np.median(np.diff(t)))
    stages.update()
    stages.set_postfix_str("estimate")
    stream = moving_camera_stream(t, data.pixels, u, data.A, dropped="extrapolate")
    dt = min(1e-3, frame_dt)
    bound = float(observer.max_stable_dt(None))
    dt = min(dt, 0.5 * bound) if np.isfinite(bound) and bound > 0 else dt
    sol = run(observer, stream, dt=dt, saveat=SaveAt(), throw=False)
    stages.update()
    ok = bool(sol.result == RESULTS.successful)
    # the estimate at each frame time: the grid point at (or just after) it
    grid = np.asarray(sol.ts)
    j = np.clip(np.searchsorted(grid, t - 1e-9), 0, len(grid) - 1)
    position = np.asarray(sol.outputs.position)[j]
    x_hat = np.asarray(sol.outputs.x_hat)[j]
    seen = np.all(np.isfinite(np.asarray(data.pixels)), axis=1)
    summary = {
        "result": "successful" if ok else str(sol.result),
        "frames": int(len(t)),
        "dropped_frames": int(np.sum(~seen)),
        "integration_step_s": dt,
        **info,
    }
    truth = None
    if data.position is not None:
        truth = np.asarray(data.position)
        summary["rms_last_half"], summary["window_s"] = _last_half_rms(t, position, truth)
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        np.savez(out / "estimate.npz", t=t, position=position, x_hat=x_hat)
        plot_structure(
            t,
            truth,
            position,
            title=f"unknown input observer (Jang's thesis) on {Path(path).name}",
            path=out / "structure.png",
        )
        (out / "summary.json").write_text(json.dumps(summary, indent=2))
    stages.update()
    stages.close()
    print(
        f"Unknown input observer (Jang's thesis, eq. 3.5) on {path}: {len(t)} frames, "
        f"gains by design_uio_for_motion (rate {rate:.3g}/s); result: {summary['result']}"
    )
    if "rms_last_half" in summary:
        a, b = summary["window_s"]
        print(
            f"RMS position error {a:g}-{b:g} s (m): "
            + ", ".join(f"{n} {r:.4g}" for n, r in zip("XYZ", summary["rms_last_half"]))
        )
    if out is not None:
        print(f"wrote {out / 'summary.json'}, {out / 'estimate.npz'} and {out / 'structure.png'}")
    if not ok:
        raise RuntimeError(f"the observer stopped: {sol.result} at sample {int(sol.failed_sample)}")
    return summary


def _thesis_set_names(sets) -> list:
    """The thesis' sets asked for (all by default), checked by name."""
    from .papers.jang import SETS

    names = list(SETS) if not sets else list(sets)
    for name in names:
        if name not in SETS:
            raise ValueError(f"unknown set {name!r}; choose from {list(SETS)}")
    return names


def _print_thesis_tables(summary, names, who: str) -> None:
    """Tables 5-3 and 5-4: per set and axis, visjax's RMS (or "infeasible") and the thesis'."""
    for group, label in (("I.", "Table 5-3 (static point)"), ("II.", "Table 5-4 (moving point)")):
        in_group = [n for n in names if n.startswith(group)]
        if not in_group:
            continue
        print(f"\n{label}: {who} (thesis)")
        print(f"{'':<4}" + "".join(f"{n:>20}" for n in in_group))
        for i, axis in enumerate("xyz"):
            cells = []
            for n in in_group:
                rms = summary[n]["rms"]
                value = f"{rms[i]:.4f}" if rms is not None else "infeasible"
                cells.append(f"{value:>11} ({summary[n]['thesis_rms'][i]:.4f})")
            print(f"{axis:<4}" + "".join(cells))


def structure_report(
    sets=None,
    duration: float = 30.0,
    noise: float = 0.1,
    seed: int = 0,
    out=None,
    quiet: bool = False,
) -> dict:
    """Jang's thesis: the UIO on the simulated analogues of the seven experiment sets
    (figures like Figs. 5-7/5-8, `summary.json`, Tables 5-3 and 5-4 beside the thesis')."""
    _enable_x64()
    from tqdm import tqdm

    from .papers.jang import SETS, structure_experiment
    from .plots import plot_structure

    names = _thesis_set_names(sets)
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
    summary = {}
    for name in tqdm(names, desc="structure", unit="set", disable=quiet):
        r = structure_experiment(name, duration, noise, seed=seed)
        summary[name] = {
            "rms": [float(x) for x in r.rms],
            "thesis_rms": list(SETS[name].thesis_rms),
        }
        if out is not None:
            kind = "moving" if SETS[name].moving else "static"
            plot_structure(
                r.ts,
                r.position,
                r.estimate,
                path=out / f"structure_{name}.png",
                title=f"seed 003, set {name} ({kind} point), simulated: pixel noise "
                f"{noise:g} px, camera 30 Hz, observer 1 kHz",
            )
    print(
        f"UIO (seed 003, eq. 3.5), simulated analogues: {duration:g} s, pixel noise "
        f"{noise:g} px, RMS position error over the second half (m)"
    )
    _print_thesis_tables(summary, names, "visjax")
    if out is not None:
        (out / "summary.json").write_text(json.dumps(summary, indent=2))
        print(f"\nwrote {out / 'summary.json'} and structure_<set>.png")
    return summary


def euclidean_data_report(path, out=None, quiet: bool = False) -> dict:
    """The adaptive structure estimator of Nath et al. on a user's data file
    (`visjax.io.EuclideanData`): built from the nominal camera of the file
    (`AdaptiveStructureEstimator.from_nominal`: initial guesses and gains from the scene's
    scale, never from a truth), run at 1 kHz on the held samples (at the samples if they
    are faster), features out of view (NaN) masked in both laws. Writes `estimate.npz`
    (`t`, `features` (M, n - k, 3), the recovered camera `A`, `R_c`, `x_c` over time),
    `summary.json` (the final features and camera; with the truth,
    `final_position_error_m`, n - k floats) and `euclidean.png`."""
    _enable_x64()
    from ._results import RESULTS
    from .estimators import AdaptiveStructureEstimator, SaveAt, platform_stream, run
    from .io import EuclideanData
    from .plots import plot_feature_estimates

    data = EuclideanData.load(path)
    k = data.n_known
    pixels = np.asarray(data.pixels, float)
    stages = _progress(2, "euclidean", quiet)
    stages.set_postfix_str("estimate (compiles once)")
    stream = platform_stream(
        data.t, data.platform_R, data.platform_x, pixels[:, k:], pixels[:, :k], data.known_features
    )
    longest = float(np.max(np.diff(np.asarray(data.t, float))))
    dt = None if longest <= 1e-3 else 1e-3
    est = AdaptiveStructureEstimator.from_nominal(
        stream, data.A_nominal, data.R_c_nominal, data.x_c_nominal, dt=dt
    )
    step = longest if dt is None else dt
    every = max(1, int(round(0.01 / step)))
    sol = run(est, stream, dt=dt, saveat=SaveAt(every=every), throw=False)
    stages.update()
    ok = bool(sol.result == RESULTS.successful)
    features = np.asarray(sol.outputs.omega_s)
    A, R_c, x_c = (np.asarray(getattr(sol.outputs, f)) for f in ("A", "R_c", "x_c"))
    summary = {
        "result": "successful" if ok else str(sol.result),
        "frames": int(pixels.shape[0]),
        "known_features": k,
        "unknown_features": int(pixels.shape[1] - k),
        "missing_observations": int(np.sum(~np.all(np.isfinite(pixels), axis=-1))),
        "integration_step_s": dt,
        "final_features_m": features[-1].tolist(),
        "camera": {"A": A[-1].tolist(), "R_c": R_c[-1].tolist(), "x_c": x_c[-1].tolist()},
    }
    if data.features is not None:
        err = np.linalg.norm(features[-1] - np.asarray(data.features), axis=-1)
        summary["final_position_error_m"] = [float(e) for e in err]
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        np.savez(
            out / "estimate.npz", t=np.asarray(sol.ts), features=features, A=A, R_c=R_c, x_c=x_c
        )
        plot_feature_estimates(
            sol.ts,
            features,
            data.features,
            title=f"adaptive structure estimator (Nath et al.) on {Path(path).name}",
            path=out / "euclidean.png",
        )
        (out / "summary.json").write_text(json.dumps(summary, indent=2))
    stages.update()
    stages.close()
    print(
        f"Adaptive LS structure estimator (Nath et al., eqs. 37-51) on {path}: "
        f"{summary['frames']} frames, {k} known and {summary['unknown_features']} unknown "
        f"features; result: {summary['result']}"
    )
    for i, e in enumerate(summary.get("final_position_error_m", [])):
        print(f"feature {k + i + 1}: final position error {e * 1000:8.3f} mm")
    if out is not None:
        print(f"wrote {out / 'summary.json'}, {out / 'estimate.npz'} and {out / 'euclidean.png'}")
    if not ok:
        raise RuntimeError(
            f"the estimator stopped: {sol.result} at sample {int(sol.failed_sample)}"
        )
    return summary


def euclidean_report(
    duration: float = 30.0, noise_px: float = 0.0, seed: int = 0, out=None, quiet: bool = False
) -> dict:
    """Nath et al.: the adaptive least-squares structure estimator on its simulation
    (`euclidean.png`, `summary.json`, the final errors)."""
    _enable_x64()
    from .papers.nath import euclidean_experiment, final_errors
    from .plots import plot_euclidean

    stages = _progress(2, "euclidean", quiet)
    stages.set_postfix_str("simulate and estimate (compiles once)")
    r = euclidean_experiment(duration, noise_px, seed=seed)
    stages.update()
    errors = final_errors(r)
    summary = {
        "final_position_error_m": [float(e) for e in errors],
        "duration_s": duration,
        "noise_px": noise_px,
        "final_camera_prediction_error_px": float(np.asarray(r.p_tilde_c[-1]).max()),
        "covariance_resets": int(r.resets[-1]),
    }
    stages.set_postfix_str("figure")
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        plot_euclidean(
            r,
            path=out / "euclidean.png",
            title=f"seed 004: adaptive LS structure, {duration:g} s at 1 kHz, "
            f"pixel noise {noise_px:g} px",
        )
        (out / "summary.json").write_text(json.dumps(summary, indent=2))
    stages.update()
    stages.close()
    print(
        f"Adaptive LS structure estimator (seed 004, eqs. 37-51): {duration:g} s at 1 kHz, "
        f"pixel noise {noise_px:g} px, uncalibrated camera"
    )
    for i, e in enumerate(errors):
        print(f"feature {i + 1}: final position error {e * 1000:8.3f} mm")
    print(
        f"camera prediction error {summary['final_camera_prediction_error_px']:.3f} px, "
        f"covariance resets {summary['covariance_resets']}"
    )
    if out is not None:
        print(f"wrote {out / 'summary.json'} and {out / 'euclidean.png'}")
    return summary


def compare_report(
    problem: str,
    data=None,
    noise: float = 0.1,
    seeds: int = 4,
    duration: float | None = None,
    out=None,
    quiet: bool = False,
) -> dict:
    """`visjax compare`: the paper's estimator, its batch baselines (all frames and a
    sliding window) and its EKF on identical noisy inputs (`visjax.studies.compare`), from
    the paper's scenario or a data file (noise added on top of its pixels). Writes
    `summary.json` (`{"records": [...], "settings": {...}}`, one record per method and
    seed), `records.csv` and `comparison.png`, and prints the medians per method."""
    _enable_x64()
    from . import studies

    factories = {
        "velocity": studies.velocity_problem,
        "structure": studies.structure_problem,
        "euclidean": studies.euclidean_problem,
    }
    if problem not in factories:
        raise ValueError(f"unknown problem {problem!r}; choose from {list(factories)}")
    kwargs = {} if duration is None else {"duration": duration}
    setup = factories[problem](data=data, noise_px=noise, **kwargs)
    records = studies.compare(
        setup.methods,
        setup.inputs,
        setup.score,
        seeds=seeds,
        updates=setup.updates,
        progress=not quiet,
    )
    summary = {
        "problem": problem,
        "data": None if data is None else str(data),
        "noise_px": noise,
        "seeds": seeds,
        "settings": setup.settings,
        "records": records,
    }
    print(
        f"{setup.name}: {seeds} noise seed(s) at {noise:g} px"
        + ("" if data is None else f" on top of {data}")
    )
    print(f"{'method':<14}{'failed':>8}{setup.label + ' (median)':>34}{'latency/sample (s)':>20}")
    for method in setup.methods:
        rows = [r for r in records if r["method"] == method]
        good = [setup.accuracy(r) for r in rows if r["result"] == "successful"]
        acc = f"{np.median(good):.4g}" if good else "-"
        lat = float(np.median([r["latency_s_per_sample"] for r in rows]))
        failed = sum(r["result"] != "successful" for r in rows)
        print(f"{method:<14}{failed:>8}{acc:>34}{lat:>20.3g}")
    if out is not None:
        import pandas as pd

        from .plots import plot_comparison

        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "summary.json").write_text(json.dumps(summary, indent=2))
        pd.DataFrame(records).to_csv(out / "records.csv", index=False)
        plot_comparison(
            records,
            setup.accuracy,
            label=setup.label,
            title=f"{setup.name}, {noise:g} px",
            path=out / "comparison.png",
        )
        print(f"wrote {out / 'summary.json'}, {out / 'records.csv'} and {out / 'comparison.png'}")
    return summary


def _tuning_setups(problem, data, noise, duration, rate, sets):
    """[(tag, TuningProblem)] of `visjax sweep` / `visjax tune`: one per thesis set for the
    structure problem (default: all seven), else one. Set-ups are cached per process (a
    data file by its path and modification time), so a `tune` after a `sweep` of the same
    problem reuses its calibration and its compiled runs."""
    import os

    if problem not in ("velocity", "structure", "euclidean"):
        raise ValueError(f"unknown problem {problem!r}; choose velocity, structure or euclidean")
    if problem == "structure":
        if data is not None:
            raise ValueError(
                "sweeps of the structure observer run on the thesis' sets (their published "
                "gains are the reference); --data is not supported for it"
            )
        from .papers.jang import SETS

        return [
            (n, _tuning_setup(problem, noise, None, None, duration, None, n))
            for n in list(sets or SETS)
        ]
    stamp = None if data is None else os.path.getmtime(data)
    data = None if data is None else str(data)
    return [(None, _tuning_setup(problem, noise, data, stamp, duration, rate, None))]


@functools.lru_cache(maxsize=16)
def _tuning_setup(problem, noise, data, stamp, duration, rate, set_name):
    from . import studies

    kwargs = {} if duration is None else {"duration": duration}
    if problem == "structure":
        return studies.structure_tuning(set_name=set_name, noise_px=noise, **kwargs)
    if rate is not None:
        kwargs["rate_hz"] = rate
    make = studies.velocity_tuning if problem == "velocity" else studies.euclidean_tuning
    return make(noise_px=noise, data=data, **kwargs)


def _held_out(setup, points: dict, seeds: int, chunk: int, mesh):
    """The metric of each named parameter point on the held-out noise seeds
    `seeds, ..., 2 seeds - 1` (never seen by the sweep or the tuning): `{name: {"params",
    "metric", "failed"}}` (`metric` the mean over the successful seeds)."""
    import jax.numpy as jnp

    from . import studies

    names = list(points)
    params = {k: np.array([float(points[n][k]) for n in names]) for k in points[names[0]]}
    table = studies.sweep(
        setup.factory,
        params,
        jnp.arange(seeds, 2 * seeds),
        metrics=setup.metrics,
        chunk=chunk,
        mesh=mesh,
    )
    out = {}
    for i, n in enumerate(names):
        rows = table[table["point"] == i]
        ok = rows["result"] == "successful"
        out[n] = {
            "params": {k: float(v) for k, v in points[n].items()},
            "metric": float(rows[ok][setup.metric].mean()) if ok.any() else float("nan"),
            "failed": int((~ok).sum()),
        }
    return out


def _mesh(shard: bool):
    if not shard:
        return None
    import jax
    from jax.sharding import Mesh

    return Mesh(np.array(jax.devices()), ("runs",))


def _finite_or_null(obj):
    """NaN and inf as JSON null (strict JSON; pandas and every parser load it)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite_or_null(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite_or_null(v) for v in obj]
    return obj


def _write_json(path, obj):
    path.write_text(json.dumps(_finite_or_null(obj), indent=2, allow_nan=False))


def _structure_lmi(setup, params) -> dict:
    """The LMI of section 3.6 of Jang's thesis for the gains at `params` (multipliers of the
    published ones): the Lipschitz bound they certify (`certified_lipschitz`), beside the
    published gains' own."""
    from .design import certified_lipschitz

    lmi = setup.settings["lmi"]
    A, C, D = (np.array(lmi[k], float) for k in ("A", "C", "D"))
    g = setup.gains(params)
    g0 = setup.gains(setup.paper)
    tuned = certified_lipschitz(A, C, D, np.array(g["K"]), np.array(g["Y"]))
    published = certified_lipschitz(A, C, D, np.array(g0["K"]), np.array(g0["Y"]))
    return {
        "certified_lipschitz": tuned,
        "published_certified_lipschitz": published,
        "satisfies_lmi": bool(tuned > 0),
        "covers_published_bound": bool(tuned >= published * (1 - 1e-6)),
    }


def _one_sweep(setup, grid, seeds, chunk, mesh, quiet):
    """Sweep one problem on the training seeds; returns (table, summary, best)."""
    import jax.numpy as jnp

    from . import studies

    params = studies.parse_grid(grid or setup.grid)
    table = studies.sweep(
        setup.factory,
        params,
        jnp.arange(seeds),
        metrics=setup.metrics,
        chunk=chunk,
        mesh=mesh,
        progress=not quiet,
    )
    summary = studies.summarise(table, setup.metric)
    best = studies.best(table, setup.metric)
    return table, summary, best


def _print_result(tag, setup, held, extra=""):
    head = f"[{tag}] " if tag else ""
    for name, r in held.items():
        gains = ", ".join(f"{k} x {v:.3g}" for k, v in r["params"].items())
        failed = f" ({r['failed']} held-out run(s) failed)" if r["failed"] else ""
        print(f"{head}{name:<11} {gains:<32} held-out {setup.metric} = {r['metric']:.4g}{failed}")
    if extra:
        print(f"{head}{extra}")


def sweep_report(
    problem: str,
    grid: str | None = None,
    noise: float = 0.1,
    seeds: int = 8,
    data=None,
    duration: float | None = None,
    rate: float | None = None,
    sets=None,
    chunk: int = 64,
    shard: bool = False,
    out=None,
    quiet: bool = False,
) -> dict:
    """`visjax sweep`: a grid of gain multipliers (`--grid`, default the problem's) over
    `seeds` noise seeds (`studies.sweep`), the best point by the mean metric, and the best
    point and the paper's gains re-measured on `seeds` held-out seeds. Writes `runs.parquet`,
    `runs.csv`, `sweep.png` and `summary.json` (`{"metric", "best": {"params", "metric"},
    "paper": {"params", "metric"}, ...}`, the metrics held-out); for the structure problem
    one folder per thesis set and a top-level `summary.json` of them by set."""
    _enable_x64()
    from . import studies
    from .plots import plot_sweep

    results = {}
    mesh = _mesh(shard)
    for tag, setup in _tuning_setups(problem, data, noise, duration, rate, sets):
        table, summary, best = _one_sweep(setup, grid, seeds, chunk, mesh, quiet)
        held = _held_out(setup, {"best": best["params"], "paper": setup.paper}, seeds, chunk, mesh)
        result = {
            "metric": setup.metric,
            "best": {"params": held["best"]["params"], "metric": held["best"]["metric"]},
            "paper": {"params": held["paper"]["params"], "metric": held["paper"]["metric"]},
            "problem": setup.name,
            "grid": grid or setup.grid,
            "noise_px": noise,
            "seeds": seeds,
            "held_out_seeds": [seeds, 2 * seeds - 1],
            "best_training_metric": best["metric"],
            "best_gains": setup.gains(best["params"]),
            "paper_gains": setup.gains(setup.paper),
            "failed_runs": int((table["result"] != "successful").sum()),
            "runs": len(table),
            "settings": setup.settings,
        }
        if problem == "structure":
            result["lmi"] = _structure_lmi(setup, best["params"])
        _print_result(
            tag, setup, held, f"{result['failed_runs']} of {len(table)} sweep runs failed"
        )
        results[tag] = result
        if out is not None:
            folder = Path(out) if tag is None else Path(out) / tag.replace(".", "_")
            studies.save_table(table, folder)
            _write_json(folder / "summary.json", result)
            plot_sweep(
                summary,
                setup.metric,
                list(setup.paper),
                best=held["best"],
                paper=held["paper"],
                label=setup.label,
                title=setup.name,
                path=folder / "sweep.png",
            )
    if out is not None and problem == "structure":
        _write_json(Path(out) / "summary.json", results)
    if out is not None:
        print(f"wrote {out}")
    return results if problem == "structure" else results[None]


def tune_report(
    problem: str,
    grid: str | None = None,
    noise: float = 0.1,
    seeds: int = 4,
    steps: int = 30,
    learning_rate: float = 0.1,
    data=None,
    duration: float | None = None,
    rate: float | None = None,
    sets=None,
    chunk: int = 64,
    shard: bool = False,
    out=None,
    quiet: bool = False,
) -> dict:
    """`visjax tune`: a sweep of the grid (`--grid`, default the problem's) on `seeds`
    training seeds, then `studies.tune` (Adam on the log gains, forward-mode gradients
    through the runner, `steps` steps) from the sweep's best point on the same seeds; the
    tuned gains, the sweep's best and the paper's gains re-measured on `seeds` held-out
    seeds. Writes `runs.parquet`, `runs.csv` (the sweep), `history.csv`, `sweep.png`,
    `tune.png` and `summary.json` (`{"metric", "best": {"params", "metric"}, "paper":
    {"params", "metric"}, ...}`: `best` is the tuned point, metrics held-out); for the
    structure problem one folder per thesis set (with the LMI check of the tuned gains)
    and a top-level `summary.json` of them by set."""
    _enable_x64()
    import jax.numpy as jnp
    import optax
    import pandas as pd

    from . import studies
    from .plots import plot_sweep, plot_tune_history

    results = {}
    mesh = _mesh(shard)
    for tag, setup in _tuning_setups(problem, data, noise, duration, rate, sets):
        table, summary, best = _one_sweep(setup, grid, seeds, chunk, mesh, quiet)
        tuned = studies.tune(
            setup.factory,
            best["params"],
            setup.loss,
            jnp.arange(seeds),
            optimiser=optax.adam(learning_rate),
            steps=steps,
            progress=not quiet,
        )
        held = _held_out(
            setup,
            {"tuned": tuned.params, "sweep best": best["params"], "paper": setup.paper},
            seeds,
            chunk,
            mesh,
        )
        result = {
            "metric": setup.metric,
            "best": {"params": held["tuned"]["params"], "metric": held["tuned"]["metric"]},
            "paper": {"params": held["paper"]["params"], "metric": held["paper"]["metric"]},
            "sweep_best": {
                "params": held["sweep best"]["params"],
                "metric": held["sweep best"]["metric"],
            },
            "improvement_over_paper": held["paper"]["metric"] / held["tuned"]["metric"],
            "problem": setup.name,
            "grid": grid or setup.grid,
            "noise_px": noise,
            "seeds": seeds,
            "held_out_seeds": [seeds, 2 * seeds - 1],
            "steps": steps,
            "optimiser": f"optax.adam({learning_rate}) on the log gains, forward mode",
            "training_loss": {"sweep_best": tuned.loss0, "tuned": tuned.loss},
            "tuned_gains": setup.gains(tuned.params),
            "paper_gains": setup.gains(setup.paper),
            "held_out_failed_runs": {k: v["failed"] for k, v in held.items()},
            "settings": setup.settings,
        }
        extra = (
            f"held-out improvement over the paper's gains: x {result['improvement_over_paper']:.3g}"
        )
        if problem == "structure":
            result["lmi"] = _structure_lmi(setup, tuned.params)
            extra += (
                f"; thesis RMS {setup.settings['thesis_rms_m']}; tuned gains satisfy the LMI "
                f"of section 3.6: {result['lmi']['satisfies_lmi']} (certified Lipschitz bound "
                f"{result['lmi']['certified_lipschitz']:.3g}, published gains "
                f"{result['lmi']['published_certified_lipschitz']:.3g})"
            )
        _print_result(tag, setup, held, extra)
        results[tag] = result
        if out is not None:
            folder = Path(out) if tag is None else Path(out) / tag.replace(".", "_")
            studies.save_table(table, folder)
            pd.DataFrame(tuned.history).to_csv(folder / "history.csv", index=False)
            _write_json(folder / "summary.json", result)
            plot_sweep(
                summary,
                setup.metric,
                list(setup.paper),
                best=held["tuned"],
                paper=held["paper"],
                label=setup.label,
                title=setup.name,
                path=folder / "sweep.png",
            )
            plot_tune_history(
                tuned.history,
                label=f"training {setup.metric}",
                title=setup.name,
                path=folder / "tune.png",
            )
    if out is not None and problem == "structure":
        _write_json(Path(out) / "summary.json", results)
    if out is not None:
        print(f"wrote {out}")
    return results if problem == "structure" else results[None]


def track_report(
    video,
    out,
    *,
    detector: str = "corners",
    max_features: int = 200,
    fb_threshold=0.5,
    fps=None,
    quiet: bool = False,
) -> dict:
    """Jang's thesis, sections 2.4 and 5.1: a video to pixel tracks by pyramidal KLT with a
    forward-backward check (`visjax.frontend.track_frames`).

    **Arguments:** `video` a file `visjax.frontend.read_video` reads (MP4 or `.npz`);
    `out` the tracks file: `.npz` with exactly the keys `t` (N,) seconds and `pixels`
    (N, n, 2), NaN where a feature is not seen (the convention of
    `visjax.io.load_tracks_csv`), or `.csv` written by `visjax.io.save_tracks_csv`;
    `detector`, `max_features`, `fb_threshold` as in `track_frames`; `fps` overrides the
    video's frame rate; `quiet` no progress bar and no summary line.

    **Returns:** the summary: frames, features, features in frame 0, fraction tracked.
    Raises `ValueError` (nothing written) when the detector finds no feature at all.
    """
    from .frontend import read_video, track_frames
    from .io import save_tracks_csv

    out = Path(out)
    if out.suffix.lower() not in (".npz", ".csv"):
        raise ValueError(f"{out}: the tracks file must end in .npz or .csv.")
    frames, video_fps = read_video(video)
    rate = video_fps if fps is None else fps
    if not (rate is not None and math.isfinite(rate) and rate > 0):
        raise ValueError(f"{video}: the video does not state its frame rate; give --fps.")
    tracks = track_frames(
        frames,
        fps=rate,
        detector=detector,
        max_features=max_features,
        fb_threshold=fb_threshold,
        progress=not quiet,
    )
    if tracks.pixels.shape[1] == 0:
        raise ValueError(f"{video}: the {detector!r} detector found no feature to track.")
    if out.suffix.lower() == ".csv":
        save_tracks_csv(out, tracks.t, tracks.pixels)
    else:
        with out.open("wb") as f:
            np.savez(f, t=tracks.t, pixels=tracks.pixels)
    summary = {
        "frames": int(frames.shape[0]),
        "fps": float(rate),
        "features": int(tracks.pixels.shape[1]),
        "features_frame0": int(np.sum(tracks.born == 0)),
        "fraction_tracked": tracks.fraction_tracked,
    }
    if not quiet:
        print(
            f"tracked {summary['frames']} frames at {rate:g} Hz: {summary['features']} features "
            f"({summary['features_frame0']} in frame 0), "
            f"{summary['fraction_tracked']:.1%} of feature-frames since detection tracked; "
            f"wrote {out}"
        )
    return summary


VPY_AMPLITUDES = (0.0, 0.05, 0.2, 0.5, 1.0, 2.0)
"""The sensitivity study's amplitudes of the second unknown input $v_{py}$ (in the unit
reading's length per second), fixed before any run."""


def _testbed_video(path, run, Kc_true, fps):
    """The rendered frames with the tracked point (green circle) and the estimate projected
    through the true camera (red cross) drawn on them, as an MP4."""
    import cv2

    from .frontend import write_video

    K = np.asarray(Kc_true, float)
    est = run.estimate[np.minimum(run.frame_index, run.estimate.shape[0] - 1)]
    out = np.empty(run.frames.shape + (3,), np.uint8)
    for i, frame in enumerate(run.frames):
        img = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
        p = run.pixels[i]
        if np.all(np.isfinite(p)):
            cv2.circle(img, (int(round(p[0])), int(round(p[1]))), 6, (0, 200, 0), 1, cv2.LINE_AA)
        e = est[i]
        if np.all(np.isfinite(e)) and e[2] > 0:
            q = K[:2, :2] @ (e[:2] / e[2]) + K[:2, 2]
            if np.all(np.abs(q) < 1e4):
                cv2.drawMarker(
                    img,
                    (int(round(q[0])), int(round(q[1]))),
                    (0, 0, 230),
                    cv2.MARKER_CROSS,
                    12,
                    1,
                    cv2.LINE_AA,
                )
        cv2.putText(
            img,
            f"{run.set_name}  t = {run.frame_ts[i]:5.2f} s",
            (8, 20),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.5,
            (255, 255, 255),
            1,
            cv2.LINE_AA,
        )
        out[i] = img
    write_video(path, out, fps)


def _testbed_record(run, thesis_rms) -> dict:
    def floats(x):
        return [float(v) for v in x] if np.all(np.isfinite(x)) else None

    return {
        "rms": floats(run.rms),
        "thesis_rms": list(thesis_rms),
        "tracking_rms_px": float(run.tracking_rms_px) if run.feasible else None,
        "units": run.units,
        "rms_frames": floats(run.rms_frames),
        "rms_ideal_pixels": floats(run.rms_ideal),
        "feasible": bool(run.feasible),
        "reason": run.reason,
        "result": run.result,
        "duration_s": run.duration,
        "scoring": "RMS over the second half of the run: `rms` at every 1 kHz sample, "
        "`rms_frames` at the 30 Hz camera samples only, `rms_ideal_pixels` at 1 kHz from "
        "the exact projections instead of the tracked pixels",
    }


def testbed_report(
    sets=None,
    units: str = "cm",
    duration: float = 30.0,
    *,
    seed: int = 0,
    video: bool = True,
    studies: bool = True,
    out=None,
    quiet: bool = False,
) -> dict:
    """Jang's thesis, chapters 4-5, on the testbed twin (`visjax.papers.jang.testbed`): each
    set end to end, Tables 5-3/5-4 beside the thesis', figures like Figs. 5-5 to 5-8, an MP4
    of the rendered frames per set, and with `studies` the least-squares camera matrix of
    section 2.3 from set I.1's data with Tables 5-1/5-2 redone, and the sensitivity of the
    moving sets to the amplitude of $v_{py}$.

    Writes `summary.json` (per set: `rms`, `thesis_rms`, `tracking_rms_px`, `units`, and the
    scoring), `tables.csv` (Tables 5-3/5-4, one row per set and axis), `testbed_<set>.png`,
    `testbed_<set>.mp4`, `testbed_<set>.npz`, and with `studies` `calibration.json` and
    `sensitivity.csv`.
    """
    _enable_x64()
    from tqdm import tqdm

    from .papers.jang import KC_REFINED, SETS, UNITS, testbed
    from .plots import plot_testbed

    names = _thesis_set_names(sets)
    if units not in UNITS:
        raise ValueError(f"`units` must be one of {list(UNITS)}; got {units!r}")
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
    t_start = time.time()
    summary, runs = {}, {}
    for name in tqdm(names, desc="testbed", unit="set", disable=quiet):
        keep = out is not None and video
        r = testbed(name, units=units, duration=duration, keep_frames=keep, seed=seed)
        summary[name] = _testbed_record(r, SETS[name].thesis_rms)
        if out is not None:
            kind = "moving" if SETS[name].moving else "static"
            if r.feasible:
                plot_testbed(
                    r,
                    path=out / f"testbed_{name}.png",
                    title=f"Jang's thesis, set {name} ({kind} point) on the testbed twin: A "
                    f"read in {units}/s, camera 30 Hz, observer 1 kHz",
                )
            arrays = {
                k: np.asarray(getattr(r, k))
                for k in (
                    "ts",
                    "position",
                    "estimate",
                    "estimate_ideal",
                    "frame_ts",
                    "frame_index",
                    "pixels",
                    "pixels_true",
                    "velocity_true",
                    "velocity_measured",
                    "q_puma",
                )
            }
            if r.q_arm is not None:
                arrays["q_arm"] = np.asarray(r.q_arm)
            np.savez(out / f"testbed_{name}.npz", **arrays)
            if keep and r.frames is not None:
                _testbed_video(out / f"testbed_{name}.mp4", r, KC_REFINED, 30.0)
        runs[name] = r.__class__(**{**r.__dict__, "frames": None})

    print(
        f"UIO (Jang's thesis, eq. 3.5) on the testbed twin: A read in {units}/s, "
        f"{duration:g} s, RMS position error over the second half (m), at 1 kHz"
    )
    _print_thesis_tables(summary, names, "twin")
    for n in names:
        if not summary[n]["feasible"]:
            print(f"{n}: {summary[n]['reason']}")

    if studies:
        _testbed_studies(runs, names, units, duration, seed, out, quiet)
    if out is not None:
        _write_json(out / "summary.json", summary)
        import pandas as pd

        rows = []
        for name in names:
            e = summary[name]
            for i, axis in enumerate("xyz"):
                rows.append(
                    {
                        "set": name,
                        "table": "5-3" if name.startswith("I.") else "5-4",
                        "axis": axis,
                        "units": units,
                        "rms_m": e["rms"][i] if e["rms"] else None,
                        "rms_frames_m": e["rms_frames"][i] if e["rms_frames"] else None,
                        "rms_ideal_pixels_m": (
                            e["rms_ideal_pixels"][i] if e["rms_ideal_pixels"] else None
                        ),
                        "thesis_rms_m": e["thesis_rms"][i],
                        "feasible": e["feasible"],
                    }
                )
        pd.DataFrame(rows).to_csv(out / "tables.csv", index=False)
        print(f"\nwrote {out / 'summary.json'}, tables.csv, testbed_<set>.png/.mp4/.npz")
    if not quiet:
        print(f"({time.time() - t_start:.0f} s)")
    return summary


def _testbed_studies(runs, names, units, duration, seed, out, quiet) -> dict:
    """Section 2.3's least squares from set I.1 with Tables 5-1/5-2 redone, and the
    sensitivity of the moving sets to $v_{py}$ (exact pixels, so that only $v_{py}$ varies)."""
    from tqdm import tqdm

    from .geometry import camera_matrix, camera_matrix_lstsq
    from .papers.jang import KC_REFINED, KC_TOOLBOX, SETS, testbed

    result = {}
    base = runs.get("I.1")
    if base is not None and base.feasible:
        cam = base.position[base.frame_index]
        m = cam[:, :2] / cam[:, 2:]
        ok = np.all(np.isfinite(base.pixels), axis=1)
        theta = np.asarray(camera_matrix_lstsq(m[ok], base.pixels[ok]))
        K_ls = np.asarray(camera_matrix(theta))
        tables = {}
        for set_name, table, thesis in (
            (
                "I.2",
                "table_5_1",
                {"toolbox": (0.0121, 0.0349, 0.0958), "least_squares": (0.0119, 0.0179, 0.0800)},
            ),
            (
                "II.1",
                "table_5_2",
                {"toolbox": (0.0172, 0.0248, 0.0548), "least_squares": (0.0172, 0.0170, 0.0519)},
            ),
        ):
            row = {"set": set_name, "thesis": {k: list(v) for k, v in thesis.items()}}
            for label, K in (("toolbox", KC_TOOLBOX), ("least_squares", K_ls)):
                r = testbed(set_name, units=units, duration=duration, Kc_observer=K, seed=seed)
                row[label] = [float(x) for x in r.rms] if r.feasible else None
            tables[table] = row
        result["calibration"] = {
            "theta_least_squares": [float(x) for x in theta],
            "Kc_least_squares": K_ls.tolist(),
            "Kc_true": np.asarray(KC_REFINED).tolist(),
            "Kc_toolbox": np.asarray(KC_TOOLBOX).tolist(),
            "Kc_thesis_least_squares": np.asarray(KC_REFINED).tolist(),
            "frames_used": int(ok.sum()),
            **tables,
            "note": "the twin renders with the thesis' least-squares Kc as the true camera; "
            "the observer is given the toolbox Kc or the least squares of section 2.3 from "
            "set I.1's tracked pixels and the forward-kinematics truth",
        }
        print(
            "\nsection 2.3 least squares from set I.1 (twin): [f, af, cx, cy] = "
            + ", ".join(f"{x:.2f}" for x in theta)
            + "  (true 551.98, 737.51, 304.03, 331.51)"
        )
        for table, row in tables.items():
            for label in ("toolbox", "least_squares"):
                v = row[label]
                cells = ", ".join(f"{x:.4f}" for x in v) if v else "infeasible"
                th = ", ".join(f"{x:.4f}" for x in row["thesis"][label])
                print(f"{table} ({row['set']}), {label} Kc: {cells}   (thesis {th})")
        if out is not None:
            _write_json(out / "calibration.json", result["calibration"])
    moving = [n for n in names if SETS[n].moving]
    rows = []
    for name in tqdm(moving, desc="v_py sensitivity", unit="set", disable=quiet or not moving):
        for a in VPY_AMPLITUDES:
            r = testbed(
                name,
                units=units,
                duration=duration,
                vp_amplitude=(SETS[name].vp_amplitude[0], a),
                track=False,
                seed=seed,
            )
            rms = r.rms if r.feasible else np.full(3, np.nan)
            rows.append(
                {
                    "set": name,
                    "units": units,
                    "v_py_amplitude": a,
                    "rms_x": float(rms[0]),
                    "rms_y": float(rms[1]),
                    "rms_z": float(rms[2]),
                    "feasible": bool(r.feasible),
                    "result": r.result,
                }
            )
    if rows:
        import pandas as pd

        table = pd.DataFrame(rows)
        result["sensitivity"] = table
        print(f"\nsensitivity to v_py (amplitude in {units}/s; exact pixels), RMS (m):")
        print(table.to_string(index=False, float_format=lambda x: f"{x:.4f}"))
        if out is not None:
            table.to_csv(out / "sensitivity.csv", index=False)
    return result


def reproduce(out="results", quick: bool = False, quiet: bool = False) -> dict:
    """Every paper's main experiment into one folder, then a summary table."""
    out = Path(out)
    results = {}
    print("== seed 000, section 6: velocity estimator ==")
    results["velocity"] = velocity_report(out=out / "velocity", quiet=quiet)
    print("\n== seed 000, section 3: Euclidean reconstruction vs OpenCV ==")
    results["geometry"] = geometry_report(scenes=20 if quick else 100, out=out / "geometry")
    print("\n== seed 003: unknown input observer, the thesis' seven sets (simulated) ==")
    results["structure"] = structure_report(
        duration=20.0 if quick else 30.0, noise=0.1, out=out / "structure", quiet=quiet
    )
    print("\n== seed 004: Euclidean structure from an uncalibrated moving camera ==")
    results["euclidean"] = euclidean_report(
        duration=20.0 if quick else 30.0, out=out / "euclidean", quiet=quiet
    )
    print("\n== Jang's thesis, chapters 4-5: the testbed twin (PUMA 560, rendered video, KLT) ==")
    results["testbed"] = testbed_report(
        ["I.1", "II.1"] if quick else None,
        "cm",
        10.0 if quick else 30.0,
        studies=not quick,
        out=out / "testbed",
        quiet=quiet,
    )
    v, g = results["velocity"], results["geometry"]["errors"]
    rows = [
        ("000 velocity, max RMS 5-10 s (m/s, rad/s)", f"{max(v['rms_5_10s']):.4f}", "< 0.05"),
        ("000 z1* recovered (m)", f"{v['z1_star_recovered']:.6f}", "1.99"),
        (
            "000 reconstruction, max R_bar error (deg)",
            f"{g['visjax']['R_bar_deg']['max']:.1e}",
            f"OpenCV {g['opencv']['R_bar_deg']['max']:.1e}",
        ),
    ]
    st = results["structure"]
    static = [n for n in st if n.startswith("I.")]
    moving = [n for n in st if n.startswith("II.")]
    for names, what in ((static, "static"), (moving, "moving")):
        mean = float(np.mean([st[n]["rms"] for n in names]))
        thesis = float(np.mean([st[n]["thesis_rms"] for n in names]))
        rows.append((f"003 UIO {what} point, mean RMS (m)", f"{mean:.4f}", f"thesis {thesis:.4f}"))
    tb = results["testbed"]
    for name in tb:
        rms = tb[name]["rms"]
        value = f"{max(rms):.4f}" if rms is not None else "infeasible"
        rows.append(
            (
                f"003 twin set {name}, worst-axis RMS (m)",
                value,
                f"thesis {max(tb[name]['thesis_rms']):.4f}",
            )
        )
    e = results["euclidean"]["final_position_error_m"]
    rows.append(("004 structure, max final position error (mm)", f"{max(e) * 1000:.3f}", "aim 1"))
    print("\n== summary ==")
    for name, value, ref in rows:
        print(f"{name:<46}{value:>12}   ({ref})")
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(
        json.dumps({"rows": [dict(zip(("what", "value", "reference"), r)) for r in rows]}, indent=2)
    )
    print(f"wrote {out}/ (velocity/, geometry/, structure/, euclidean/, testbed/, summary.json)")
    return results
