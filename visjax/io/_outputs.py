"""The outputs of the command line as documented formats: the keys of every `summary.json`
and the columns of every table the commands write.

Every `summary.json` is one JSON object, strict JSON (a non-finite number is `null`),
numbers stored as numbers. It loads with `json.load`, and with pandas as a Series
(`pandas.read_json(path, typ="series", precise_float=True)`, nested objects kept as
Python values; without `precise_float` pandas rounds the last digits) or one row
(`pandas.json_normalize(json.load(f))`). Its key `kind` names its schema in `SUMMARIES`;
every summary has the keys of `COMMON` (the visjax version, the settings, the seed, the wall
time). Tables are Parquet files (and CSV where a spreadsheet is handy) with the columns of
`TABLES`; estimated trajectories are NPZ files with the arrays of `ARRAYS`.

A type is one of `str`, `int`, `float`, `bool`, `dict`, `list[str]`, `list[float]`,
`list[int]`, `list[dict]`, `list[list[float]]`, or several joined by `|` (`float|null`: a
number, or `null` where it is not finite or does not apply). A key ending in `?` is
present only in some runs (the description says when).
"""

import json
import math
import warnings
from pathlib import Path

from ._staging import unstaged

COMMON = {
    "kind": ("str", "the schema of this summary (a key of `visjax.io.SUMMARIES`)"),
    "visjax_version": ("str", "the visjax version that wrote it"),
    "jax_version": ("str", "the JAX version"),
    "backend?": (
        "str",
        "JAX's default backend that computed it (`cpu`, `gpu`, `tpu`); absent only from "
        "summaries of earlier versions",
    ),
    "device?": (
        "str",
        "the first device of that backend (`cpu`, `NVIDIA H200`, ...); absent only from "
        "summaries of earlier versions",
    ),
    "dtype?": (
        "str",
        "the floating-point type it computed in: `float64` (`jax_enable_x64`, the command "
        "line's default) or `float32` (`--dtype float32`); absent only from summaries of "
        "earlier versions",
    ),
    "created_utc": ("str", "when it was written, ISO 8601, UTC"),
    "wall_time_s": ("float", "the command's wall time, s (compilation included)"),
    "seed": ("int|null", "the first noise seed (`null` where nothing is random)"),
    "settings": ("dict", "every option of the command, by its Python name"),
}

_ORDER = ("list[str]", "the order of the six components: vx, vy, vz, wx, wy, wz")
_DATA_RESULT = (
    "str",
    "`successful`; the result code of a run that stopped; `too_many_dropped_frames` "
    "(a successful run on a file whose frames miss a feature in more than "
    "`visjax.io.MAX_DROPPED_FRACTION` of them); or `worse_than_trivial` (with the truth: "
    "an error at least `visjax.studies.QUALITY_RATIO` times the trivial estimate's, "
    "`quality`)",
)
_INNOVATION = (
    "the observer's output error against the noise level the data imply, over the second "
    "half (`visjax.studies.judge_innovation`): `output_rms` and `noise_rms` per measured "
    "output, `ratio` (the worst `output_rms / noise_rms`), `threshold` "
    "(`visjax.studies.INNOVATION_GATE`), `samples`, `flag` (`ok` or `innovation_too_large`, "
    "a printed warning that leaves the `result` as it is; then also `quality.flag` where "
    "the truth's verdict is `ok`)"
)
_DROPPED = (
    "float",
    "the fraction of the file's frames with a feature missing (`dropped_fraction()`), or, "
    "where more, of the frames the estimator held (features degenerate, or not those of "
    "the frames before); always written (absent only from summaries of earlier versions)",
)
_DROPPED_STUDY = (
    "float",
    "with `--data` in one of the papers' formats: the fraction of the file's frames with a "
    "feature missing (`dropped_fraction()`)",
)
_FAILED_SAMPLE = ("int", "when the run stopped: the sample it stopped at (its time is printed)")

