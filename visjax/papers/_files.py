"""Each paper's estimator on a user's data file, as `visjax velocity|structure|euclidean
--data FILE` runs it: the estimate, what the summary reports and what failed, with no file
written and nothing printed (`visjax.report` does that).

A run that did not succeed reports its result code, the sample it stopped at and its time
(`failure`, one line), and no error against the truth (a frozen state's numbers are not an
estimate). A file whose frames miss a feature in more than `visjax.io.MAX_DROPPED_FRACTION`
of them runs, but its result is `DROPPED_RESULT` instead of `successful`: the estimate rests
mostly on held or extrapolated frames. Every summary reports the fraction
(`dropped_fraction`)."""

import dataclasses
import functools
from pathlib import Path
from typing import Any

import numpy as np

from ..io import Outputs
from ._reproduction import Reproduction, stages

DROPPED_RESULT = "too_many_dropped_frames"
"""The result of a data file's run that succeeded on a file whose frames miss a feature in
more than `visjax.io.MAX_DROPPED_FRACTION` of them: the name of `visjax.RESULTS`'s item."""

_FORMATS = {
    "velocity": "VelocityData",
    "moving_point": "MovingPointData",
    "static_points": "StaticPointsData",
}  # the registered problems' data classes in `visjax.io`


@dataclasses.dataclass(frozen=True)
class FileEstimate:
    """One estimator's run on a data file.

    **Fields:** `body` (the summary's keys, JSON-able); `arrays` (name -> array, what
    `estimate.npz` holds); `t`, `estimate` and `truth` (the times, the estimate and the
    truth at those times, `None` without one: what the figure draws); `failure` (`None`,
    or one line: what stopped the run, with its sample and time, or the frames missing)."""

    body: dict
    arrays: dict
    t: Any
    estimate: Any
    truth: Any
    failure: str | None


def last_half_rms(t, estimate, truth):
    """The RMS error per component over the second half of the run, `[start, end]` in
    seconds, both ends included (`WindowRMS.over`, the one windowed RMS, with NaN samples
    left out, as a dropped frame leaves them)."""
    from ..estimators import WindowRMS

    t = np.asarray(t, float)
    start = t[0] + 0.5 * (t[-1] - t[0])
    window = WindowRMS(start, np.nextafter(t[-1], np.inf))
    summary = window.over(t, np.asarray(estimate, float), np.asarray(truth, float), skip_nan=True)
    rms = [float(x) for x in np.asarray(summary.rms)]
    return rms, [float(t[t >= start][0]), float(t[-1])]


def _float64(data):
    """The data's floating arrays as float64 (a float32 file runs as a float64 one: the
    commands compute in float64)."""
    changed = {}
    for f in dataclasses.fields(data):
        v = getattr(data, f.name)
        if v is not None and np.issubdtype(np.asarray(v).dtype, np.floating):
            changed[f.name] = np.asarray(v, np.float64)
    return dataclasses.replace(data, **changed)


def _load(cls, path):
    return _float64(cls.load(path))


def _failure(sol, t) -> tuple[str, int, str | None]:
    """`(result, failed_sample, failure)`: the result code's name, the sample the run
    stopped at (-1 if it did not) and, for a failed run, one line: `diverged at sample 123
    (t = 0.123 s)` (`t` the file's sample times)."""
    from .._results import result_names

    code = result_names(sol.result)
    if code == "successful":
        return code, -1, None
    k = int(np.asarray(sol.failed_sample))
    t = np.asarray(t, float)
    when = f" (t = {t[k]:.6g} s)" if 0 <= k < t.shape[0] else ""
    return code, k, f"{code} at sample {k}{when}"


def coverage_line(fraction: float, frames: int) -> str:
    """`frames with a feature missing or held: 1500 of 2000 (75.0%)` (held: a frame the
    estimator could not use, its features degenerate or not those of the frames before),
    and past
    `visjax.io.MAX_DROPPED_FRACTION` what that makes of the result."""
    from ..io import MAX_DROPPED_FRACTION

    missing = int(round(fraction * frames))
    line = f"frames with a feature missing or held: {missing} of {frames} ({fraction:.1%})"
    if fraction > MAX_DROPPED_FRACTION:
        line += (
            f", more than visjax.io.MAX_DROPPED_FRACTION ({MAX_DROPPED_FRACTION:.0%}): the "
            "estimate rests mostly on held frames"
        )
    return line


