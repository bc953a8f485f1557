"""The reproduction report: each paper's experiment as figures, `summary.json` and the
printed tables, and `reproduce`, which runs them all. The command line calls these.

Every `summary.json` follows its schema in `visjax.io.SUMMARIES` (checked when it is
written) and records the visjax version, the settings, the seed and the wall time;
estimated trajectories go to NPZ files and tables to Parquet (`visjax.io.TABLES`,
`visjax.io.ARRAYS`); figures are written in every format of `formats` (png, pdf, svg).
"""

import datetime
import math
import time
from pathlib import Path

import numpy as np

FORMATS = ("png", "pdf", "svg")


def _summary(kind: str, body: dict, *, settings: dict, seed, started: float, out=None) -> dict:
    """The summary of a command: `body` with the keys every summary has (`visjax.io.COMMON`),
    checked against its schema, written to `out / "summary.json"` when `out` is given."""
    import jax

    from . import __version__
    from .io import finite_or_null, validate_summary, write_summary

    summary = {
        "kind": kind,
        "visjax_version": __version__,
        "jax_version": jax.__version__,
        "created_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "wall_time_s": time.perf_counter() - started,
        "seed": seed,
        "settings": {k: (str(v) if isinstance(v, Path) else v) for k, v in settings.items()},
        **body,
    }
    if out is not None:
        return write_summary(Path(out) / "summary.json", summary)
    return validate_summary(finite_or_null(summary))


def _check_seeds(seeds, noise) -> None:
    if not (isinstance(seeds, int) and not isinstance(seeds, bool) and seeds >= 1):
        raise ValueError(f"`seeds` must be a positive int; got {seeds!r}.")
    if seeds > 1 and not noise > 0:
        raise ValueError(
            f"{seeds} seeds need pixel noise (`noise` > 0): noise-free runs are all the same."
        )


def _median(rows) -> list:
    """The median over seeds (the first axis), as a list of floats."""
    return [float(x) for x in np.median(np.asarray(rows, float), axis=0)]


def _stack(runs):
    """Runs (Modules of arrays) stacked on a leading seed axis, as NumPy arrays."""
    import jax

    return jax.tree_util.tree_map(lambda *xs: np.stack([np.asarray(x) for x in xs]), *runs)


def _files(path, formats) -> str:
    """The figure files written for `path` in `formats`, for the printed file list."""
    return ", ".join(str(Path(path).with_suffix("." + f)) for f in formats)


def _enable_x64():
    """The command line runs in float64 (the library itself never flips the flag)."""
    import jax

    jax.config.update("jax_enable_x64", True)


def _progress(total: int, desc: str, quiet: bool):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="stage", disable=quiet)