SUMMARIES = {
    "geometry": {
        "scenes": ("int", "random planar scenes"),
        "points": ("int", "points per scene"),
        "noise_px": ("float", "pixel noise sigma, px"),
        "seconds": ("dict", "`visjax_compile`, `visjax` (batched) and `opencv` (loop), s"),
        "errors": (
            "dict",
            "per method (`visjax`, `opencv`) and error (`H_max_abs`, `R_bar_deg`, `x_h_abs`, "
            "`n_star_deg`, `alpha_rel`): `median` and `max` over the scenes",
        ),
    },
    "velocity": {
        "order": _ORDER,
        "window_s": ("list[float]", "the scoring window [start, end), s (the paper's 5-10 s)"),
        "rms_window": ("list[float]", "RMS velocity error per component over the window"),
        "max_window": ("list[float]", "largest absolute error per component over the window"),
        "rate_hz": ("float", "sample rate, Hz"),
        "noise_px": ("float", "pixel noise sigma, px"),
        "duration_s": ("float", "simulated time, s"),
        "z1_star_recovered": ("float", "the reference depth of feature 1 from the known length, m"),
        "n_star_recovered": ("list[float]", "the plane normal measured from the frames"),
        "K": ("list[float]", "the diagonal of the gain K (eq. (63) by default)"),
        "rho": ("list[float]", "the diagonal of the gain rho"),
        "seeds?": ("int", "with `--seeds` > 1: the noise seeds; the errors are medians"),
        "rms_window_seeds?": ("list[list[float]]", "with `--seeds` > 1: each seed's RMS"),
        "z1_star_recovered_seeds?": ("list[float]", "with `--seeds` > 1: each seed's z1*"),
    },
    "velocity_data": {
        "z1_star": ("float", "the reference depth of feature 1, m"),
        "n_star": ("list[float]", "the plane normal measured from the frames"),
        "result": _DATA_RESULT,
        "order": _ORDER,
        "samples": ("int", "frames in the file"),
        "dropped_frames": ("int", "frames with too few features seen, held over"),
        "integration_step_s": ("float|null", "the Euler step (`null`: the frame times)"),
        "K": ("list[float]", "the diagonal of K"),
        "rho": ("list[float]", "the diagonal of rho"),
        "rms_last_half?": ("list[float]", "with the truth: RMS error over the second half"),
        "window_s?": ("list[float]", "with the truth: that window, s"),
        "filter_hz?": ("float", "with `--filter-hz`: the low-pass bandwidth, Hz"),
        "filter_delay_s?": ("float", "with `--filter-hz`: the filter's group delay, s"),
        "quality?": (
            "dict",
            "with the truth: the worst RMS error against zero velocity's over the same "
            "window (`trivial`, `ratio_to_trivial`, per component `ratios`, `threshold`, "
            "`flag`: `ok` or `worse_than_trivial`, then also the `result`); with or without "
            "it, for a run that did not stop, `innovation`: " + _INNOVATION,
        ),
        "dropped_fraction?": _DROPPED,
        "failed_sample?": _FAILED_SAMPLE,
    },
    "moving_point": {
        "duration_s": ("float", "simulated time per set, s"),
        "noise_px": ("float", "pixel noise sigma, px"),
        "sets": (
            "dict",
            "per thesis set (`I.1` ... `II.3`): `rms` (x, y, z position RMS error over the "
            "second half, m; with `--seeds` > 1 the median, each seed's in `rms_seeds`) and "
            "`thesis_rms` (Tables 5-3/5-4)",
        ),
        "seeds?": ("int", "with `--seeds` > 1: the noise seeds"),
    },
    "structure_data": {
        "result": _DATA_RESULT,
        "frames": ("int", "frames in the file"),
        "dropped_frames": ("int", "frames where the point was not seen"),
        "integration_step_s": ("float", "the observer's Euler step, s"),
        "depth_guess_m": ("float", "the observer's initial depth guess, m"),
        "D": ("list[float]", "the direction of the unknown input"),
        "design": (
            "dict",
            "the LMI design for the file's camera motion: `method`, `alpha`, "
            "`convergence_rate_per_s`",
        ),
        "unmodelled_motion": (
            "float",
            "the largest camera velocity outside the design's model (v_cz, w_x, w_y)",
        ),
        "rms_last_half?": ("list[float]", "with the truth: x, y, z RMS error, second half, m"),
        "window_s?": ("list[float]", "with the truth: that window, s"),
        "quality?": (
            "dict",
            "with the truth: the worst RMS error against the initial depth guess held on "
            "each frame's ray, over the same window (as for `velocity_data`); `innovation` "
            "as for `velocity_data`, the outputs the frame's normalized image coordinates",
        ),
        "dropped_fraction?": _DROPPED,
        "failed_sample?": _FAILED_SAMPLE,
    },
    "static_points": {
        "final_position_error_m": ("list[float]", "per unknown feature, at the end, m"),
        "duration_s": ("float", "simulated time, s"),
        "noise_px": ("float", "pixel noise sigma, px"),
        "final_camera_prediction_error_px": ("float", "largest camera prediction error, px"),
        "covariance_resets": ("int", "covariance resets of the camera law (eq. (40))"),
        "seeds?": ("int", "with `--seeds` > 1: the noise seeds; the errors are medians"),
        "final_position_error_m_seeds?": (
            "list[list[float]]",
            "with `--seeds` > 1: each seed's final errors",
        ),
    },
    "euclidean_data": {
        "result": _DATA_RESULT,
        "frames": ("int", "frames in the file"),
        "known_features": ("int", "features of known position"),
        "unknown_features": ("int", "features estimated"),
        "missing_observations": ("int", "feature-frames not seen"),
        "integration_step_s": ("float|null", "the Euler step (`null`: the frame times)"),
        "final_features_m": ("list[list[float]]", "the estimated features at the end, m"),
        "camera": ("dict", "the camera estimated at the end: `A`, `R_c`, `x_c`"),
        "final_position_error_m?": ("list[float]", "with the truth: per feature, m"),
        "dropped_fraction?": _DROPPED,
        "failed_sample?": _FAILED_SAMPLE,
    },
    "run": {
        "problem": ("str", "the problem's description (its source and noise)"),
        "method": ("str", "the method run (the estimator, or a baseline)"),
        "result": (
            "str",
            "the result code's name (`successful`, or why it failed; "
            "`too_many_dropped_frames` as for `velocity_data`)",
        ),
        "failed_sample": ("int", "the sample at which the run failed, -1 if it did not"),
        "metrics": ("dict", "the problem's metrics against the truth (`null` if it failed)"),
        "gains": ("dict", "the gains run (the problem's defaults)"),
        "problem_settings": ("dict", "the problem's scenario and methods"),
        "dropped_fraction?": _DROPPED_STUDY,
        "quality?": (
            "dict",
            "with the truth, for a problem with a trivial estimate (`studies.quality`): "
            "`trivial_estimate`, `metric`, `trivial` (its value), `ratio_to_trivial`, "
            "`threshold`, `flag` (`ok`, or `worse_than_trivial`, then also the `result`); "
            "for an observer with an output-error check (`problem.innovation`), with or "
            "without the truth, `innovation`: " + _INNOVATION,
        ),
    },
    "compare": {
        "problem": ("str", "the registered problem's name (as given on the command line)"),
        "data": ("str|null", "the data file, or `null` for the paper's scenario"),
        "noise_px": (
            "float|list[float]|null",
            "pixel noise sigma, px (`--noise a,b,c`: the levels; default the problem's own, "
            "`null` for a problem without a `noise_px` data parameter)",
        ),
        "seeds": ("int", "noise seeds"),
        "problem_settings": ("dict", "the problem's scenario and methods"),
        "records": ("list[dict]", "one per method and seed (the rows of `records.parquet`)"),
        "statistics?": (
            "dict",
            "`Comparison.statistics` of the headline `metric`: per method (`methods`) the "
            "`median` over the successful runs, its 95% bootstrap interval (`low`, `high`), "
            "`n`, `runs`, `failure_rate` and each result code's count (`results`); per pair "
            "(`pairs`: `a`, `b`) the `median_difference` a - b on the seeds both succeeded "
            "on, its interval and the Wilcoxon signed-rank `pvalue`",
        ),
        "tuning?": (
            "dict",
            "`--tune` (`studies.Tuning.as_json`): `search`, `budget` (evaluations per "
            "method), `metric`, `train_seeds` (disjoint from the records' seeds) and per "
            "method (`methods`) the `searched` parameters with their ranges, the tuned "
            "`params`, their `defaults`, `train_median` and `train_failed` at the tuned "
            "point and at the defaults (`..._at_defaults`), and `evaluations`",
        ),
        "dropped_fraction?": _DROPPED_STUDY,
        "quality?": (
            "dict",
            "with the truth, for a problem with a trivial estimate: `trivial_estimate`, "
            "`metric`, `trivial` (its value), `threshold`, and `worse_than_trivial`, per "
            "method the successful runs whose metric is at least `threshold` times the "
            "trivial one (each record's `ratio_to_trivial`)",
        ),
    },
    "sweep": {
        "metric": ("str", "the metric minimised"),
        "best": (
            "dict",
            "`params` (the grid's parameters) and held-out `metric` of the best point",
        ),
        "paper": ("dict", "the same for the parameters' defaults (the paper's values)"),
        "problem": ("str", "the problem's name"),
        "method?": ("str", "the method swept (`--methods`; default the estimator)"),
        "grid": ("str", "the grid of the problem's parameters"),
        "noise_px": ("float|null", "pixel noise sigma, px (`null`: the problem states none)"),
        "seeds": ("int", "training noise seeds"),
        "held_out_seeds": ("list[int]", "the first and last held-out seed"),
        "best_training_metric": ("float|null", "the best point's metric on the training seeds"),
        "best_gains": ("dict", "the best point's gains"),
        "paper_gains": ("dict", "the paper's gains"),
        "failed_runs": ("int", "sweep runs that did not succeed"),
        "runs": ("int", "sweep runs"),
        "problem_settings": ("dict", "the problem's scenario"),
        "lmi?": ("dict", "moving_point on a thesis set: the LMI check of the best gains"),
        "dropped_fraction?": _DROPPED_STUDY,
    },
    "tune": {
        "metric": ("str", "the metric minimised"),
        "best": ("dict", "`params` and held-out `metric` of the tuned gains"),
        "paper": ("dict", "the same for the paper's gains"),
        "sweep_best": ("dict", "the same for the sweep's best point"),
        "improvement_over_paper": ("float|null", "paper's held-out metric / tuned one"),
        "problem": ("str", "the problem's name"),
        "method?": ("str", "the method tuned (`--methods`; default the estimator)"),
        "grid": ("str", "the grid of the sweep"),
        "noise_px": ("float|null", "pixel noise sigma, px (`null`: the problem states none)"),
        "seeds": ("int", "training noise seeds"),
        "held_out_seeds": ("list[int]", "the first and last held-out seed"),
        "steps": ("int", "optimiser steps"),
        "optimiser": ("str", "the optimiser"),
        "training_loss": ("dict", "`sweep_best` and `tuned` training loss"),
        "tuning_improved": (
            "bool",
            "a step's training loss was below the start's (`false`: "
            "the tuned point is the sweep's best)",
        ),
        "tuned_step": ("int", "the optimiser step of the tuned point (0: the start)"),
        "tuned_gains": ("dict", "the tuned gains"),
        "paper_gains": ("dict", "the paper's gains"),
        "held_out_failed_runs": ("dict", "failed held-out runs per point"),
        "problem_settings": ("dict", "the problem's scenario"),
        "lmi?": ("dict", "moving_point on a thesis set: the LMI check of the tuned gains"),
        "dropped_fraction?": _DROPPED_STUDY,
    },
    "sweep_shard": {
        "runs": ("int", "the runs of this slice"),
        "shard": ("list[int]", "`[i, N]`: the i-th of N slices (`--shard i/N`)"),
        "parts": ("str", "the folder of the slice's parts (`visjax merge` reads them)"),
    },
    "merge": {
        "runs": ("int", "runs in the merged table"),
        "chunks": ("int", "the sweep's chunks, each one part"),
        "sources": ("list[str]", "the parts folders merged"),
        "failed_runs": ("int", "runs that did not succeed"),
        "metric": ("str|null", "the sweep's metric (`null` for a functional sweep)"),
        "best?": ("dict|null", "the best point by the mean metric over the seeds"),
    },
    "sets": {
        "sets": (
            "dict",
            "per variant of the problem (a thesis set), the summary of its folder (its "
            "`kind` says which)",
        ),
    },
    "testbed": {
        "units": ("str", "the unit read for the velocities of the thesis' A matrices"),
        "duration_s": ("float", "time per set, s"),
        "sets": (
            "dict",
            "per set: `rms`, `thesis_rms`, `tracking_rms_px`, `rms_frames`, "
            "`rms_ideal_pixels`, `feasible`, `reason`, `result`, `scoring` (null where the "
            "run was infeasible)",
        ),
    },
    "point_depth": {
        "duration_s": ("float", "the simulated time, s"),
        "noise_px": ("float", "pixel noise sigma, px"),
        "projections": (
            "dict",
            "per projection (`planar`, `spherical`): `deviation` (the largest gap between "
            "the depth error z(t)/z(0) and the assigned second-order response), "
            "`time_to_5pct_s` and `ideal_time_to_5pct_s` (from when each stays below 5%), "
            "`sigma2_ratio_final` (sigma^2 over its target at the end)",
        ),
    },
    "homography": {
        "noise_px": ("float", "pixel noise sigma, px"),
        "seeds": ("int", "noise seeds"),
        "duration_s": ("float", "the simulated time, s"),
        "metric": ("str", "the velocity problem's metric (`rms_worst`)"),
        "trivial": ("float", "the metric of answering zero velocity"),
        "methods": (
            "dict",
            "per front end (`observer`, `four_point`): `median` (the metric's median over "
            "the seeds that succeeded, `null` if none) and `failed` (runs that did not)",
        ),
    },
    "reproduce": {
        "quick": ("bool", "whether `--quick` shortened the runs"),
        "rows": (
            "list[dict]",
            "the summary table, one row per registered reproduction's number "
            "(`visjax.studies.ROW_KEYS`): `name`, `value` (a number, `null` if infeasible), "
            "`reference` (a number, in `unit`), `reference_kind` (what the reference is: "
            "`published` (the paper's value), `truth` (the simulation's), `bound` (the "
            "largest value the project accepts), `OpenCV` (OpenCV's result on the same "
            "input), `ideal` (the response the paper's law assigns), `trivial` (the error "
            "of a trivial estimate)) and `unit`",
        ),
    },
}

