r"""Recordings to look at: a run logged to a Rerun file (`.rrd`), to scrub through in the
Rerun viewer (`rerun FILE.rrd`), with `rerun-sdk` (the optional extra `visjax[viz]`; the
base install does not need it). The commands' `--rerun FILE.rrd` (`run`, `compare`,
`reproduce`) write one.

What is logged, on the timeline `t` (seconds):

- `PREFIX/METHOD/estimate/COLUMN` and `PREFIX/METHOD/truth/COLUMN`: each saved output of a
  method's run, component by component (`studies.solution_table`: the problem's column
  names, the truth beside each estimate that has one), as scalars: the velocity, the
  depths, the positions, the homography's entries;
- `PREFIX/METHOD/points` and `PREFIX/truth_points`: the 3-D points of the first output
  whose components are x, y, z and whose truth the problem knows (a moving point's
  position, the static features), estimated and true, at each saved time;
- `PREFIX/METHOD/error/H`: for a homography `H` (N, 3, 3) with its truth, Hamel et al.'s
  error $\|\hat H H^{-1} - I\|_F$ over time;
- `PREFIX/pixels`: the pixels the methods see (a problem's `clean` or `pixels` array of one
  row per time of its `ts`), as 2-D points, one entity per time;
- `PREFIX/camera_path` and `PREFIX/world/...`: for a camera on a moving platform (a problem
  with the platform's poses `R_b`, `x_b` and the camera's nominal mounting `x_c_nominal`,
  Nath et al.'s), the camera's path in the world as a line strip and its position over
  time, the known features (`omega_c`) and the unknown ones' truth;
- `PREFIX/ARRAY/KEY`: for `reproduce`, each job's arrays with a time axis `t`, and
  `PREFIX/frames` its image frames, where it has any.
"""

import contextlib
from pathlib import Path

import numpy as np

from . import studies
from .frontend import read_video

MAX_TIMES = 2000
"""The most times logged per series (longer runs are decimated evenly): a file to scrub
through, not the data (the tables hold every sample)."""


def open_recording(path, name: str = "visjax"):
    """A Rerun recording stream saving to `path` (`.rrd`). **Raises:** `ImportError` saying
    how to install `rerun-sdk`; `ValueError` for a path that does not end in `.rrd`."""
    if Path(path).suffix != ".rrd":
        raise ValueError(f"{path}: a Rerun recording's file ends in .rrd.")
    try:
        import rerun as rr
    except ImportError:
        raise ImportError(
            "writing Rerun recordings needs the optional extra: pip install 'visjax[viz]'"
        ) from None
    rec = rr.RecordingStream(name)
    rec.save(str(path))
    return rec