def geometry_report(
    scenes: int = 100,
    points: int = 4,
    noise: float = 0.0,
    seed: int = 0,
    out=None,
    formats=("png",),
    quiet: bool = False,
) -> dict:
    """Chitrakaran et al., section 3: random planar scenes reconstructed by visjax and by
    OpenCV, both against ground truth. Writes `summary.json` (kind `geometry`),
    `scenes.parquet` (one row per scene and method, `visjax.io.TABLES`) and the figure
    `geometry.<format>`."""
    started = time.perf_counter()
    settings = dict(scenes=scenes, points=points, noise=noise, seed=seed, formats=list(formats))
    _enable_x64()
    from .papers.chitrakaran import geometry_study
    from .plots import plot_geometry

    stages = _progress(2, "geometry", quiet)
    stages.set_postfix_str("visjax (batched) and OpenCV (per scene)")
    sc, ours, errors, seconds = geometry_study(scenes, points, noise, seed)
    stages.update()
    body = {
        "scenes": scenes,
        "points": points,
        "noise_px": noise,
        "seconds": seconds,
        "errors": {
            who: {
                k: {"median": float(np.median(v)), "max": float(np.max(v))} for k, v in errs.items()
            }
            for who, errs in errors.items()
        },
    }
    if out is not None:
        import pandas as pd

        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        stages.set_postfix_str("figure")
        pd.concat(
            [
                pd.DataFrame({"scene": np.arange(scenes), "method": who, **errs})
                for who, errs in errors.items()
            ],
            ignore_index=True,
        ).to_parquet(out / "scenes.parquet", index=False)
        plot_geometry(sc, ours, errors, path=out / "geometry.png", formats=formats)
    stages.update()
    stages.close()
    summary = _summary("geometry", body, settings=settings, seed=seed, started=started, out=out)

    print(
        "Euclidean reconstruction from a homography (Chitrakaran et al., section 3): "
        f"{scenes} random planar scenes, {points} points, pixel noise {noise} px"
    )
    print(
        f"{'error vs ground truth':<22}{'visjax median':>15}{'visjax max':>13}"
        f"{'OpenCV median':>15}{'OpenCV max':>13}"
    )
    for k in errors["visjax"]:
        v, c = summary["errors"]["visjax"][k], summary["errors"]["opencv"][k]
        print(f"{k:<22}{v['median']:>15.3e}{v['max']:>13.3e}{c['median']:>15.3e}{c['max']:>13.3e}")
    t = summary["seconds"]
    print(
        f"time: visjax {t['visjax'] * 1e3:.2f} ms batched (+{t['visjax_compile']:.1f} s compile), "
        f"OpenCV {t['opencv'] * 1e3:.2f} ms loop"
    )
    if out is not None:
        print(
            f"wrote {out / 'summary.json'}, {out / 'scenes.parquet'}, "
            f"{_files(out / 'geometry.png', formats)}"
        )
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
    formats=("png",),
    seeds: int = 1,
) -> dict:
    """Chitrakaran et al., section 6: the velocity estimator on the paper's simulation.
    Writes `summary.json` (kind `velocity`: RMS and max error per DOF over the scoring
    window), `estimate.npz` (`t`, `v_hat`, `velocity`) and `velocity.<format>` (like the
    paper's Fig. 2), and prints the RMS table. With `seeds` > 1 (and noise), the noise seeds
    `seed, ..., seed + seeds - 1`: the errors are their medians (each seed's in
    `rms_window_seeds`), `v_hat` has a leading seed axis and the figure shows the median
    error and its 10-90 % band over the seeds."""
    started = time.perf_counter()
    _check_seeds(seeds, noise)
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
    settings = dict(
        duration=duration, rate=rate, noise=noise, seed=seed, seeds=seeds, K=K, rho=rho,
        formats=list(formats),
    )  # fmt: skip
    stages = _progress(3 + seeds, "velocity", quiet)
    started_stages = []

    def progress(stage):
        if started_stages:
            stages.update()
        started_stages.append(stage)
        stages.set_postfix_str(stage)

    runs = []
    for i in range(seeds):
        if i:
            progress(f"seed {seed + i}")
        runs.append(
            velocity_experiment(
                duration, rate, noise, K=K, rho=rho, seed=seed + i, progress=None if i else progress
            )
        )
    per_seed = [summarise(r, duration, rate, noise) for r in runs]
    body = dict(per_seed[0])
    if seeds > 1:
        body["seeds"] = seeds
        for key in ("rms_window", "max_window"):
            body[key] = _median([p[key] for p in per_seed])
        body["rms_window_seeds"] = [p["rms_window"] for p in per_seed]
        body["z1_star_recovered_seeds"] = [p["z1_star_recovered"] for p in per_seed]
        body["z1_star_recovered"] = float(np.median(body["z1_star_recovered_seeds"]))
        n_mean = np.mean([p["n_star_recovered"] for p in per_seed], axis=0)
        body["n_star_recovered"] = [float(x) for x in n_mean / np.linalg.norm(n_mean)]
    body["K"], body["rho"] = [float(k) for k in K], [float(x) for x in rho]
    r = runs[0]
    estimate = np.asarray(r.estimate) if seeds == 1 else np.stack([x.estimate for x in runs])
    progress("figure")
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        np.savez(
            out / "estimate.npz",
            t=np.asarray(r.ts),
            v_hat=estimate,
            velocity=np.asarray(r.velocity),
        )
        title = (
            f"velocity estimator (Chitrakaran et al.), section 6: {rate:g} Hz, {duration:g} s, "
            f"pixel noise {noise:g} px" + (f", {seeds} seeds" if seeds > 1 else "")
        )
        plot_velocity(
            r.ts, r.velocity, estimate, title=title, path=out / "velocity.png", formats=formats
        )
    stages.update()
    stages.close()
    summary = _summary(
        "velocity",
        body,
        settings=settings,
        seed=seed if noise > 0 else None,
        started=started,
        out=out,
    )

    a, b = summary["window_s"]
    print(
        "Velocity estimator (Chitrakaran et al., eqs. 39-40), section-6 simulation: "
        f"{duration:g} s at {rate:g} Hz, pixel noise {noise:g} px"
    )
    if seeds > 1:
        print(f"medians over {seeds} noise seeds ({seed} to {seed + seeds - 1})")
    print(f"recovered z1* = {summary['z1_star_recovered']:.6f} m")
    print(f"{'DOF':<6}{f'RMS {a:g}-{b:g} s':>16}{f'max {a:g}-{b:g} s':>16}")
    for name, rms, mx in zip(DOF_NAMES, summary["rms_window"], summary["max_window"]):
        unit = "m/s" if name.startswith("v") else "rad/s"
        print(f"{name:<6}{rms:>16.5f}{mx:>16.5f}  {unit}")
    if out is not None:
        print(
            f"wrote {out / 'summary.json'}, {out / 'estimate.npz'}, "
            f"{_files(out / 'velocity.png', formats)}"
        )
    return summary