TABLES = {
    "run/estimates.parquet": {
        "t": "float (s)",
        "<column>": "float (each component of each saved output of the method, named by the "
        "problem: docs/tables.md)",
        "<column>_true": "float (the truth beside an estimate that has one)",
    },
    "geometry/scenes.parquet": {
        "scene": "int",
        "method": "str",
        "H_max_abs": "float",
        "R_bar_deg": "float",
        "x_h_abs": "float",
        "n_star_deg": "float",
        "alpha_rel": "float",
    },
    "moving_point/sets.parquet": {
        "set": "str",
        "axis": "str",
        "rms_m": "float",
        "thesis_rms_m": "float",
    },
    "testbed/tables.parquet": {
        "set": "str",
        "table": "str",
        "axis": "str",
        "rms_m": "float",
        "rms_frames_m": "float",
        "rms_ideal_pixels_m": "float",
        "thesis_rms_m": "float",
        "feasible": "bool",
    },
    "testbed/sensitivity.parquet": {
        "set": "str (a moving set)",
        "v_py_amplitude_<unit>_s": "float (`<unit>` the `--units` of the A matrices: cm or m)",
        "axis": "str (x, y, z)",
        "rms_m": "float (NaN: infeasible)",
        "feasible": "bool",
        "result": "str",
    },
    "testbed/error_budget.parquet": {
        "set": "str (I.1, II.1: visjax.papers.jang.BUDGET_SETS)",
        "sources": "str (none, one of visjax.papers.jang.ERROR_SOURCES, or all)",
        "reading": "str (stated: the source's stated value; else its other reading's label)",
        "axis": "str (x, y, z)",
        "rms_m": "float (NaN: the run did not succeed)",
        "thesis_rms_m": "float (Tables 5-3/5-4)",
        "tracking_rms_px": "float",
        "result": "str",
    },
    "compare/tuning.parquet": {
        "method": "str",
        "evaluation": "int (0: the defaults)",
        "<parameter>": "float (each searched parameter of the method; `--tune`)",
        "failed": "int (training seeds failed)",
        "median": "float (the headline metric's median over the others)",
    },
    "reproduce summary.parquet": {
        "name": "str",
        "value": "float",
        "reference": "float",
        "reference_kind": "str",
        "unit": "str",
    },
}