def file_coverage(problem: str, path) -> tuple[float, int] | None:
    """`(dropped_fraction(), frames)` of the data file of a registered problem in one of
    the papers' formats (`velocity`, `moving_point`, `static_points`, by their registered
    names); `None` for another problem (its format is its own)."""
    from .. import io

    name = _FORMATS.get(problem)
    if name is None:
        return None
    data = getattr(io, name).load(path)
    return float(data.dropped_fraction()), int(np.shape(data.pixels)[0])


def _outcome(command: str, sol, t, data, body: dict) -> str | None:
    """The run's result, failed sample and `dropped_fraction` into `body`; returns the
    command's one-line failure (`velocity: the run failed: diverged at sample 12 (t =
    0.012 s)`), or `None` for a successful run on a well-covered file."""
    from ..io import MAX_DROPPED_FRACTION

    code, k, failed = _failure(sol, t)
    fraction = float(data.dropped_fraction())
    if "dropped_frames" in body:  # frames held (a feature missing, or not measurable)
        fraction = max(fraction, body["dropped_frames"] / max(len(t), 1))
    body["dropped_fraction"] = fraction
    if failed is not None:
        body["result"], body["failed_sample"] = code, k
        return f"{command}: the run failed: {failed}"
    if fraction > MAX_DROPPED_FRACTION:
        body["result"] = DROPPED_RESULT
        frames = int(np.shape(data.pixels)[0])
        return f"{command}: the result is {DROPPED_RESULT}: {coverage_line(fraction, frames)}"
    body["result"] = "successful"
    return None


def velocity_from_file(path, filter_hz=None) -> FileEstimate:
    """The velocity estimator of Chitrakaran et al. (eqs. (39)-(40)) on a
    `visjax.io.VelocityData` file: $n^*$ from the frames, $z_1^*$ from the known length
    (`fixed_camera`, `velocity_stream`), the file's gains (eq. (63) if none), the file's own
    rate where the gains allow it (`integration_step`), and with `filter_hz` a causal 2nd-order
    low-pass of the estimate (`lowpass`)."""
    import jax.numpy as jnp

    from ..estimators import (
        SaveAt,
        VelocityEstimator,
        fixed_camera,
        integration_step,
        lowpass,
        lowpass_delay,
        run,
        velocity_innovation,
        velocity_stream,
    )
    from ..io import VelocityData
    from .chitrakaran import DOF_NAMES, K_EQ63, RHO_EQ63

    data = _load(VelocityData, path)
    camera = fixed_camera(
        data.pixels,
        data.A,
        data.R_star,
        data.s1,
        known_length=data.length,
        reference_pixels=data.reference_pixels,
        dropped="hold",
    )
    stream = velocity_stream(data.t, data.pixels, camera, dropped="hold")
    n_star, z1_star = camera.n_star, camera.z1_star
    K = K_EQ63 if data.K is None else data.K
    rho = RHO_EQ63 if data.rho is None else data.rho
    est = VelocityEstimator(K=K, rho=rho)
    dt = integration_step(stream, est)  # the file's own rate where the gains allow it
    # saved about once per sample interval (a gain whose bound needs a short step would
    # otherwise save every one of its steps: hundreds of MB for seconds of data)
    every = 1 if dt is None else max(1, round(float(np.median(np.diff(data.t))) / dt))
    sol = run(est, stream, dt=dt, saveat=SaveAt(every=every, diagnostics=True), throw=False)
    ts = np.asarray(sol.ts)
    v_hat = np.asarray(sol.outputs.v_hat)
    body = {
        "z1_star": float(z1_star),
        "n_star": [float(x) for x in n_star],
        "result": "successful",
        "order": list(DOF_NAMES),
        "samples": int(len(data.t)),
        "dropped_frames": int(np.sum(~np.asarray(stream.present))),
        "integration_step_s": dt,
        "K": [float(x) for x in np.asarray(K)],
        "rho": [float(x) for x in np.asarray(rho)],
    }
    failure = _outcome("velocity", sol, data.t, data, body)
    arrays = {"t": ts, "v_hat": v_hat, "v_object": np.asarray(sol.outputs.v_object)}
    if filter_hz is not None:
        arrays["v_filtered"] = np.asarray(lowpass(jnp.asarray(ts), jnp.asarray(v_hat), filter_hz))
        body["filter_hz"] = filter_hz
        body["filter_delay_s"] = lowpass_delay(filter_hz)
    shown, truth = arrays.get("v_filtered", v_hat), None
    innovation = None
    if "failed_sample" not in body:  # the check without the truth, over the second half
        half = float(data.t[0] + 0.5 * (data.t[-1] - data.t[0]))
        innovation = velocity_innovation(stream, sol, est, t_start=half, step=dt)
    if data.velocity is not None and "failed_sample" not in body:  # no error of a frozen state
        # the truth at the integration grid: the sample held at each grid time
        k = np.searchsorted(np.asarray(data.t), ts + 1e-9, side="right") - 1
        truth = np.asarray(data.velocity)[k]
        body["rms_last_half"], body["window_s"] = last_half_rms(ts, shown, truth)
        zero, _ = last_half_rms(ts, np.zeros_like(shown), truth)  # the trivial estimate
        body["quality"] = _quality(body["rms_last_half"], zero, "zero velocity")
        if failure is None and body["quality"]["flag"] != "ok":
            body["result"] = body["quality"]["flag"]
            failure = f"velocity: the result is {body['result']}: {_quality_words(body)}"
    _innovation(body, innovation)
    return FileEstimate(body, arrays, ts, shown, truth, failure)