def velocity_data_report(
    path, out=None, quiet: bool = False, filter_hz=None, formats=("png",)
) -> dict:
    """The velocity estimator of Chitrakaran et al. on a user's data file
    (`visjax.io.VelocityData`, run by `papers.velocity_from_file`): $n^*$ from the frames,
    $z_1^*$ from the known length, the estimate in the camera and object frames
    (`estimate.npz`), `summary.json` (kind `velocity_data`) with `z1_star` and, when the
    file has the true `velocity`, `rms_last_half` (6 floats over the second half of the
    run), and `velocity.<format>`."""
    started = time.perf_counter()
    settings = dict(data=str(path), filter_hz=filter_hz, formats=list(formats))
    _enable_x64()
    from .papers import velocity_from_file
    from .papers.chitrakaran import DOF_NAMES
    from .plots import plot_velocity

    stages = _progress(2, "velocity", quiet)
    stages.set_postfix_str("reconstruct every frame, estimate")
    run = velocity_from_file(path, filter_hz)
    stages.update()
    title = f"velocity estimator (Chitrakaran et al.) on {Path(path).name}"
    out = _write_file_run(run, out, "velocity", plot_velocity, title, formats)
    stages.update()
    stages.close()
    summary = _summary(
        "velocity_data", run.body, settings=settings, seed=None, started=started, out=out
    )
    print(
        f"Velocity estimator (Chitrakaran et al., eqs. 39-40) on {path}: "
        f"{summary['samples']} frames"
    )
    print(f"recovered z1* = {summary['z1_star']:.6f} m; result: {summary['result']}")
    _print_last_half(summary, "RMS error", DOF_NAMES)
    return _finish_file_run(run, out, "velocity", formats, summary)


def _write_file_run(run, out, name, plot, title, formats):
    """`estimate.npz` and the figure of a run on a data file, into `out` (if given)."""
    if out is None:
        return None
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    np.savez(out / "estimate.npz", **run.arrays)
    plot(run.t, run.truth, run.estimate, title=title, path=out / f"{name}.png", formats=formats)
    return out


def _print_last_half(summary, what, names):
    if "rms_last_half" in summary:
        a, b = summary["window_s"]
        rms = summary["rms_last_half"]
        print(f"{what} {a:g}-{b:g} s: " + ", ".join(f"{n} {r:.4g}" for n, r in zip(names, rms)))


