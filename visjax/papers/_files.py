"""Each paper's estimator on a user's data file, as `visjax velocity|structure|euclidean
--data FILE` runs it: the estimate, what the summary reports and what failed, with no file
written and nothing printed (`visjax.report` does that)."""

import dataclasses
import functools
from pathlib import Path
from typing import Any

import numpy as np

from ..io import Outputs
from ._reproduction import Reproduction, stages


@dataclasses.dataclass(frozen=True)
class FileEstimate:
    """One estimator's run on a data file.

    **Fields:** `body` (the summary's keys, JSON-able); `arrays` (name -> array, what
    `estimate.npz` holds); `t`, `estimate` and `truth` (the times, the estimate and the
    truth at those times, `None` without one: what the figure draws); `failure` (`None`,
    or what stopped the run, with its sample)."""

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


def _failure(sol, what: str) -> str | None:
    from .._results import RESULTS

    if bool(sol.result == RESULTS.successful):
        return None
    return f"the {what} stopped: {sol.result} at sample {int(sol.failed_sample)}"


def velocity_from_file(path, filter_hz=None) -> FileEstimate:
    """The velocity estimator of Chitrakaran et al. (eqs. (39)-(40)) on a
    `visjax.io.VelocityData` file: $n^*$ from the frames, $z_1^*$ from the known length
    (`fixed_camera`, `velocity_stream`), the file's gains (eq. (63) if none), the file's own
    rate where the gains allow it (`integration_step`), and with `filter_hz` a causal 2nd-order
    low-pass of the estimate (`lowpass`)."""
    import jax.numpy as jnp

    from .._results import result_names
    from ..estimators import (
        SaveAt,
        VelocityEstimator,
        fixed_camera,
        integration_step,
        lowpass,
        lowpass_delay,
        run,
        velocity_stream,
    )
    from ..io import VelocityData
    from .chitrakaran import DOF_NAMES, K_EQ63, RHO_EQ63

    data = VelocityData.load(path)
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
    sol = run(est, stream, dt=dt, saveat=SaveAt(), throw=False)
    failure = _failure(sol, "estimator")
    ts = np.asarray(sol.ts)
    v_hat = np.asarray(sol.outputs.v_hat)
    body = {
        "z1_star": float(z1_star),
        "n_star": [float(x) for x in n_star],
        "result": "successful" if failure is None else result_names(sol.result),
        "order": list(DOF_NAMES),
        "samples": int(len(data.t)),
        "dropped_frames": int(np.sum(~np.asarray(stream.present))),
        "integration_step_s": dt,
        "K": [float(x) for x in np.asarray(K)],
        "rho": [float(x) for x in np.asarray(rho)],
    }
    arrays = {"t": ts, "v_hat": v_hat, "v_object": np.asarray(sol.outputs.v_object)}
    if filter_hz is not None:
        arrays["v_filtered"] = np.asarray(lowpass(jnp.asarray(ts), jnp.asarray(v_hat), filter_hz))
        body["filter_hz"] = filter_hz
        body["filter_delay_s"] = lowpass_delay(filter_hz)
    shown, truth = arrays.get("v_filtered", v_hat), None
    if data.velocity is not None:
        # the truth at the integration grid: the sample held at each grid time
        k = np.searchsorted(np.asarray(data.t), ts + 1e-9, side="right") - 1
        truth = np.asarray(data.velocity)[k]
        body["rms_last_half"], body["window_s"] = last_half_rms(ts, shown, truth)
    return FileEstimate(body, arrays, ts, shown, truth, failure)