def _innovation(body: dict, innovation) -> None:
    """The observer's output error against the noise its data imply, into `body["quality"]`
    (`innovation`, `visjax.studies.judge_innovation`; `flag` its flag where the rest is
    `"ok"` or absent): a warning, not a result code."""
    from ..studies import judge_innovation

    if innovation is None:
        return
    quality = body.setdefault("quality", {})
    quality["innovation"] = judge_innovation(innovation)
    if quality.get("flag", "ok") == "ok":
        quality["flag"] = quality["innovation"]["flag"]


def _quality(rms, trivial, what: str) -> dict:
    """The run's error against the trivial estimate's over the same window, as
    `visjax.studies.judge` judges a problem's run: the worst component of each (the
    problem's `rms_worst`), and the ratio per component (`ratios`)."""
    from ..studies import judge

    judged = judge(max(rms), max(trivial), trivial_estimate=what, metric="rms_worst")
    judged["ratios"] = [r / t if t > 0 else None for r, t in zip(rms, trivial)]
    return judged


def _innovation_warning(body) -> list[str]:
    """A printed warning where the observer's output error is past its gate."""
    from ..studies import innovation_line

    judged = body.get("quality", {}).get("innovation")
    if judged is None or judged["flag"] == "ok":
        return []
    return [f"warning: {judged['flag']}: {innovation_line(judged)}"]


def _quality_words(body) -> str:
    from ..studies import quality_line

    return quality_line(body["quality"]) + " (over the second half)"


def moving_point_from_file(path) -> FileEstimate:
    """The unknown input observer of Jang's thesis (eq. (3.5)) on a
    `visjax.io.MovingPointData` file: the observer and its gains from
    `moving_point_observer_for_data` (the LMI design for the file's camera motion), dropped
    frames extrapolated from the last two seen, 1 kHz on the held frames; the estimate at
    each frame time (the grid point at or just after it)."""
    from ..estimators import (
        SaveAt,
        integration_step,
        moving_point_innovation,
        moving_point_stream,
        run,
    )
    from ..io import MovingPointData
    from ._moving_point import moving_point_observer_for_data

    data = _load(MovingPointData, path)
    t = np.asarray(data.t, float)
    observer, u, info = moving_point_observer_for_data(data)
    stream = moving_point_stream(t, data.pixels, u, data.A, dropped="extrapolate", throw=False)
    dt = integration_step(stream, observer, max_step=1e-3)  # the thesis' 1 kHz law
    sol = run(observer, stream, dt=dt, saveat=SaveAt(), throw=False)
    grid = np.asarray(sol.ts)
    j = np.clip(np.searchsorted(grid, t - 1e-9), 0, len(grid) - 1)
    position = np.asarray(sol.outputs.position)[j]
    x_hat = np.asarray(sol.outputs.x_hat)[j]
    seen = np.all(np.isfinite(np.asarray(data.pixels)), axis=1)
    body = {
        "result": "successful",
        "frames": int(len(t)),
        "dropped_frames": int(np.sum(~seen)),
        "integration_step_s": dt,
        **info,
    }
    failure = _outcome("moving_point", sol, t, data, body)
    truth = None
    if data.position is not None:
        truth = np.asarray(data.position)
    if truth is not None and "failed_sample" not in body:  # no error of a frozen state
        body["rms_last_half"], body["window_s"] = last_half_rms(t, position, truth)
        # the trivial estimate: the point on each frame's ray at the initial depth guess
        pixels = np.asarray(data.pixels, float)
        rays = np.linalg.solve(np.asarray(data.A, float), np.c_[pixels, np.ones(len(t))].T).T
        guess = rays / rays[:, 2:] * info["depth_guess_m"]
        trivial, _ = last_half_rms(t, guess, truth)
        body["quality"] = _quality(body["rms_last_half"], trivial, "the initial depth guess")
        if failure is None and body["quality"]["flag"] != "ok":
            body["result"] = body["quality"]["flag"]
            failure = f"moving_point: the result is {body['result']}: {_quality_words(body)}"
    if "failed_sample" not in body:  # the check without the truth, over the second half
        half = float(t[0] + 0.5 * (t[-1] - t[0]))
        _innovation(
            body,
            moving_point_innovation(
                t, data.pixels, data.A, sol.ts, sol.outputs.x_hat, t_start=half
            ),
        )
    arrays = {"t": t, "position": position, "x_hat": x_hat}
    return FileEstimate(body, arrays, t, position, truth, failure)