def _finish_file_run(run, out, name, formats, summary):
    """The files written, then the run's failure (if any) as an error."""
    if out is not None:
        print(
            f"wrote {out / 'summary.json'}, {out / 'estimate.npz'}, "
            f"{_files(out / f'{name}.png', formats)}"
        )
    if run.failure is not None:
        raise RuntimeError(run.failure)
    return summary


def structure_data_report(path, out=None, quiet: bool = False, formats=("png",)) -> dict:
    """The unknown input observer of Jang's thesis (eq. (3.5)) on a user's data file
    (`visjax.io.StructureData`, run by `papers.moving_point_from_file`).

    The observer and its gains come from `visjax.papers.moving_point_observer_for_data`
    (gains designed by `design_uio_for_motion` for the file's camera motion; motion
    outside the design's model reported in `summary.json` as `unmodelled_motion`).
    Dropped frames (NaN pixels) are extrapolated from the last two seen. The observer
    runs at 1 kHz on the held frames. Writes `estimate.npz` (`t`, `position`, `x_hat`),
    `summary.json` (kind `structure_data`; with the truth, `rms_last_half`, 3 floats, m, at
    the frame times of the second half) and `structure.<format>`."""
    started = time.perf_counter()
    settings = dict(data=str(path), formats=list(formats))
    _enable_x64()
    from .papers import moving_point_from_file
    from .plots import plot_structure

    stages = _progress(2, "structure", quiet)
    stages.set_postfix_str("design the gains (LMI), estimate")
    run = moving_point_from_file(path)
    stages.update()
    title = f"unknown input observer (Jang's thesis) on {Path(path).name}"
    out = _write_file_run(run, out, "structure", plot_structure, title, formats)
    stages.update()
    stages.close()
    summary = _summary(
        "structure_data", run.body, settings=settings, seed=None, started=started, out=out
    )
    rate = summary["design"]["convergence_rate_per_s"]
    print(
        f"Unknown input observer (Jang's thesis, eq. 3.5) on {path}: {summary['frames']} "
        f"frames, gains by design_uio_for_motion (rate {rate:.3g}/s); result: "
        f"{summary['result']}"
    )
    _print_last_half(summary, "RMS position error (m)", "XYZ")
    return _finish_file_run(run, out, "structure", formats, summary)


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
    formats=("png",),
    seeds: int = 1,
) -> dict:
    """Jang's thesis: the UIO on the simulated analogues of the seven experiment sets.
    Writes `summary.json` (kind `structure`: per set the RMS position error beside the
    thesis' Tables 5-3/5-4), `sets.parquet` (one row per set and axis), per set
    `estimate_<set>.npz` (`t`, `position`, `estimate`), `structure_<set>.<format>` (like
    Figs. 5-7/5-8) and `camera_velocity_<set>.<format>` (like Figs. 5-5/5-6), and prints the
    tables. With `seeds` > 1, the noise seeds `seed, ..., seed + seeds - 1`: each set's `rms`
    is their median (each seed's in `rms_seeds`), `estimate` has a leading seed axis and the
    figures show the median error and its 10-90 % band."""
    started = time.perf_counter()
    _check_seeds(seeds, noise)
    names = _thesis_set_names(sets)
    settings = dict(
        sets=names, duration=duration, noise=noise, seed=seed, seeds=seeds, formats=list(formats)
    )
    _enable_x64()
    from tqdm import tqdm

    from .papers.jang import SETS, structure_experiment
    from .plots import plot_camera_velocity, plot_structure

    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
    per_set = {}
    for name in tqdm(names, desc="structure", unit="set", disable=quiet):
        runs = [structure_experiment(name, duration, noise, seed=seed + i) for i in range(seeds)]
        r = runs[0]
        rms = [[float(x) for x in run.rms] for run in runs]
        per_set[name] = {"rms": rms[0] if seeds == 1 else _median(rms)}
        if seeds > 1:
            per_set[name]["rms_seeds"] = rms
        per_set[name]["thesis_rms"] = list(SETS[name].thesis_rms)
        estimate = np.asarray(r.estimate) if seeds == 1 else np.stack([x.estimate for x in runs])
        if out is not None:
            kind = "moving" if SETS[name].moving else "static"
            np.savez(
                out / f"estimate_{name}.npz",
                t=np.asarray(r.ts),
                position=np.asarray(r.position),
                estimate=estimate,
            )
            plot_structure(
                r.ts,
                r.position,
                estimate,
                path=out / f"structure_{name}.png",
                formats=formats,
                title=f"unknown input observer (Jang's thesis), set {name} ({kind} point), "
                f"simulated: pixel noise {noise:g} px, camera 30 Hz, observer 1 kHz",
            )
            plot_camera_velocity(
                r.frame_ts,
                r.camera_velocity,
                path=out / f"camera_velocity_{name}.png",
                formats=formats,
                title=f"Jang's thesis, set {name}: camera velocity (simulated analogue)",
            )
    body = {"duration_s": duration, "noise_px": noise, "sets": per_set}
    if seeds > 1:
        body["seeds"] = seeds
    if out is not None:
        import pandas as pd

        pd.DataFrame(
            [
                {
                    "set": name,
                    "axis": axis,
                    "rms_m": per_set[name]["rms"][i],
                    "thesis_rms_m": per_set[name]["thesis_rms"][i],
                }
                for name in names
                for i, axis in enumerate("xyz")
            ]
        ).to_parquet(out / "sets.parquet", index=False)
    summary = _summary(
        "structure",
        body,
        settings=settings,
        seed=seed if noise > 0 else None,
        started=started,
        out=out,
    )
    print(
        f"Unknown input observer (Jang's thesis, eq. 3.5), simulated analogues: "
        f"{duration:g} s, pixel noise {noise:g} px, RMS position error over the second half (m)"
    )
    _print_thesis_tables(per_set, names, "visjax")
    if out is not None:
        print(
            f"\nwrote {out / 'summary.json'}, sets.parquet, estimate_<set>.npz, "
            f"structure_<set> and camera_velocity_<set> ({', '.join(formats)})"
        )
    return summary