def moving_point_from_file(path) -> FileEstimate:
    """The unknown input observer of Jang's thesis (eq. (3.5)) on a
    `visjax.io.MovingPointData` file: the observer and its gains from
    `moving_point_observer_for_data` (the LMI design for the file's camera motion), dropped
    frames extrapolated from the last two seen, 1 kHz on the held frames; the estimate at
    each frame time (the grid point at or just after it)."""
    from .._results import result_names
    from ..estimators import SaveAt, integration_step, moving_point_stream, run
    from ..io import MovingPointData
    from ._moving_point import moving_point_observer_for_data

    data = MovingPointData.load(path)
    t = np.asarray(data.t, float)
    observer, u, info = moving_point_observer_for_data(data)
    stream = moving_point_stream(t, data.pixels, u, data.A, dropped="extrapolate", throw=False)
    dt = integration_step(stream, observer, max_step=1e-3)  # the thesis' 1 kHz law
    sol = run(observer, stream, dt=dt, saveat=SaveAt(), throw=False)
    failure = _failure(sol, "observer")
    grid = np.asarray(sol.ts)
    j = np.clip(np.searchsorted(grid, t - 1e-9), 0, len(grid) - 1)
    position = np.asarray(sol.outputs.position)[j]
    x_hat = np.asarray(sol.outputs.x_hat)[j]
    seen = np.all(np.isfinite(np.asarray(data.pixels)), axis=1)
    body = {
        "result": "successful" if failure is None else result_names(sol.result),
        "frames": int(len(t)),
        "dropped_frames": int(np.sum(~seen)),
        "integration_step_s": dt,
        **info,
    }
    truth = None
    if data.position is not None:
        truth = np.asarray(data.position)
        body["rms_last_half"], body["window_s"] = last_half_rms(t, position, truth)
    arrays = {"t": t, "position": position, "x_hat": x_hat}
    return FileEstimate(body, arrays, t, position, truth, failure)


def static_points_from_file(path) -> FileEstimate:
    """The adaptive structure estimator of Nath et al. (eqs. (37)-(51)) on a
    `visjax.io.StaticPointsData` file: built from the file's nominal camera
    (`StaticPointsEstimator.from_nominal`: initial guesses and gains from the scene's
    scale, never from a truth), 1 kHz on the held samples (at the samples if they are
    faster), features out of view (NaN) masked in both laws; saved every 10 ms."""
    from .._results import result_names
    from ..estimators import (
        SaveAt,
        StaticPointsEstimator,
        integration_step,
        run,
        static_points_stream,
    )
    from ..io import StaticPointsData

    data = StaticPointsData.load(path)
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
    failure = _failure(sol, "estimator")
    features = np.asarray(sol.outputs.omega_s)
    A, R_c, x_c = (np.asarray(getattr(sol.outputs, f)) for f in ("A", "R_c", "x_c"))
    body = {
        "result": "successful" if failure is None else result_names(sol.result),
        "frames": int(pixels.shape[0]),
        "known_features": k,
        "unknown_features": int(pixels.shape[1] - k),
        "missing_observations": int(np.sum(~np.all(np.isfinite(pixels), axis=-1))),
        "integration_step_s": dt,
        "final_features_m": features[-1].tolist(),
        "camera": {"A": A[-1].tolist(), "R_c": R_c[-1].tolist(), "x_c": x_c[-1].tolist()},
    }
    truth = None if data.features is None else np.asarray(data.features)
    if truth is not None:
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


def _last_half_lines(body, what, names) -> list[str]:
    if "rms_last_half" not in body:
        return []
    a, b = body["window_s"]
    cells = ", ".join(f"{n} {r:.4g}" for n, r in zip(names, body["rms_last_half"]))
    return [f"{what} {a:g}-{b:g} s: {cells}"]


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
        f"recovered z1* = {body['z1_star']:.6f} m; result: {body['result']}",
        *_last_half_lines(body, "RMS error", DOF_NAMES),
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
        f"gains by design_uio_for_motion (rate {rate:.3g}/s); result: {body['result']}",
        *_last_half_lines(body, "RMS position error (m)", "XYZ"),
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
        f"features; result: {body['result']}"
    ]
    for i, e in enumerate(body.get("final_position_error_m", [])):
        lines.append(f"feature {k + i + 1}: final position error {e * 1000:8.3f} mm")
    rep = _file_reproduction(run, "euclidean", figure, lines, write)
    bar.update()
    bar.close()
    return rep