ARRAYS = {
    "point_depth/transient.npz": {
        "t": "(N,) s",
        "ideal": "(N,) the assigned second-order response of the depth error, z(t)/z(0)",
        "z_ratio_planar": "(N,) the measured z(t)/z(0), planar projection",
        "z_ratio_spherical": "(N,) the same, spherical projection",
    },
    "velocity/estimate.npz": {
        "t": "(N,) s",
        "v_hat": "(N, 6) the estimate [v_e, w_e] in the camera frame, m/s and rad/s; "
        "(S, N, 6) with `--seeds` S",
        "velocity": "(N, 6) the true velocity",
    },
    "moving_point/estimate_<set>.npz": {
        "t": "(N,) s",
        "position": "(N, 3) the true point in the camera frame, m",
        "estimate": "(N, 3) the observer's estimate, m; (S, N, 3) with `--seeds` S",
    },
    "static_points/estimate.npz": {
        "t": "(M,) s",
        "features": "(M, n, 3) the estimated unknown features, m; (S, M, n, 3) with `--seeds` S",
        "truth": "(n, 3) their true positions, m",
    },
}

_SCALARS = {"str": str, "bool": bool, "dict": dict}


def _is(value, spec: str) -> bool:
    for kind in spec.split("|"):
        if kind == "null" and value is None:
            return True
        if kind == "int" and isinstance(value, int) and not isinstance(value, bool):
            return True
        if kind == "float" and isinstance(value, (int, float)) and not isinstance(value, bool):
            return True
        if kind in _SCALARS and isinstance(value, _SCALARS[kind]):
            return True
        if kind.startswith("list[") and isinstance(value, list):
            inner = kind[5:-1]
            if all(_is(v, inner + ("|null" if inner == "float" else "")) for v in value):
                return True
    return False