def static_points_from_file(path) -> FileEstimate:
    """The adaptive structure estimator of Nath et al. (eqs. (37)-(51)) on a
    `visjax.io.StaticPointsData` file: built from the file's nominal camera
    (`StaticPointsEstimator.from_nominal`: initial guesses and gains from the scene's
    scale, never from a truth), 1 kHz on the held samples (at the samples if they are
    faster), features out of view (NaN) masked in both laws; saved every 10 ms."""
    from ..estimators import (
        SaveAt,
        StaticPointsEstimator,
        integration_step,
        run,
        static_points_stream,
    )
    from ..io import StaticPointsData

    data = _load(StaticPointsData, path)
    k = data.n_known
    pixels = np.asarray(data.pixels, float)
    stream = static_points_stream(
        data.t, data.platform_R, data.platform_x, pixels[:, k:], pixels[:, :k],
        data.known_features, throw=False,
    )  # fmt: skip
    longest = float(np.max(np.diff(np.asarray(data.t, float))))
    # the gains of `from_nominal` are derived for the step, so no bound applies here
    dt = integration_step(stream, max_step=1e-3)
    est = StaticPointsEstimator.from_nominal(
        stream, data.A_nominal, data.R_c_nominal, data.x_c_nominal, dt=dt
    )
    every = max(1, int(round(0.01 / (longest if dt is None else dt))))
    sol = run(est, stream, dt=dt, saveat=SaveAt(every=every), throw=False)
    features = np.asarray(sol.outputs.omega_s)
    A, R_c, x_c = (np.asarray(getattr(sol.outputs, f)) for f in ("A", "R_c", "x_c"))
    body = {
        "result": "successful",
        "frames": int(pixels.shape[0]),
        "known_features": k,
        "unknown_features": int(pixels.shape[1] - k),
        "missing_observations": int(np.sum(~np.all(np.isfinite(pixels), axis=-1))),
        "integration_step_s": dt,
        "final_features_m": features[-1].tolist(),
        "camera": {"A": A[-1].tolist(), "R_c": R_c[-1].tolist(), "x_c": x_c[-1].tolist()},
    }
    failure = _outcome("static_points", sol, data.t, data, body)
    truth = None if data.features is None else np.asarray(data.features)
    if truth is not None and "failed_sample" not in body:  # no error of a frozen state
        err = np.linalg.norm(features[-1] - truth, axis=-1)
        body["final_position_error_m"] = [float(e) for e in err]
    ts = np.asarray(sol.ts)
    arrays = {"t": ts, "features": features, "A": A, "R_c": R_c, "x_c": x_c}
    return FileEstimate(body, arrays, ts, features, truth, failure)


# The data-file runs as `visjax velocity|structure|euclidean --data FILE` report them
# (`visjax.report` writes and prints; the run's failure is raised after the files).


def _file_reproduction(run: FileEstimate, name: str, figure, lines, write) -> Reproduction:
    if write is not None:
        draw = functools.partial(figure, run.t, run.truth, run.estimate)
        write(Outputs(arrays={"estimate.npz": run.arrays}, figures={name: draw}))
    return Reproduction(run.body, lines, failure=run.failure)


def _number(x, spec: str = ".4g") -> str:
    """A number as text; `-` for one that is missing (`None`) or not finite."""
    try:
        x = float(x)
    except (TypeError, ValueError):
        return "-"
    return format(x, spec) if np.isfinite(x) else "-"