def euclidean_data_report(path, out=None, quiet: bool = False, formats=("png",)) -> dict:
    """The adaptive structure estimator of Nath et al. on a user's data file
    (`visjax.io.EuclideanData`, run by `papers.static_points_from_file`): built from the
    nominal camera of the file (`AdaptiveStructureEstimator.from_nominal`: initial guesses
    and gains from the scene's scale, never from a truth), run at 1 kHz on the held
    samples (at the samples if they are faster), features out of view (NaN) masked in both
    laws. Writes `estimate.npz` (`t`, `features` (M, n - k, 3), the recovered camera `A`,
    `R_c`, `x_c` over time), `summary.json` (kind `euclidean_data`: the final features and
    camera; with the truth, `final_position_error_m`, n - k floats) and
    `euclidean.<format>`."""
    started = time.perf_counter()
    settings = dict(data=str(path), formats=list(formats))
    _enable_x64()
    from .papers import static_points_from_file
    from .plots import plot_feature_estimates

    stages = _progress(2, "euclidean", quiet)
    stages.set_postfix_str("estimate (compiles once)")
    run = static_points_from_file(path)
    stages.update()
    title = f"adaptive structure estimator (Nath et al.) on {Path(path).name}"

    def plot(t, truth, features, **kwargs):  # its order: the estimate, then the truth
        return plot_feature_estimates(t, features, truth, **kwargs)

    out = _write_file_run(run, out, "euclidean", plot, title, formats)
    stages.update()
    stages.close()
    summary = _summary(
        "euclidean_data", run.body, settings=settings, seed=None, started=started, out=out
    )
    k = summary["known_features"]
    print(
        f"Adaptive LS structure estimator (Nath et al., eqs. 37-51) on {path}: "
        f"{summary['frames']} frames, {k} known and {summary['unknown_features']} unknown "
        f"features; result: {summary['result']}"
    )
    for i, e in enumerate(summary.get("final_position_error_m", [])):
        print(f"feature {k + i + 1}: final position error {e * 1000:8.3f} mm")
    return _finish_file_run(run, out, "euclidean", formats, summary)