def validate_summary(summary: dict) -> dict:
    """Check a summary against its schema (`COMMON` and `SUMMARIES[summary["kind"]]`):
    every required key present with its type, no key the schema does not name. Returns the
    summary; raises `ValueError` naming the first key that is wrong."""
    if not isinstance(summary, dict):
        raise ValueError(f"a summary is a JSON object; got {type(summary).__name__}.")
    kind = summary.get("kind")
    kind = RENAMED_KINDS.get(kind, kind) if isinstance(kind, str) else kind
    if kind not in SUMMARIES:
        raise ValueError(f"summary `kind` must be one of {sorted(SUMMARIES)}; got {kind!r}.")
    schema = {**COMMON, **SUMMARIES[kind]}
    for key, (spec, _) in schema.items():
        name = key.rstrip("?")
        if name not in summary:
            if key.endswith("?"):
                continue
            raise ValueError(f"{kind} summary: the key {name!r} is missing.")
        if not _is(summary[name], spec):
            raise ValueError(
                f"{kind} summary: {name!r} must be {spec}; got {type(summary[name]).__name__} "
                f"{summary[name]!r:.80}."
            )
    known = {k.rstrip("?") for k in schema}
    extra = sorted(set(summary) - known)
    if extra:
        raise ValueError(f"{kind} summary: keys not in its schema: {extra}.")
    return summary