def _every(n: int) -> int:
    return max(1, -(-n // MAX_TIMES))


def _scalars(rec, entity: str, t, values) -> None:
    import rerun as rr

    step = _every(len(t))
    for tk, v in zip(np.asarray(t)[::step], np.asarray(values, float)[::step]):
        rec.set_time("t", duration=float(tk))
        rec.log(entity, rr.Scalars([float(v)]))


def _points(rec, entity: str, t, points, dims: int) -> None:
    import rerun as rr

    kind = rr.Points3D if dims == 3 else rr.Points2D
    step = _every(len(t))
    for tk, p in zip(np.asarray(t)[::step], np.asarray(points, float)[::step]):
        rec.set_time("t", duration=float(tk))
        p = p.reshape(-1, dims)
        rec.log(entity, kind(p[np.all(np.isfinite(p), axis=1)]))


def log_solution(rec, prefix: str, problem, method: str, solution) -> list[str]:
    """One method's run (`studies.solution`): its outputs and the truth over time, and its
    3-D points (module docstring). **Returns:** the entities logged."""
    table = studies.solution_table(solution, problem, method)
    t, logged = table.pop("t"), []
    for column, values in table.items():
        kind, name = ("truth", column[:-5]) if column.endswith("_true") else ("estimate", column)
        entity = f"{prefix}/{method}/{kind}/{name}"
        _scalars(rec, entity, t, values)
        logged.append(entity)
    outputs = studies.solution_outputs(solution)
    truth = problem.truth_outputs(method, solution)
    H, H_true = outputs.get("H"), truth.get("H")
    if H is not None and H_true is not None and np.shape(H) == np.shape(H_true) == (len(t), 3, 3):
        eye = np.eye(3)
        error = np.linalg.norm(np.asarray(H) @ np.linalg.inv(np.asarray(H_true)) - eye, axis=(1, 2))
        _scalars(rec, f"{prefix}/{method}/error/H", t, error)
        logged.append(f"{prefix}/{method}/error/H")
    for name, v in outputs.items():  # the first output of 3-D points the truth knows
        if v is None or np.ndim(v) < 2 or np.shape(v)[-1] != 3 or np.shape(v)[0] != len(t):
            continue
        if truth.get(name) is None:
            continue  # a state of three components (x1, x2, x3), not a point
        true = np.broadcast_to(np.asarray(truth[name], float), np.shape(v))
        _points(rec, f"{prefix}/{method}/points", t, v, 3)
        _points(rec, f"{prefix}/truth_points", t, true, 3)
        logged += [f"{prefix}/{method}/points", f"{prefix}/truth_points"]
        break
    return logged


def log_problem(rec, prefix: str, problem, methods, seed: int = 0) -> list[str]:
    """Each method's run of seed `seed` (`log_solution`), and the pixels they see where the
    problem holds them (module docstring). **Returns:** the entities logged."""
    logged = []
    ts = getattr(problem, "ts", None)
    for attr in ("clean", "pixels"):
        pixels = getattr(problem, attr, None)
        if ts is not None and pixels is not None and np.shape(pixels)[0] == np.shape(ts)[0]:
            _points(rec, f"{prefix}/pixels", ts, pixels, 2)
            logged.append(f"{prefix}/pixels")
            break
    logged += _log_platform(rec, prefix, problem)
    for method in methods:
        sol = studies.solution(problem, None, seed, method=method)
        logged += log_solution(rec, prefix, problem, method, sol)
    return logged


def _log_platform(rec, prefix: str, problem) -> list[str]:
    """The camera's path and the world's points of a camera on a moving platform."""
    import rerun as rr

    parts = [getattr(problem, k, None) for k in ("ts", "R_b", "x_b", "x_c_nominal")]
    if any(p is None for p in parts):
        return []
    ts, R_b, x_b, x_c = (np.asarray(p, float) for p in parts)
    path = x_b + np.einsum("nij,j->ni", R_b, x_c)  # the camera's centre in the world
    rec.log(f"{prefix}/camera_path", rr.LineStrips3D([path]), static=True)
    _points(rec, f"{prefix}/camera", ts, path, 3)
    logged = [f"{prefix}/camera_path", f"{prefix}/camera"]
    for name, attr in (("known", "omega_c"), ("unknown_true", "truth")):
        points = getattr(problem, attr, None)
        if points is not None:
            rec.log(f"{prefix}/world/{name}", rr.Points3D(np.asarray(points, float)), static=True)
            logged.append(f"{prefix}/world/{name}")
    return logged


def log_arrays(rec, prefix: str, arrays) -> list[str]:
    """A reproduction's arrays (`io.Outputs.arrays`: name -> {key: array}): each array with a
    leading time axis of its `t`, component by component, and its `frames` as images.
    **Returns:** the entities logged."""
    import rerun as rr

    logged = []
    for name, group in (arrays or {}).items():
        if not isinstance(group, dict) or "t" not in group:
            continue
        t = np.asarray(group["t"], float)
        for key, value in group.items():
            value = np.asarray(value)
            if key == "t" or value.ndim < 1 or value.shape[0] != len(t):
                continue
            if key == "frames" and value.ndim == 3:
                for tk, frame in zip(t[:: _every(len(t))], value[:: _every(len(t))]):
                    rec.set_time("t", duration=float(tk))
                    rec.log(f"{prefix}/{name}/frames", rr.Image(frame))
                logged.append(f"{prefix}/{name}/frames")
                continue
            if not np.issubdtype(value.dtype, np.number):
                continue
            flat = value.reshape(len(t), -1)
            for i in range(flat.shape[1]):
                entity = f"{prefix}/{name}/{key}" + (f"_{i}" if flat.shape[1] > 1 else "")
                _scalars(rec, entity, t, flat[:, i])
                logged.append(entity)
    return logged


@contextlib.contextmanager
def request_log(request):
    """For a command (`visjax.verbs`): `log(tag, problem)`, which logs the problem's runs
    (`log_request`) to `request.rerun`, or does nothing without one; the recording is
    closed (its file finished) on leaving."""
    if request.rerun is None:
        yield lambda tag, problem: None
        return
    rec = open_recording(request.rerun)
    try:
        yield lambda tag, problem: log_request(rec, request, tag, problem)
    finally:
        rec.disconnect()


def log_request(rec, request, tag, problem) -> list[str]:
    """What `--rerun` logs for a command's problem (`visjax.verbs`): `run`, its method's
    run; `compare`, each method's run; of the first seed, under the problem's name (and
    the variant's). **Returns:** the entities logged."""
    if request.command == "run":
        methods = [problem.check_method(request.method)]
    else:
        methods = [problem.check_method(m) for m in (request.methods or problem.methods)]
    prefix = "/".join(filter(None, (request.problem, None if tag is None else str(tag))))
    return log_problem(rec, prefix, problem, methods, request.seed)


def log_reproduction(rec, folder, name: str, max_frames: int = 100) -> list[str]:
    """What `reproduce --rerun` logs of one reproduction, from the files it wrote into
    `folder`: each `.npz` with a time axis (`log_arrays`) and up to `max_frames` frames of
    each video. **Returns:** the entities logged."""
    import rerun as rr

    logged = []
    for path in sorted(Path(folder).rglob("*.npz")):
        with np.load(path) as arrays:
            group = {k: arrays[k] for k in arrays.files}
        sub = path.parent.relative_to(folder).as_posix()
        logged += log_arrays(rec, name if sub == "." else f"{name}/{sub}", {path.stem: group})
    for path in sorted(Path(folder).rglob("*.mp4")):
        frames, fps = read_video(path, allow_damaged=True)
        step = max(1, -(-len(frames) // max_frames))
        entity = f"{name}/{path.stem}/frames"
        for k in range(0, len(frames), step):
            rec.set_time("t", duration=k / fps)
            rec.log(entity, rr.Image(frames[k]))
        logged.append(entity)
    return logged