def euclidean_report(
    duration: float = 30.0,
    noise: float = 0.0,
    seed: int = 0,
    out=None,
    quiet: bool = False,
    formats=("png",),
    seeds: int = 1,
) -> dict:
    """Nath et al.: the adaptive least-squares structure estimator on its simulation.
    Writes `summary.json` (kind `euclidean`: the final position errors), `estimate.npz`
    (`t`, `features` over time, `truth`) and `euclidean.<format>`. With `seeds` > 1, the
    noise seeds `seed, ..., seed + seeds - 1`: the errors are their medians (each seed's in
    `final_position_error_m_seeds`), `features` has a leading seed axis and the figure shows
    the medians and their 10-90 % bands."""
    started = time.perf_counter()
    _check_seeds(seeds, noise)
    settings = dict(duration=duration, noise=noise, seed=seed, seeds=seeds, formats=list(formats))
    _enable_x64()
    from .papers.nath import euclidean_experiment, final_errors
    from .plots import plot_euclidean

    stages = _progress(1 + seeds, "euclidean", quiet)
    stages.set_postfix_str("simulate and estimate (compiles once)")
    runs = []
    for i in range(seeds):
        runs.append(euclidean_experiment(duration, noise, seed=seed + i))
        stages.update()
    r = runs[0] if seeds == 1 else _stack(runs)
    per_seed = [[float(e) for e in final_errors(x)] for x in runs]
    errors = per_seed[0] if seeds == 1 else _median(per_seed)
    body = {
        "final_position_error_m": errors,
        "duration_s": duration,
        "noise_px": noise,
        "final_camera_prediction_error_px": float(
            np.median([np.asarray(x.p_tilde_c[-1]).max() for x in runs])
        ),
        "covariance_resets": int(np.median([int(x.resets[-1]) for x in runs])),
    }
    if seeds > 1:
        body["seeds"] = seeds
        body["final_position_error_m_seeds"] = per_seed
    stages.set_postfix_str("figure")
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        np.savez(
            out / "estimate.npz",
            t=np.asarray(runs[0].ts),
            features=np.asarray(r.omega_s),
            truth=np.asarray(runs[0].omega_true),
        )
        plot_euclidean(
            r,
            path=out / "euclidean.png",
            formats=formats,
            title=f"adaptive least-squares structure estimator (Nath et al.): {duration:g} s "
            f"at 1 kHz, pixel noise {noise:g} px" + (f", {seeds} seeds" if seeds > 1 else ""),
        )
    stages.update()
    stages.close()
    summary = _summary(
        "euclidean",
        body,
        settings=settings,
        seed=seed if noise > 0 else None,
        started=started,
        out=out,
    )
    print(
        "Adaptive least-squares structure estimator (Nath et al., eqs. 37-51): "
        f"{duration:g} s at 1 kHz, pixel noise {noise:g} px, uncalibrated camera"
        + (f"; medians over {seeds} noise seeds" if seeds > 1 else "")
    )
    for i, e in enumerate(errors):
        print(f"feature {i + 1}: final position error {e * 1000:8.3f} mm")
    print(
        f"camera prediction error {summary['final_camera_prediction_error_px']:.3f} px, "
        f"covariance resets {summary['covariance_resets']}"
    )
    if out is not None:
        print(
            f"wrote {out / 'summary.json'}, {out / 'estimate.npz'}, "
            f"{_files(out / 'euclidean.png', formats)}"
        )
    return summary