def finite_or_null(obj):
    """NaN and inf as `None` (JSON `null`), NumPy scalars and arrays as Python numbers and
    lists, throughout a nested structure."""
    if hasattr(obj, "tolist") and not isinstance(obj, (str, bytes)):
        obj = obj.tolist()
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): finite_or_null(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite_or_null(v) for v in obj]
    return obj


def write_summary(path, summary: dict) -> dict:
    """Validate `summary` and write it to `path` as strict JSON; returns what was written.
    Inside `staged_output`, paths name the final folder, not the staging one."""

    clean = validate_summary(finite_or_null(unstaged(summary)))
    Path(path).write_text(json.dumps(clean, indent=2, allow_nan=False))
    return clean


READ_ONLY_KINDS = {
    "velocity_data": "velocity",
    "structure_data": "moving_point",
    "euclidean_data": "static_points",
}
"""Summary kinds that visjax 0.3 wrote and reads still (with a `FutureWarning`), by the
problem whose `visjax PROBLEM --data FILE` wrote them: that command now writes kind `run`."""

RENAMED_KINDS = {"structure": "moving_point", "euclidean": "static_points"}
"""Summary kinds of visjax 0.3 (old -> new): read as the new kind, with a `FutureWarning`."""


def read_summary(path):
    """A `summary.json` as a `pandas.Series` (nested objects as Python values), checked
    against its schema. A summary of a kind of `READ_ONLY_KINDS` or `RENAMED_KINDS` (read
    as its new kind) is read with a `FutureWarning`."""
    import pandas as pd

    summary = validate_summary(json.loads(Path(path).read_text()))
    if summary["kind"] in RENAMED_KINDS:
        warnings.warn(
            f"{path}: summary kind {summary['kind']!r} of visjax 0.3 is now "
            f"{RENAMED_KINDS[summary['kind']]!r}",
            FutureWarning,
            stacklevel=2,
        )
    problem = READ_ONLY_KINDS.get(summary["kind"])
    if problem is not None:
        warnings.warn(
            f"{path}: summary kind {summary['kind']!r} was written by `visjax {problem} "
            f"--data` of visjax 0.3; that command now writes kind 'run' (as `visjax run "
            f"{problem} --data`)",
            FutureWarning,
            stacklevel=2,
        )
    # precise_float: pandas' fast float parser rounds the last digits of what json wrote
    return pd.read_json(path, typ="series", precise_float=True)