def _last_half_lines(body, what, names) -> list[str]:
    if body.get("rms_last_half") is None:
        return []
    a, b = (_number(x, "g") for x in body["window_s"])
    cells = ", ".join(f"{n} {_number(r)}" for n, r in zip(names, body["rms_last_half"]))
    return [f"{what} {a}-{b} s: {cells}"]


def _coverage_line(body) -> str:
    return coverage_line(body["dropped_fraction"], body.get("frames", body.get("samples")))


def velocity_file_reproduction(path, filter_hz=None, *, quiet=True, write=None) -> Reproduction:
    """`velocity_from_file` as `visjax velocity --data` reports it: `estimate.npz` (the
    estimate in the camera and object frames), the figure `velocity` and the lines."""
    from ..plots import plot_velocity
    from .chitrakaran import DOF_NAMES

    bar = stages(2, "velocity", quiet)
    bar.set_postfix_str("reconstruct every frame, estimate")
    run = velocity_from_file(path, filter_hz)
    bar.update()
    title = f"velocity estimator (Chitrakaran et al.) on {Path(path).name}"
    body = run.body
    lines = [
        f"Velocity estimator (Chitrakaran et al., eqs. 39-40) on {path}: {body['samples']} frames",
        f"recovered z1* = {_number(body['z1_star'], '.6f')} m; result: {body['result']}",
        _coverage_line(body),
        *_last_half_lines(body, "RMS error", DOF_NAMES),
        *([f"quality: {_quality_words(body)}"] if "quality" in body else []),
        *_innovation_warning(body),
    ]
    rep = _file_reproduction(
        run, "velocity", functools.partial(plot_velocity, title=title), lines, write
    )
    bar.update()
    bar.close()
    return rep


def moving_point_file_reproduction(path, *, quiet=True, write=None) -> Reproduction:
    """`moving_point_from_file` as `visjax moving_point --data` reports it: `estimate.npz`
    (`t`, `position`, `x_hat`), the figure `structure` and the lines."""
    from ..plots import plot_structure

    bar = stages(2, "structure", quiet)
    bar.set_postfix_str("design the gains (LMI), estimate")
    run = moving_point_from_file(path)
    bar.update()
    title = f"unknown input observer (Jang's thesis) on {Path(path).name}"
    body = run.body
    rate = body["design"]["convergence_rate_per_s"]
    lines = [
        f"Unknown input observer (Jang's thesis, eq. 3.5) on {path}: {body['frames']} frames, "
        f"gains by design_uio_for_motion (rate {_number(rate, '.3g')}/s); result: "
        f"{body['result']}",
        _coverage_line(body),
        *_last_half_lines(body, "RMS position error (m)", "XYZ"),
        *([f"quality: {_quality_words(body)}"] if "quality" in body else []),
        *_innovation_warning(body),
    ]
    rep = _file_reproduction(
        run, "structure", functools.partial(plot_structure, title=title), lines, write
    )
    bar.update()
    bar.close()
    return rep


def static_points_file_reproduction(path, *, quiet=True, write=None) -> Reproduction:
    """`static_points_from_file` as `visjax static_points --data` reports it: `estimate.npz`
    (`t`, `features`, the recovered camera `A`, `R_c`, `x_c` over time), the figure
    `euclidean` and the lines."""
    from ..plots import plot_feature_estimates

    bar = stages(2, "euclidean", quiet)
    bar.set_postfix_str("estimate (compiles once)")
    run = static_points_from_file(path)
    bar.update()
    title = f"adaptive structure estimator (Nath et al.) on {Path(path).name}"

    def figure(t, truth, features, **kwargs):  # its order: the estimate, then the truth
        return plot_feature_estimates(t, features, truth, title=title, **kwargs)

    body = run.body
    k = body["known_features"]
    lines = [
        f"Adaptive LS structure estimator (Nath et al., eqs. 37-51) on {path}: "
        f"{body['frames']} frames, {k} known and {body['unknown_features']} unknown "
        f"features; result: {body['result']}",
        _coverage_line(body),
    ]
    for i, e in enumerate(body.get("final_position_error_m") or []):
        mm = None if e is None else 1000 * e
        lines.append(f"feature {k + i + 1}: final position error {_number(mm, '8.3f')} mm")
    rep = _file_reproduction(run, "euclidean", figure, lines, write)
    bar.update()
    bar.close()
    return rep