def _write_json(path, obj):
    """Strict JSON (NaN and inf as null), for files that are not summaries."""
    import json

    from .io import finite_or_null

    path.write_text(json.dumps(finite_or_null(obj), indent=2, allow_nan=False))


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
    from .frontend import annotate_frames, write_video

    K = np.asarray(Kc_true, float)
    est = np.asarray(run.estimate)[np.minimum(run.frame_index, run.estimate.shape[0] - 1)]
    in_front = np.all(np.isfinite(est), axis=-1) & (est[:, 2] > 0)
    z = np.where(in_front, est[:, 2], 1.0)
    projected = (est[:, :2] / z[:, None]) @ K[:2, :2].T + K[:2, 2]
    projected = np.where(in_front[:, None], projected, np.nan)
    captions = [f"{run.set_name}  t = {t:5.2f} s" for t in np.asarray(run.frame_ts)]
    write_video(path, annotate_frames(run.frames, run.pixels, projected, captions), fps)


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
    formats=("png",),
) -> dict:
    """Jang's thesis, chapters 4-5, on the testbed twin (`visjax.papers.jang.testbed`): each
    set end to end, Tables 5-3/5-4 beside the thesis', figures like Figs. 5-5 to 5-8, an MP4
    of the rendered frames per set, and with `studies` the least-squares camera matrix of
    section 2.3 from set I.1's data with Tables 5-1/5-2 redone, and the sensitivity of the
    moving sets to the amplitude of $v_{py}$.

    Writes `summary.json` (kind `testbed`; per set: `rms`, `thesis_rms`, `tracking_rms_px`,
    and the scoring), `tables.parquet` and `tables.csv` (Tables 5-3/5-4, one row per set
    and axis), `testbed_<set>.<format>`, `testbed_<set>.mp4`, `testbed_<set>.npz`, and with
    `studies` `calibration.json`, `sensitivity.parquet` and `sensitivity.csv`.
    """
    started = time.perf_counter()
    names = _thesis_set_names(sets)
    settings = dict(
        sets=names,
        units=units,
        duration=duration,
        seed=seed,
        video=video,
        studies=studies,
        formats=list(formats),
    )
    _enable_x64()
    from tqdm import tqdm

    from .papers.jang import KC_REFINED, SETS, UNITS, testbed
    from .plots import plot_testbed

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
                    formats=formats,
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
        table = pd.DataFrame(rows)
        table.to_parquet(out / "tables.parquet", index=False)
        table.to_csv(out / "tables.csv", index=False)
    body = {"units": units, "duration_s": duration, "sets": summary}
    summary = _summary("testbed", body, settings=settings, seed=seed, started=started, out=out)
    if out is not None:
        print(
            f"\nwrote {out / 'summary.json'}, tables.parquet/.csv, testbed_<set>.npz/.mp4 and "
            f"testbed_<set> ({', '.join(formats)})"
        )
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
            table.to_parquet(out / "sensitivity.parquet", index=False)
            table.to_csv(out / "sensitivity.csv", index=False)
    return result


QUICK = {
    "geometry_scenes": (100, 20),
    "structure_duration_s": (30.0, 20.0),
    "euclidean_duration_s": (30.0, 20.0),
    "testbed_sets": (None, ["I.1", "II.1"]),
    "testbed_duration_s": (30.0, 10.0),
    "testbed_studies": (True, False),
}


def quick_help() -> str:
    """What `reproduce --quick` shortens (the command line's help)."""

    def show(v):
        return "all" if v is None else ("/".join(v) if isinstance(v, list) else f"{v:g}")

    changes = ", ".join(
        f"{k.replace('_', ' ')} {show(full)} -> {show(quick)}"
        for k, (full, quick) in QUICK.items()
        if not isinstance(full, bool)
    )
    return (
        f"shorter runs: {changes}, and the testbed without its studies (the camera matrix "
        "of section 2.3, the v_py sensitivity); the velocity simulation runs in full. "
        "results/ then differs from the documentation's tables, which are full runs"
    )


"""What `reproduce --quick` changes: (full, quick) per setting. The velocity simulation
(10 s at 1 kHz) runs in full either way."""