def schema_markdown() -> str:
    """The schemas as Markdown (the page `docs/outputs.md` includes)."""
    lines = ["## Keys of every summary", "", "| key | type | meaning |", "|---|---|---|"]
    lines += [f"| `{k}` | `{t}` | {d} |" for k, (t, d) in COMMON.items()]
    for kind, keys in SUMMARIES.items():
        lines += ["", f"## `{kind}`"]
        old = [k for k, v in RENAMED_KINDS.items() if v == kind]
        if old:
            lines += ["", f"Also read from the kind `{old[0]}` of visjax 0.3 (a `FutureWarning`)."]
        if kind in READ_ONLY_KINDS:
            lines += [
                "",
                f"Read only (with a `FutureWarning`): written by `visjax "
                f"{READ_ONLY_KINDS[kind]} --data` of visjax 0.3, which now writes kind `run`.",
            ]
        lines += ["", "| key | type | meaning |", "|---|---|---|"]
        lines += [f"| `{k}` | `{t}` | {d} |" for k, (t, d) in keys.items()]
    lines += ["", "## Tables", ""]
    for name, cols in TABLES.items():
        lines += [f"`{name}`: " + ", ".join(f"`{c}` ({t})" for c, t in cols.items()), ""]
    lines += ["## Arrays", ""]
    for name, arrays in ARRAYS.items():
        lines += [f"`{name}`:", ""]
        lines += [f"- `{k}`: {d}" for k, d in arrays.items()]
        lines += [""]
    return "\n".join(lines)