def reproduce(out="results", quick: bool = False, quiet: bool = False, formats=("png",)) -> dict:
    """Every paper's main experiment into one folder, then a summary table (`summary.json`,
    kind `reproduce`, and `summary.parquet`: one row per figure, its value as a number,
    its unit and the paper's reference). `quick` shortens the runs as `QUICK` says."""
    started = time.perf_counter()
    q = {k: v[1] if quick else v[0] for k, v in QUICK.items()}
    settings = dict(out=str(out), quick=quick, formats=list(formats), **q)
    out = Path(out)
    results = {}
    print("== Chitrakaran et al., section 6: the velocity estimator ==")
    results["velocity"] = velocity_report(out=out / "velocity", quiet=quiet, formats=formats)
    print("\n== Chitrakaran et al., section 3: Euclidean reconstruction vs OpenCV ==")
    results["geometry"] = geometry_report(
        scenes=q["geometry_scenes"], out=out / "geometry", quiet=quiet, formats=formats
    )
    print("\n== Jang's thesis: the unknown input observer on the seven sets (simulated) ==")
    results["structure"] = structure_report(
        duration=q["structure_duration_s"],
        noise=0.1,
        out=out / "structure",
        quiet=quiet,
        formats=formats,
    )
    print("\n== Nath et al.: Euclidean structure from an uncalibrated moving camera ==")
    results["euclidean"] = euclidean_report(
        duration=q["euclidean_duration_s"], out=out / "euclidean", quiet=quiet, formats=formats
    )
    print("\n== Jang's thesis, chapters 4-5: the testbed twin (PUMA 560, rendered video, KLT) ==")
    results["testbed"] = testbed_report(
        q["testbed_sets"],
        "cm",
        q["testbed_duration_s"],
        studies=q["testbed_studies"],
        out=out / "testbed",
        quiet=quiet,
        formats=formats,
    )
    v, g = results["velocity"], results["geometry"]["errors"]
    a, b = v["window_s"]
    rows = [
        (
            f"Chitrakaran et al., velocity: largest RMS error {a:g}-{b:g} s",
            max(v["rms_window"]),
            "m/s or rad/s",
            0.05,
            "bound",
        ),
        ("Chitrakaran et al., z1* recovered", v["z1_star_recovered"], "m", 1.99, "truth"),
        (
            "Chitrakaran et al., reconstruction: largest R_bar error",
            g["visjax"]["R_bar_deg"]["max"],
            "deg",
            g["opencv"]["R_bar_deg"]["max"],
            "OpenCV",
        ),
    ]
    st = results["structure"]["sets"]
    static = [n for n in st if n.startswith("I.")]
    moving = [n for n in st if n.startswith("II.")]
    for names, what in ((static, "static"), (moving, "moving")):
        mean = float(np.mean([st[n]["rms"] for n in names]))
        thesis = float(np.mean([st[n]["thesis_rms"] for n in names]))
        rows.append((f"Jang's thesis, UIO, {what} point: mean RMS", mean, "m", thesis, "published"))
    tb = results["testbed"]["sets"]
    for name in tb:
        rms = tb[name]["rms"]
        rows.append(
            (
                f"Jang's thesis, testbed twin set {name}: worst-axis RMS"
                + ("" if rms is not None else " (infeasible)"),
                max(rms) if rms is not None else None,
                "m",
                float(max(tb[name]["thesis_rms"])),
                "published",
            )
        )
    e = results["euclidean"]["final_position_error_m"]
    rows.append(
        (
            "Nath et al., structure: largest final position error",
            max(e) * 1000,
            "mm",
            1.0,
            "bound",
        )
    )
    columns = ("what", "value", "unit", "reference", "reference_kind")
    table = [dict(zip(columns, r)) for r in rows]
    print("\n== summary ==")
    for r in table:
        value = "infeasible" if r["value"] is None else f"{r['value']:.4g}"
        bound = "< " if r["reference_kind"] == "bound" else ""
        reference = f"{r['reference_kind']} {bound}{r['reference']:.4g}"
        print(f"{r['what']:<62}{value:>12} {r['unit']:<13}({reference})")
    out.mkdir(parents=True, exist_ok=True)
    import pandas as pd

    pd.DataFrame(table, columns=list(columns)).astype(
        {"value": float, "reference": float}
    ).to_parquet(out / "summary.parquet", index=False)
    _summary(
        "reproduce",
        {"quick": quick, "rows": table},
        settings=settings,
        seed=None,
        started=started,
        out=out,
    )
    print(
        f"wrote {out}/ (velocity/, geometry/, structure/, euclidean/, testbed/, summary.json, "
        "summary.parquet)"
    )
    return results
