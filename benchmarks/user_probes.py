"""Probe the command line with users' plausible mistakes and the safety of their folders.

Each probe builds its inputs in a temporary folder (from the package's own example scenes,
`visjax.sim`'s catalogue records, wrapped as the formats of `visjax.io`), runs `visjax` in a
subprocess, and classifies the outcome:

- `clear_error`: exit status not 0, exactly one `visjax: error:` (or `visjax: interrupted`)
  line, among the last lines of stderr, and no traceback;
- `result_code`: exit status 0, and the command reported a result that is not
  `successful` (a result code printed or in a `summary.json`: `result`, `records`,
  `failed_runs`, a `dropped_fraction` above `visjax.io.MAX_DROPPED_FRACTION` or its printed
  warning): the mistake caught and named;
- `silent_garbage`: exit status 0 and a successful report for a probe that is a mistake;
- `traceback`: "Traceback" in stderr, or a crash (an exit status not 0, 1, 2, 130, 143);
- `handled` / `failed_check`: a probe that is not a mistake but a safety check (a user's
  file in `--out` surviving, two runs into one `--out`, a signal mid-run): its assertions
  held / did not. Every probe also checks that no file the user had (every file but the
  entries a command recorded in a `.visjax-outputs*.json`) was deleted or changed, that
  no `.visjax-stage-*` folder is left, and that a `summary.json` written follows its
  schema; a probe that breaks one of these is `failed_check` whatever it printed;
- `unclear_error`: exit status 1 or 2 without the one error line (no traceback either);
- `timeout`: the command still ran after the probe's time limit (it then gets SIGINT, as
  from a user's Ctrl-C, and SIGKILL 60 s later; what it printed is in `stderr_tail`).

In that order of precedence: a crash is a `traceback` whatever else happened.

A few probes are marked `benign`: an absurd value whose correct handling is to run
normally (a `--chunk` larger than the runs, which is clamped); run normally they are
`handled`, not `silent_garbage`.

Prints one JSON document `{"probes": [{"name", "kind", "exit", "outcome", "stderr_tail",
...}], "counts": {outcome: n}}` on stdout and a Markdown table of the counts (and the probes
that came out `silent_garbage`, `traceback`, `failed_check`, `unclear_error` or `timeout`)
on stderr. The goal: none of those.

    python benchmarks/user_probes.py            # every probe (about 120), 2 at a time
    python benchmarks/user_probes.py --quick    # the first probe of each kind
    python benchmarks/user_probes.py --only velocity_A_transposed --keep /tmp/probes

`tests/test_user_probes.py` runs `--quick` (a slow test).
"""

import argparse
import concurrent.futures
import contextlib
import dataclasses
import functools
import hashlib
import importlib.util
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import types
import zipfile
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np
import numpy.lib.format as npy_format
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT_S = 300.0
MEMORY_LIMIT = 10 * 2**30  # address space of each command (a runaway allocation fails)
MAX_DROPPED_FRACTION = 0.5  # visjax.io.MAX_DROPPED_FRACTION (not imported: no JAX here)
OUTCOMES = (
    "clear_error",
    "result_code",
    "handled",
    "silent_garbage",
    "traceback",
    "failed_check",
    "unclear_error",
    "timeout",
)
BAD = ("silent_garbage", "traceback", "failed_check", "unclear_error", "timeout")
OK_EXITS = (0, 1, 2, 130, 143)
COMMAND = {"v": "velocity", "s": "moving_point", "e": "static_points", "e8": "static_points"}


# --- the base data: the example scenes, generated once ----------------------------------


_MAKE_BASE = """
import sys
from pathlib import Path

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)
from visjax import sim
from visjax.frontend import write_video

folder = Path(sys.argv[1])
records = {
    # 500 frames, 6 features; noise-free: at 0.1 px the estimator's error is larger than
    # zero velocity's (a result code, `worse_than_trivial`), and the safety probes need a
    # run that succeeds
    "v": sim.sinusoidal_plate_record(0.5, 0, 0.0, 0.0),
    "s": sim.sideways_camera_record(2.0, 0, 0.1),  # 100 frames, 400 camera velocities
    "e": sim.tilted_platform_record(2.0, 0, 0.2, 0.0),  # 400 frames, 11 features
    "e8": sim.tilted_platform_record(8.0, 0, 0.2, 0.0),  # 1600 x 11 = 17,600 observations
    "v2": sim.sinusoidal_plate_record(2.0, 0, 0.1, 0.0),  # 2 s: a run long enough to interrupt
}
for name, record in records.items():
    arrays = {k: np.asarray(v) for k, v in record.items() if v is not None}
    np.savez(folder / f"{name}.npz", **arrays)
rng = np.random.default_rng(0)
texture = np.kron(rng.integers(0, 256, (60, 80)).astype(np.uint8), np.ones((4, 4), np.uint8))
frames = np.stack([np.roll(texture, k, axis=1)[40:200, 40:280] for k in range(15)])
write_video(folder / "video.mp4", frames, 15.0)
write_video(folder / "video.npz", frames, 15.0)
"""


def make_base(folder: Path) -> dict:
    """The example scenes (`visjax.sim`'s catalogue records, with noise and no dropout:
    every missing pixel is a probe's) as dicts of NumPy arrays, and a short textured video
    (`.mp4` and lossless `.npz`) in `folder`. Made in a subprocess: this process imports
    no JAX (it forks the probes' commands)."""
    subprocess.run([sys.executable, "-c", _MAKE_BASE, str(folder)], check=True, env=_environment())
    base = {}
    for name in ("v", "s", "e", "e8", "v2"):
        with np.load(folder / f"{name}.npz") as f:
            base[name] = {k: f[k] for k in f.files}
    with np.load(folder / "video.npz") as f:
        base["frames"] = f["frames"]
    base["videos"] = folder
    return base


BASE: dict = {}


def data(fmt: str) -> dict:
    """A fresh copy of a base scene's arrays."""
    return {k: np.array(v) for k, v in BASE[fmt].items()}


def save(path: Path, arrays: dict) -> Path:
    np.savez(path, **arrays)  # unvalidated: the mistake goes into the file as a user's would
    return path


# --- running a command -------------------------------------------------------------------


def _environment(extra: dict | None = None) -> dict:
    env = dict(os.environ)
    env.pop("VISJAX_MAX_DATA_BYTES", None)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env.setdefault("JAX_PLATFORMS", "cpu")
    env.update(extra or {})
    return env


_LAUNCH = (
    "import resource, runpy, sys; "
    f"resource.setrlimit(resource.RLIMIT_AS, ({MEMORY_LIMIT}, {MEMORY_LIMIT})); "
    "sys.argv[0] = 'visjax'; runpy.run_module('visjax.cli', run_name='__main__', alter_sys=True)"
)  # `python -m visjax.cli`, its address space limited (a runaway allocation fails)


def start(argv, cwd: Path, env=None) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-c", _LAUNCH, *argv],
        cwd=cwd,
        env=_environment(env),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        encoding="utf-8",
        errors="replace",
        start_new_session=True,
    )


def finish(p: subprocess.Popen, timeout: float):
    """`(exit status, or None past `timeout`, stdout, stderr)`. Past `timeout` the command
    gets SIGINT (a user's Ctrl-C: it should clean up and stop), then SIGKILL 60 s later."""
    try:
        out, err = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        p.send_signal(signal.SIGINT)
        try:
            out, err = p.communicate(timeout=60)
            note = f"\n[probe: timed out after {timeout:g} s; SIGINT: exit {p.returncode}]"
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGKILL)
            out, err = p.communicate()
            note = f"\n[probe: timed out after {timeout:g} s; no exit 60 s after SIGINT: SIGKILL]"
        return None, out, err + note
    return p.returncode, out, err


def visjax(argv, cwd: Path, env=None, timeout=TIMEOUT_S):
    return finish(start(argv, cwd, env), timeout)


# --- what a run left -----------------------------------------------------------------------


def _lines(text: str) -> list[str]:
    return [ln.strip() for ln in re.split(r"[\r\n]", text or "") if ln.strip()]


def _user_code_error(err: str) -> bool:
    """One `visjax: error:` line that says the error is in the user's own code, first,
    then that code's traceback (issue 44: their traceback helps them)."""
    lines = _lines(err)
    return (
        bool(lines)
        and lines[0].startswith("visjax: error:")
        and lines[0].endswith("(your code's traceback below)")
    )


def crashed(rc, err: str) -> bool:
    if _user_code_error(err):  # the traceback is the user's code's, announced as such
        return rc is not None and rc not in OK_EXITS
    return "Traceback" in (err or "") or (rc is not None and rc not in OK_EXITS)


def clear_error(err: str) -> bool:
    """Exactly one `visjax: error:` / `visjax: interrupted` line, among the last three
    non-empty lines (a progress bar's last redraw may follow it), no traceback."""
    lines = _lines(err)
    if _user_code_error(err):
        return sum(ln.startswith("visjax: error:") for ln in lines) == 1
    said = [ln for ln in lines if ln.startswith(("visjax: error:", "visjax: interrupted"))]
    return len(said) == 1 and said[0] in lines[-3:] and "Traceback" not in err


def _owned(folder: Path) -> set[Path]:
    """Paths that commands recorded as theirs (manifest entries, the manifests, locks)."""
    owned = set()
    for manifest in folder.rglob(".visjax-outputs*.json"):
        owned.add(manifest)
        with contextlib.suppress(OSError, ValueError, AttributeError, TypeError):
            for entry in json.loads(manifest.read_text()).get("entries", []):
                owned.add(manifest.parent / entry)
    owned.update(folder.rglob("*.lock"))
    return owned


def snapshot(folder: Path) -> dict[str, str]:
    """`{relative path: sha256}` of the user's files under `folder` (not a command's)."""
    owned = _owned(folder)
    files = {}
    for path in folder.rglob("*"):
        if path.is_symlink() or not path.is_file():
            continue
        if any(path == o or o in path.parents for o in owned):
            continue
        if any(part.startswith(".visjax-stage-") for part in path.parts):
            continue
        files[str(path.relative_to(folder))] = hashlib.sha256(path.read_bytes()).hexdigest()
    return files


def damage(folder: Path, before: dict[str, str]) -> list[str]:
    """What happened to the user's files and the folder: deleted or changed files, staging
    folders left behind."""
    problems = []
    for rel, digest in before.items():
        path = folder / rel
        if not path.is_file():
            problems.append(f"the user's file {rel} was deleted")
        elif hashlib.sha256(path.read_bytes()).hexdigest() != digest:
            problems.append(f"the user's file {rel} was changed")
    stages = [str(p.relative_to(folder)) for p in folder.rglob(".visjax-stage-*")]
    if stages:
        problems.append(f"staging folder(s) left: {stages}")
    return problems


def _summaries(folder: Path) -> list[Path]:
    return [
        p
        for p in folder.rglob("summary.json")
        if not any(part.startswith(".visjax-stage-") for part in p.parts)
    ]


@functools.cache
def _schemas():
    """`visjax/io/_outputs.py` and the module it imports, `_staging.py` (plain Python),
    loaded alone as a package of their own: importing `visjax` would import JAX into this
    process."""
    package = types.ModuleType("_visjax_io")
    package.__path__ = [str(ROOT / "visjax" / "io")]
    sys.modules["_visjax_io"] = package
    for name in ("_staging", "_outputs"):
        spec = importlib.util.spec_from_file_location(
            f"_visjax_io.{name}", ROOT / "visjax" / "io" / f"{name}.py"
        )
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module
        spec.loader.exec_module(module)
    return sys.modules["_visjax_io._outputs"]


def schema_problems(folder: Path, before: dict[str, str]) -> list[str]:
    """Every `summary.json` under `folder` that a command wrote (not one of the user's
    files, `before`) follows its schema (`visjax.io`)."""
    problems = []
    for path in _summaries(folder):
        if str(path.relative_to(folder)) in before:
            continue
        try:
            _schemas().validate_summary(json.loads(path.read_text()))
        except (ValueError, OSError) as e:
            problems.append(f"{path.relative_to(folder)} does not follow its schema: {e}")
    return problems


_CODE = re.compile(r"\bresult(?: is|:|=)\s*([A-Za-z_]+)")
_FAILED = re.compile(r"\b([1-9]\d*) of \d+ (?:sweep |held-out )?runs failed")


def _walk(tree, found: list[str], where="") -> None:
    if isinstance(tree, dict):
        for k, v in tree.items():
            here = f"{where}.{k}" if where else k
            if k == "result" and isinstance(v, str) and v != "successful":
                found.append(f"{here} = {v}")
            elif k == "failed_runs" and isinstance(v, int) and v > 0:
                found.append(f"{here} = {v}")
            elif k == "failed" and isinstance(v, int) and v > 0:
                found.append(f"{here} = {v}")
            elif k == "dropped_fraction" and isinstance(v, float) and v > MAX_DROPPED_FRACTION:
                found.append(f"{here} = {v:.3f}")
            elif k == "worse_than_trivial" and isinstance(v, dict) and any(v.values()):
                found.append(f"{here} = {v}")
            elif k == "flag" and v in ("worse_than_trivial", "innovation_too_large"):
                found.append(f"{here} = {v}")
            else:
                _walk(v, found, here)
    elif isinstance(tree, list):
        for i, v in enumerate(tree):
            _walk(v, found, f"{where}[{i}]")


def reported(stdout: str, folder: Path) -> str | None:
    """Where the run said its result is not successful: a printed result code, a printed
    dropped-frames warning or failed-run count, or a summary's result fields."""
    for m in _CODE.finditer(stdout or ""):
        if m[1] != "successful":
            return f"printed: {m[0]}"
    for word in ("too_many_dropped_frames", "MAX_DROPPED_FRACTION"):
        if word in (stdout or ""):
            line = next(ln for ln in _lines(stdout) if word in ln)
            return f"printed: {line[:160]}"
    m = _FAILED.search(stdout or "")
    if m:
        return f"printed: {m[0]}"
    for path in _summaries(folder):
        found: list[str] = []
        with contextlib.suppress(OSError, ValueError):
            _walk(json.loads(path.read_text()), found)
        if found:
            return f"{path.relative_to(folder)}: {found[0]}" + (
                f" (and {len(found) - 1} more)" if len(found) > 1 else ""
            )
    return None


# --- probes ----------------------------------------------------------------------------------


@dataclasses.dataclass
class Outcome:
    exit: int | list | None
    stdout: str
    stderr: str
    problems: list[str]
    crashed: bool = False


@dataclasses.dataclass
class Probe:
    name: str
    kind: str
    run: Callable[[Path], Outcome]
    mistake: bool = True
    benign: bool = False
    what: str = ""


def command_probe(
    build: Callable[[Path], list[str]],
    *,
    env: dict | None = None,
    timeout: float = TIMEOUT_S,
    check: Callable[[Path, int | None, str, str], list[str]] | None = None,
) -> Callable[[Path], Outcome]:
    """A probe that builds its files (`build(folder)` returns the command's arguments, run
    in `folder`), runs one command, then checks the folder (`damage`, the summaries'
    schema, `check`)."""

    def run(folder: Path) -> Outcome:
        argv = build(folder)
        before = snapshot(folder)
        rc, out, err = visjax(argv, folder, env, timeout)
        problems = damage(folder, before) + schema_problems(folder, before)
        if check is not None and rc is not None:
            problems += check(folder, rc, out, err)
        return Outcome(rc, out, err, problems, crashed(rc, err))

    return run


def classify(probe: Probe, o: Outcome, folder: Path) -> tuple[str, str | None]:
    """The outcome's class, and the evidence of a reported result code."""
    if o.crashed:
        return "traceback", None
    if o.exit is None:
        return "timeout", None
    if o.problems:
        return "failed_check", None
    if not probe.mistake:
        return "handled", None
    if o.exit != 0:
        return ("clear_error" if clear_error(o.stderr) else "unclear_error"), None
    evidence = reported(o.stdout, folder)
    if evidence:
        return "result_code", evidence
    return ("handled" if probe.benign else "silent_garbage"), None


PROBES: list[Probe] = []


def probe(name, kind, *, mistake=True, benign=False, what=""):
    def register(run):
        PROBES.append(Probe(name, kind, run, mistake, benign, what))
        return run

    return register


def data_cmd(fmt, file="data.npz", *extra, command=None):
    cmd = command or [COMMAND[fmt]]
    return [*cmd, "--data", file, "--out", "out", "--quiet", *extra]


def data_probe(name, kind, fmt, mutate, *, command=None, extra=(), what="", env=None):
    """A data file of format `fmt` with `mutate(arrays)` applied, run by its command."""

    def build(folder):
        arrays = data(fmt)
        mutate(arrays)
        save(folder / "data.npz", arrays)
        return data_cmd(fmt, "data.npz", *extra, command=command)

    PROBES.append(Probe(name, kind, command_probe(build, env=env), what=what))


def file_probe(name, kind, fmt, write, *, file="data.npz", env=None, what=""):
    """A data file written by `write(path, arrays)` (a damaged or foreign file)."""

    def build(folder):
        write(folder / file, data(fmt))
        return data_cmd(fmt, file)

    PROBES.append(Probe(name, kind, command_probe(build, env=env), what=what))


def argv_probe(name, kind, argv, *, timeout=TIMEOUT_S, benign=False, what=""):
    """A command line, run as it is (plus `--out out`)."""

    def build(folder):
        return [*argv, "--out", "out"]

    PROBES.append(Probe(name, kind, command_probe(build, timeout=timeout), True, benign, what))


def _set(key, value):
    def mutate(a):
        a[key] = value(a) if callable(value) else value

    return mutate


def _both(*mutations):
    def mutate(a):
        for m in mutations:
            m(a)

    return mutate


def _rename(old, new):
    def mutate(a):
        a[new] = a.pop(old)

    return mutate


def _drop_frames(feature, fraction=0.75, seed=0):
    """NaN pixels in `fraction` of the frames (never frame 0): feature `feature`'s, or every
    feature's (`None`)."""

    def mutate(a):
        n = a["pixels"].shape[0]
        frames = np.random.default_rng(seed).choice(np.arange(1, n), int(fraction * n), False)
        if a["pixels"].ndim == 2 or feature is None:
            a["pixels"][frames] = np.nan
        else:
            a["pixels"][frames, feature] = np.nan

    return mutate


def _keep_frames(*frames):
    def mutate(a):
        keep = a["pixels"][list(frames)].copy()
        a["pixels"][:] = np.nan
        a["pixels"][list(frames)] = keep

    return mutate


# 1. data files: intrinsics, times, features, missing frames, gains


def _transpose(key):
    return _set(key, lambda a: a[key].T.copy())


data_probe("velocity_A_transposed", "transposed_A", "v", _transpose("A"))
data_probe("structure_A_transposed", "transposed_A", "s", _transpose("A"))
data_probe("euclidean_A_nominal_transposed", "transposed_A", "e", _transpose("A_nominal"))


def _scale_times(factor, *keys, dtype=None):
    def mutate(a):
        for key in keys:
            t = a[key] * factor
            a[key] = np.round(t).astype(dtype) if dtype is not None else t

    return mutate


data_probe("velocity_t_ms", "time_units", "v", _scale_times(1e3, "t"))
data_probe("structure_t_ms", "time_units", "s", _scale_times(1e3, "t", "camera_t"))
data_probe("euclidean_t_ms", "time_units", "e", _scale_times(1e3, "t"))
data_probe("structure_camera_t_ms_only", "time_units", "s", _scale_times(1e3, "camera_t"))
data_probe("velocity_t_us", "time_units", "v", _scale_times(1e6, "t"))
data_probe("velocity_t_ns_int64", "time_units", "v", _scale_times(1e9, "t", dtype=np.int64))
data_probe(
    "velocity_t_timedelta64",
    "time_units",
    "v",
    _scale_times(1e9, "t", dtype="timedelta64[ns]"),
)
data_probe(
    "structure_t_timedelta64",
    "time_units",
    "s",
    _scale_times(1e9, "t", "camera_t", dtype="timedelta64[ns]"),
)


def _nan_feature(feature, first=0):
    def mutate(a):
        a["pixels"][first:, feature] = np.nan

    return mutate


data_probe(
    "velocity_feature_seen_only_in_reference",
    "never_seen",
    "v",
    _nan_feature(3, first=1),
    what="feature 3 in frame 0 (the reference image) only",
)
data_probe(
    "velocity_feature_never_seen_with_reference_pixels",
    "never_seen",
    "v",
    _both(_set("reference_pixels", lambda a: a["pixels"][0].copy()), _nan_feature(3)),
)
data_probe("euclidean_feature_never_seen", "never_seen", "e", _nan_feature(8))
data_probe(
    "structure_point_seen_once",
    "never_seen",
    "s",
    lambda a: a["pixels"].__setitem__(slice(1, None), np.nan),
)

data_probe(
    "euclidean_17589_of_17600_missing",
    "mostly_missing",
    "e8",
    _keep_frames(0),
    what="1600 frames x 11 features, 11 observations (frame 0)",
)
data_probe(
    "euclidean_17578_of_17600_missing",
    "mostly_missing",
    "e8",
    _keep_frames(0, 800),
    what="22 observations (frames 0 and 800)",
)
data_probe("velocity_two_frames_seen_of_500", "mostly_missing", "v", _keep_frames(0, 1))
data_probe("structure_two_frames_seen_of_100", "mostly_missing", "s", _keep_frames(0, 1))

data_probe("velocity_75pct_frames_dropped", "dropped_frames", "v", _drop_frames(None))
data_probe("velocity_75pct_frames_miss_a_feature", "dropped_frames", "v", _drop_frames(5))
data_probe("structure_75pct_frames_dropped", "dropped_frames", "s", _drop_frames(None))
data_probe("euclidean_75pct_frames_miss_a_feature", "dropped_frames", "e", _drop_frames(7))
data_probe(
    "run_velocity_75pct_frames_dropped",
    "dropped_frames",
    "v",
    _drop_frames(None),
    command=["run", "velocity"],
)
data_probe(
    "compare_velocity_75pct_frames_miss_a_feature",
    "dropped_frames",
    "v",
    _drop_frames(5),
    command=["compare", "velocity"],
    extra=("--seeds", "2"),
)
data_probe(
    "sweep_velocity_75pct_frames_miss_a_feature",
    "dropped_frames",
    "v",
    _drop_frames(5),
    command=["sweep", "velocity"],
    extra=("--grid", "K_scale=0.5/1", "--seeds", "1"),
)

data_probe("velocity_rho_1e9", "gains", "v", _set("rho", np.full(6, 1e9)))
data_probe("velocity_K_1e9", "gains", "v", _set("K", np.full(6, 1e9)))
data_probe(
    "velocity_K_1e12_no_truth",
    "gains",
    "v",
    _both(_set("K", np.full(6, 1e12)), lambda a: a.pop("velocity")),
)
data_probe("velocity_K_negative", "gains", "v", _set("K", -np.array([300, 300, 200, 15, 15, 15.0])))
data_probe(
    "run_velocity_rho_1e9", "gains", "v", _set("rho", np.full(6, 1e9)), command=["run", "velocity"]
)


# 2. files that are not the format: damaged, foreign, complex, objects, misspelt, bombs


def _truncated(path, arrays):
    save(path, arrays)
    raw = path.read_bytes()
    path.write_bytes(raw[: len(raw) // 2])


def _corrupt(path, arrays):
    save(path, arrays)
    raw = bytearray(path.read_bytes())
    middle = len(raw) // 2
    raw[middle : middle + 64] = bytes(range(7, 7 + 64))
    path.write_bytes(bytes(raw))


def _empty(path, arrays):
    path.write_bytes(b"")


def _npy_renamed(path, arrays):
    with path.open("wb") as f:
        np.save(f, arrays["pixels"])


def _text(path, arrays):
    path.write_text("t u v\n0.0 512.1 384.2\n0.005 512.3 384.0\n")


def _csv_tracks(path, arrays):
    rows = ["t,feature,u,v"]
    for k, t in enumerate(arrays["t"][:50]):
        for i, (u, v) in enumerate(arrays["pixels"][k]):
            rows.append(f"{t!r},{i},{u!r},{v!r}")
    path.write_text("\n".join(rows) + "\n")


file_probe("velocity_truncated_zip", "unreadable_file", "v", _truncated)
file_probe("structure_truncated_zip", "unreadable_file", "s", _truncated)
file_probe("euclidean_truncated_zip", "unreadable_file", "e", _truncated)
file_probe("velocity_corrupt_zip", "unreadable_file", "v", _corrupt)
file_probe("euclidean_corrupt_zip", "unreadable_file", "e", _corrupt)
file_probe("velocity_empty_file", "unreadable_file", "v", _empty)
file_probe("velocity_npy_renamed_npz", "unreadable_file", "v", _npy_renamed)
file_probe("euclidean_text_file", "unreadable_file", "e", _text)
file_probe("velocity_csv_tracks_as_data", "unreadable_file", "v", _csv_tracks, file="tracks.csv")


@probe("velocity_data_is_a_folder", "unreadable_file")
def _data_folder(folder):
    def build(f):
        (f / "data.npz").mkdir()
        return data_cmd("v")

    return command_probe(build)(folder)


def _complex(key):
    return _set(key, lambda a: a[key].astype(complex))


data_probe("velocity_pixels_complex", "complex", "v", _complex("pixels"))
data_probe("structure_camera_velocity_complex", "complex", "s", _complex("camera_velocity"))
data_probe("euclidean_platform_x_complex", "complex", "e", _complex("platform_x"))


def _objects(key):
    def mutate(a):
        rows = np.empty(a[key].shape[0], dtype=object)
        for i, row in enumerate(a[key]):
            rows[i] = row
        a[key] = rows

    return mutate


data_probe("velocity_pixels_object_array", "object", "v", _objects("pixels"))
data_probe("euclidean_known_features_object_array", "object", "e", _objects("known_features"))

data_probe("velocity_key_pixel", "misspelt_key", "v", _rename("pixels", "pixel"))
data_probe(
    "structure_key_camera_vel", "misspelt_key", "s", _rename("camera_velocity", "camera_vel")
)
data_probe(
    "euclidean_key_known_feature", "misspelt_key", "e", _rename("known_features", "known_feature")
)
data_probe("velocity_key_Rstar", "misspelt_key", "v", _rename("R_star", "Rstar"))
data_probe("velocity_extra_key_notes", "misspelt_key", "v", _set("notes", np.array("run 3")))


def _zip_bomb(bytes_, *, forge=None):
    """A valid velocity file whose `pixels` member is `bytes_` of zeros, deflated (a few MB
    on disk); `forge`: the declared uncompressed size written into the headers instead."""

    def write(path, arrays):
        n = bytes_ // 96
        with zipfile.ZipFile(path, "w") as zf:
            for key, value in arrays.items():
                if key == "pixels":
                    continue
                with zf.open(f"{key}.npy", "w") as f:
                    npy_format.write_array(f, np.asarray(value))
            info = zipfile.ZipInfo("pixels.npy")
            info.compress_type = zipfile.ZIP_DEFLATED
            with zf.open(info, "w", force_zip64=bytes_ > 2**31) as f:
                header = {"descr": "<f8", "fortran_order": False, "shape": (n, 6, 2)}
                npy_format.write_array_header_1_0(f, header)
                chunk, left = bytes(2**24), n * 96
                while left > 0:
                    f.write(chunk[: min(left, len(chunk))])
                    left -= len(chunk)
        if forge is not None:  # the local and central headers declare `forge` bytes
            raw = bytearray(path.read_bytes())
            at = raw.find(b"PK\x03\x04" + b"\x14\x00", 0)
            while at >= 0:
                name_len = int.from_bytes(raw[at + 26 : at + 28], "little")
                if raw[at + 30 : at + 30 + name_len] == b"pixels.npy":
                    raw[at + 22 : at + 26] = forge.to_bytes(4, "little")
                at = raw.find(b"PK\x03\x04", at + 4)
            at = raw.find(b"PK\x01\x02")
            while at >= 0:
                name_len = int.from_bytes(raw[at + 28 : at + 30], "little")
                if raw[at + 46 : at + 46 + name_len] == b"pixels.npy":
                    raw[at + 24 : at + 28] = forge.to_bytes(4, "little")
                at = raw.find(b"PK\x01\x02", at + 4)
            path.write_bytes(bytes(raw))

    return write


file_probe(
    "velocity_zip_bomb_200MB_limit_64MB",
    "zip_bomb",
    "v",
    _zip_bomb(200 * 2**20),
    env={"VISJAX_MAX_DATA_BYTES": str(64 * 2**20)},
)
file_probe(
    "velocity_zip_bomb_3GiB",
    "zip_bomb",
    "v",
    _zip_bomb(3 * 2**30),
    what="3 MB on disk, 3 GiB inflated (the default limit: 2 GiB)",
)
file_probe(
    "velocity_zip_bomb_forged_size",
    "zip_bomb",
    "v",
    _zip_bomb(200 * 2**20, forge=4096),
    what="200 MB inflated, its headers declaring 4 kB",
)


def _foreign(fmt, command):
    def build(folder):
        save(folder / "data.npz", data(fmt))
        return data_cmd(fmt, command=[command])

    return build


FORMAT_NAME = {"v": "velocity", "s": "moving_point", "e": "static_points"}
for fmt, command in (("s", "velocity"), ("v", "static_points"), ("e", "moving_point")):
    name = f"{command}_given_a_{FORMAT_NAME[fmt]}_file"
    PROBES.append(Probe(name, "wrong_format", command_probe(_foreign(fmt, command))))


def _swap_times(a):
    a["t"][[10, 11]] = a["t"][[11, 10]]


data_probe("velocity_t_not_increasing", "bad_values", "v", _swap_times)
data_probe("structure_t_repeated", "bad_values", "s", lambda a: a["t"].__setitem__(5, a["t"][4]))
data_probe(
    "euclidean_A_nominal_nan",
    "bad_values",
    "e",
    lambda a: a["A_nominal"].__setitem__((0, 2), np.nan),
)
data_probe(
    "velocity_pixels_homogeneous",
    "bad_values",
    "v",
    _set("pixels", lambda a: np.concatenate([a["pixels"], np.ones_like(a["pixels"][..., :1])], -1)),
)


# 3. the study commands: grids, seeds, chunks and other options

PD = ["--grid", "alpha=100/200", "--seeds", "1"]
for name, argv in (
    (
        "sweep_grid_unknown_axis",
        ["sweep", "velocity", "--duration", "0.5", "--grid", "K_scal=0.1/1"],
    ),
    ("sweep_grid_negative", ["sweep", "point_depth", "--grid", "alpha=-1/2"]),
    ("sweep_grid_nan", ["sweep", "homography", "--grid", "k_P=nan/10"]),
    (
        "sweep_grid_inf",
        ["sweep", "static_points", "--duration", "2", "--grid", "alpha_scale=1/inf"],
    ),
    ("sweep_grid_zero", ["sweep", "point_depth", "--grid", "alpha=0/100"]),
    ("sweep_grid_log_axis_negative_end", ["sweep", "point_depth", "--grid", "alpha=-10:3000:5"]),
    ("sweep_grid_1e11_points", ["sweep", "point_depth", "--grid", "alpha=1:10:100000000000"]),
    ("tune_grid_unknown_axis", ["tune", "point_depth", "--grid", "alpah=100/200"]),
    ("tune_grid_negative", ["tune", "velocity", "--duration", "0.5", "--grid", "rho_scale=-1/1"]),
    ("tune_grid_inf", ["tune", "point_depth", "--grid", "alpha=100/inf"]),
    ("compare_with_grid", ["compare", "point_depth", "--grid", "alpha=1/2"]),
):
    argv_probe(name, "grid", argv)

for name, argv, timeout in (
    ("compare_seeds_2e9", ["compare", "point_depth", "--seeds", "2000000000"], TIMEOUT_S),
    ("compare_seeds_0", ["compare", "point_depth", "--seeds", "0"], TIMEOUT_S),
    (
        "sweep_seeds_negative",
        ["sweep", "point_depth", "--grid", "alpha=100/200", "--seeds", "-1"],
        TIMEOUT_S,
    ),
    (
        "sweep_seeds_1e8_of_50_points",
        ["sweep", "point_depth", "--grid", "alpha=100:3000:50", "--seeds", "100000000"],
        TIMEOUT_S,
    ),
    (
        "tune_seeds_3e9",
        ["tune", "point_depth", "--grid", "alpha=100/200", "--seeds", "3000000000"],
        TIMEOUT_S,
    ),
    ("compare_seeds_1e6", ["compare", "point_depth", "--seeds", "1000000"], 90.0),
):
    argv_probe(name, "seeds", argv, timeout=timeout)

for name, extra, benign in (
    ("sweep_chunk_0", ["--chunk", "0"], False),
    ("sweep_chunk_negative", ["--chunk", "-4"], False),
    ("sweep_chunk_1e12", ["--chunk", "1000000000000"], True),
    ("sweep_shard_3_of_2", ["--shard", "3/2"], False),
):
    argv_probe(name, "chunk", ["sweep", "point_depth", *PD, *extra], benign=benign)

for name, argv in (
    ("tune_steps_0", ["tune", "point_depth", *PD, "--steps", "0"]),
    ("tune_steps_1e9", ["tune", "point_depth", *PD, "--steps", "1000000000"]),
    ("tune_learning_rate_negative", ["tune", "point_depth", *PD, "--learning-rate", "-0.1"]),
    ("compare_noise_negative", ["compare", "point_depth", "--noise", "-1"]),
    ("run_duration_1e9", ["run", "point_depth", "--duration", "1e9"]),
    ("run_duration_0", ["run", "point_depth", "--duration", "0"]),
    ("run_unknown_method", ["run", "velocity", "--method", "nosuch"]),
    ("run_unknown_problem", ["run", "velocity_estimator"]),
    ("run_unknown_set", ["run", "moving_point", "--set", "I.9"]),
):
    argv_probe(name, "study_option", argv)


# 4. visjax track: videos that are not


def _video_probe(name, write, file="video.mp4", what=""):
    def build(folder):
        write(folder / file)
        return ["track", file, "--out", "tracks.npz"]  # not --quiet: its summary line

    PROBES.append(Probe(name, "track_video", command_probe(build), what=what))


def _copy_video(suffix, edit=None):
    def write(path):
        raw = (BASE["videos"] / f"video{suffix}").read_bytes()
        path.write_bytes(edit(raw) if edit else raw)

    return write


def _npz_video(frames=None, fps=15.0):
    def write(path):
        np.savez(path, frames=BASE["frames"] if frames is None else frames(BASE["frames"]), fps=fps)

    return write


def _garbled(raw):
    raw = bytearray(raw)
    middle = len(raw) // 2
    raw[middle : middle + 1024] = bytes(i % 251 for i in range(1024))
    return bytes(raw)


def _still_image(path):
    import cv2

    png = path.with_suffix(".png")
    cv2.imwrite(str(png), BASE["frames"][0])
    png.rename(path)


_video_probe("track_empty_video", lambda p: p.write_bytes(b""))
_video_probe("track_text_renamed_mp4", lambda p: p.write_text("not a video\n" * 20))
_video_probe("track_truncated_mp4", _copy_video(".mp4", lambda raw: raw[: len(raw) // 2]))
_video_probe("track_corrupt_mp4", _copy_video(".mp4", _garbled))
_video_probe("track_velocity_data_as_video", lambda p: save(p, data("v")), file="data.npz")
_video_probe("track_still_png_renamed_mp4", _still_image)
_video_probe(
    "track_npz_float_frames", _npz_video(lambda f: f.astype(float) / 255), file="video.npz"
)
_video_probe("track_npz_fps_0", _npz_video(fps=0.0), file="video.npz")
_video_probe("track_npz_one_frame", _npz_video(lambda f: f[:1]), file="video.npz")
_video_probe("track_npz_black_frames", _npz_video(lambda f: np.zeros_like(f)), file="video.npz")


# 5. --out: the user's files, other commands' results, concurrent runs, signals


def _user_files(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "notes.txt").write_text("my notes on this experiment\n")
    (out / "analysis").mkdir(exist_ok=True)
    (out / "analysis" / "fit.py").write_text("print('my analysis')\n")


def _with_user_files(fmt, mutate=None, *, extra=()):
    def build(folder):
        arrays = data(fmt)
        if mutate:
            mutate(arrays)
        save(folder / "data.npz", arrays)
        _user_files(folder / "out")
        return data_cmd(fmt, "data.npz", *extra)

    return build


def _wrote(*names):
    def check(folder, rc, out, err):
        missing = [n for n in names if not (folder / "out" / n).exists()]
        return [f"no {missing} in out/ after exit {rc}"] if missing else []

    return check


PROBES += [
    Probe(
        "out_user_files_survive_a_run",
        "out_user_files",
        command_probe(_with_user_files("v"), check=_wrote("summary.json", "estimates.parquet")),
        mistake=False,
    ),
    Probe(
        "out_user_files_survive_a_failed_run",
        "out_user_files",
        command_probe(_with_user_files("v", _drop_frames(None))),
        what="75% of the frames dropped: a failed run, its files kept",
    ),
    Probe(
        "out_user_files_survive_a_refused_file",
        "out_user_files",
        command_probe(_with_user_files("v", _transpose("A"))),
    ),
]


def _named_like_output(make):
    def build(folder):
        save(folder / "data.npz", data("v"))
        _user_files(folder / "out")
        make(folder / "out")
        return data_cmd("v")

    return build


def _user_folder_estimate(out):
    (out / "estimates.parquet").mkdir()
    (out / "estimates.parquet" / "mine.txt").write_text("a folder of mine\n")


PROBES += [
    Probe(
        "out_user_subfolder_named_estimates_parquet",
        "out_user_files",
        command_probe(_named_like_output(_user_folder_estimate)),
        mistake=False,
    ),
    Probe(
        "out_user_summary_json",
        "out_user_files",
        command_probe(
            _named_like_output(lambda out: (out / "summary.json").write_text('{"mine": 1}\n'))
        ),
        mistake=False,
    ),
]


@probe("out_user_file_added_named_like_next_output", "out_user_files", mistake=False)
def _added_later(folder):
    save(folder / "data.npz", data("v"))
    _user_files(folder / "out")
    rc, out, err = visjax(data_cmd("v"), folder)
    if rc != 0 or crashed(rc, err):
        return Outcome(rc, out, err, [f"the first run failed: exit {rc}"], crashed(rc, err))
    (folder / "out" / "velocity.pdf").write_text("my own figure\n")
    return command_probe(lambda f: data_cmd("v", "data.npz", "--format", "png,pdf"))(folder)


def _other_command(second, *, force=False):
    """velocity's results in out/ with the user's files; then `second` into it."""

    def run(folder):
        save(folder / "data.npz", data("v"))
        save(folder / "structure.npz", data("s"))
        _user_files(folder / "out")
        rc, out, err = visjax(data_cmd("v"), folder)
        if rc != 0 or crashed(rc, err):
            return Outcome(rc, out, err, [f"the first run failed: exit {rc}"], crashed(rc, err))
        first = (folder / "out" / "summary.json").read_bytes()

        def check(f, rc, out, err):
            now = f / "out" / "summary.json"
            if force:
                title = json.loads(now.read_text()).get("problem", "") if now.exists() else ""
                bad = [] if title.startswith("moving point") else [f"the summary is {title}'s"]
                table = f / "out" / "estimates.parquet"
                if table.exists() and "v_hat[0]" in pd.read_parquet(table).columns:
                    bad.append("velocity's estimates.parquet left beside the new results")
                return bad if rc == 0 else [f"--force run failed: exit {rc}"]
            if not now.exists() or now.read_bytes() != first:
                return ["velocity's summary.json was replaced or deleted"]
            if not (f / "out" / "estimates.parquet").exists():
                return ["velocity's estimates.parquet was deleted"]
            return []

        return command_probe(lambda f: second, check=check)(folder)

    return run


S_INTO_OUT = ["moving_point", "--data", "structure.npz", "--out", "out", "--quiet"]
PROBES += [
    Probe("out_holds_another_commands_results", "out_other_command", _other_command(S_INTO_OUT)),
    Probe(
        "out_holds_another_commands_results_force",
        "out_other_command",
        _other_command([*S_INTO_OUT, "--force"], force=True),
        mistake=False,
    ),
]


@probe("out_compare_into_a_sweeps_folder", "out_other_command")
def _compare_into_sweep(folder):
    rc, out, err = visjax(["sweep", "point_depth", *PD, "--out", "out", "--quiet"], folder)
    if rc != 0 or crashed(rc, err):
        return Outcome(rc, out, err, [f"the sweep failed: exit {rc}"], crashed(rc, err))
    first = (folder / "out" / "summary.json").read_bytes()

    def check(f, rc, out, err):
        ok = (f / "out" / "summary.json").read_bytes() == first
        return [] if ok else ["the sweep's summary.json was replaced"]

    argv = ["compare", "point_depth", "--seeds", "1", "--out", "out", "--quiet"]
    return command_probe(lambda f: argv, check=check)(folder)


@probe("out_is_the_data_folder", "out_user_files", mistake=False)
def _out_data_folder(folder):
    def build(f):
        (f / "logs").mkdir()
        save(f / "logs" / "data.npz", data("v"))
        (f / "logs" / "README.txt").write_text("logged on the rig\n")
        return ["velocity", "--data", "logs/data.npz", "--out", "logs", "--quiet"]

    return command_probe(build, check=lambda f, rc, o, e: [] if rc == 0 else [f"exit {rc}"])(folder)


@probe("out_is_the_data_file", "out_user_files")
def _out_data_file(folder):
    def build(f):
        save(f / "data.npz", data("v"))
        return ["velocity", "--data", "data.npz", "--out", "data.npz", "--quiet"]

    return command_probe(build)(folder)


@probe("track_out_exists", "out_user_files")
def _track_out_exists(folder):
    def build(f):
        shutil.copy(BASE["videos"] / "video.npz", f / "video.npz")
        np.savez(f / "tracks.npz", t=np.arange(3.0), pixels=np.zeros((3, 1, 2)))
        return ["track", "video.npz", "--out", "tracks.npz", "--quiet"]

    return command_probe(build)(folder)


def _concurrent(first_argv, second_argv):
    """Two runs started together into one out/ (with the user's files): each succeeds or
    is refused in one line (never both refused); the folder holds one command's complete
    results, recorded in its manifest."""

    def run(folder):
        save(folder / "data.npz", data("v"))
        save(folder / "structure.npz", data("s"))
        _user_files(folder / "out")
        before = snapshot(folder)
        procs = [start(first_argv, folder), start(second_argv, folder)]
        results = [finish(p, TIMEOUT_S) for p in procs]
        codes = [r[0] for r in results]
        out = "\n--- second run ---\n".join(r[1] for r in results)
        err = "\n--- second run ---\n".join(r[2] for r in results)
        broke = any(crashed(rc, e) for rc, _, e in results)
        if None in codes:
            return Outcome(None, out, err, [], broke)
        problems = damage(folder, before) + schema_problems(folder, before)
        for rc, _, e in results:
            if rc not in (0, 2) or (rc == 2 and not clear_error(e)):
                problems.append(f"a run exited {rc} without one clear line")
        if 0 not in codes:
            problems.append("both runs were refused")
        manifest = folder / "out" / ".visjax-outputs.json"
        if not manifest.exists():
            problems.append("no .visjax-outputs.json in out/")
        else:
            record = json.loads(manifest.read_text())
            gone = [e for e in record["entries"] if not (folder / "out" / e).exists()]
            if gone:
                problems.append(f"the manifest names entries that are missing: {gone}")
            summary = json.loads((folder / "out" / "summary.json").read_text())
            titles = {"velocity": "velocity", "moving_point": "moving point"}
            if not summary.get("problem", "").startswith(titles.get(record["command"], "?")):
                problems.append(
                    f"mixed: the manifest is {record['command']}'s, the summary "
                    f"{summary.get('problem')}'s"
                )
            stray = {"estimates.parquet", "run.png"} - set(record["entries"])
            stray = [n for n in stray if (folder / "out" / n).exists()]
            if stray:
                problems.append(f"mixed: {stray} in out/ but not in its manifest")
        return Outcome(codes, out, err, problems, broke)

    return run


V_INTO_OUT = data_cmd("v")
PROBES += [
    Probe(
        "out_two_concurrent_runs_same_command",
        "out_concurrent",
        _concurrent(V_INTO_OUT, V_INTO_OUT),
        mistake=False,
    ),
    Probe(
        "out_two_concurrent_runs_different_commands",
        "out_concurrent",
        _concurrent(V_INTO_OUT, S_INTO_OUT),
        mistake=False,
    ),
]


def _signalled(argv, signum, *, delay=2.0):
    """A run into out/ (holding the user's files), sent `signum` `delay` s after its
    staging folder appears: exit 128 + signum, one `visjax: interrupted` line, no staging
    folder left, the user's files intact, and if it says nothing was written, nothing new
    in out/."""

    def run(folder):
        save(folder / "data.npz", data("v2"))  # 2 s: a run long enough to interrupt
        _user_files(folder / "out")
        before = snapshot(folder)
        entries = set(os.listdir(folder / "out"))
        p = start(argv, folder)
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and p.poll() is None:
            if any((folder / "out").glob(".visjax-stage-*")):
                break
            time.sleep(0.05)
        problems = []
        if p.poll() is None:
            time.sleep(delay)
        if p.poll() is None:
            p.send_signal(signum)
        else:
            problems.append(f"the run ended (exit {p.returncode}) before the signal")
        rc, out, err = finish(p, TIMEOUT_S)
        if rc is None:
            return Outcome(None, out, err, problems, crashed(rc, err))
        problems += damage(folder, before)
        if not problems:
            if rc != 128 + signum:
                problems.append(f"exit {rc}, not {128 + signum}")
            if not clear_error(err) or "visjax: interrupted" not in err:
                problems.append("no single `visjax: interrupted` line")
            new = sorted(set(os.listdir(folder / "out")) - entries)
            if "nothing was written" in err and new:
                problems.append(f"said nothing was written, but out/ has new entries {new}")
        return Outcome(rc, out, err, problems, crashed(rc, err))

    return run


SWEEP_V = ["sweep", "velocity", "--data", "data.npz", "--grid", "K_scale=0.3:3:4"]
COMPARE_V = ["compare", "velocity", "--data", "data.npz", "--seeds", "2"]
PROBES += [
    Probe("out_sigint_mid_run", "out_signal", _signalled(V_INTO_OUT, signal.SIGINT), False),
    Probe("out_sigterm_mid_run", "out_signal", _signalled(V_INTO_OUT, signal.SIGTERM), False),
    Probe(
        "out_sigint_mid_sweep",
        "out_signal",
        _signalled([*SWEEP_V, "--seeds", "2", "--out", "out", "--quiet"], signal.SIGINT),
        False,
    ),
    Probe(
        "out_sigterm_mid_compare",
        "out_signal",
        _signalled([*COMPARE_V, "--out", "out", "--quiet"], signal.SIGTERM),
        False,
    ),
]


@probe("out_sigkill_mid_run_then_rerun", "out_signal", mistake=False)
def _killed_then_rerun(folder):
    save(folder / "data.npz", data("v"))
    _user_files(folder / "out")
    p = start(V_INTO_OUT, folder)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and p.poll() is None:
        if any((folder / "out").glob(".visjax-stage-*")):
            break
        time.sleep(0.05)
    time.sleep(1.0)
    with contextlib.suppress(ProcessLookupError):
        os.killpg(p.pid, signal.SIGKILL)
    finish(p, 60)
    # the killed run's staging folder is the next run's to clean up
    return command_probe(lambda f: V_INTO_OUT, check=_wrote("summary.json"))(folder)


# --- the driver --------------------------------------------------------------------------------


# 6. the second pass (issue 44): deletions, verified parts, the newer commands


def _plain_snapshot(folder: Path) -> dict[str, str]:
    """Every file under `folder` with its digest, manifests or not (a forged manifest must
    not make the user's files look like a command's)."""
    files = {}
    for path in folder.rglob("*"):
        if path.is_file() and not path.is_symlink() and ".visjax-stage-" not in str(path):
            files[str(path.relative_to(folder))] = hashlib.sha256(path.read_bytes()).hexdigest()
    return files


def _forged_manifest(entries, *, command="velocity"):
    """`out/.visjax-outputs.json` listing `entries` (left by anyone); the user's files
    beside `out` and in it; then `velocity --data` into `out`: nothing of the user's goes."""

    def run(folder):
        save(folder / "data.npz", data("v"))
        (folder / "keep.txt").write_text("beside --out\n")
        _user_files(folder / "out")
        (folder / "out" / "data.npz").write_bytes((folder / "data.npz").read_bytes())
        record = {"command": command, "entries": entries}
        (folder / "out" / ".visjax-outputs.json").write_text(json.dumps(record))
        before = _plain_snapshot(folder)
        rc, out, err = visjax(data_cmd("v"), folder)
        after = _plain_snapshot(folder)
        lost = [k for k, v in before.items() if after.get(k) != v and "visjax-outputs" not in k]
        problems = [f"the user's file {k} was deleted or changed" for k in lost]
        return Outcome(rc, out, err, problems, crashed(rc, err))

    return run


PROBES += [
    Probe("out_manifest_lists_dotdot", "out_manifest", _forged_manifest([".."]), False),
    Probe("out_manifest_lists_dot", "out_manifest", _forged_manifest(["."]), False),
    Probe(
        "out_manifest_lists_paths",
        "out_manifest",
        _forged_manifest(["../keep.txt", "/etc", "analysis/fit.py"]),
        False,
    ),
    Probe("out_manifest_lists_users_file", "out_manifest", _forged_manifest(["data.npz"]), False),
]

PD_PLANAR = ["sweep", "point_depth", "--set", "planar", "--duration", "0.05", *PD]


def _users_variant_folder(link: bool, force: bool):
    """The user's own `planar/` (a folder, or a link to one elsewhere) in `--out` where a
    sweep writes its parts: refused before any work, nothing of the user's touched."""

    def run(folder):
        out = folder / "out"
        out.mkdir()
        mine = folder / "mine" if link else out / "planar"
        (mine / "parts").mkdir(parents=True)
        (mine / "notes.txt").write_text("mine\n")
        (mine / "parts" / "part-0000000.parquet").write_text("my own file of that name\n")
        if link:
            (out / "planar").symlink_to(mine, target_is_directory=True)
        before = _plain_snapshot(folder)
        argv = [*PD_PLANAR, "--out", "out", "--quiet", *(["--force"] if force else [])]
        rc, o, err = visjax(argv, folder)
        after = _plain_snapshot(folder)
        lost = [k for k, v in before.items() if after.get(k) != v]
        problems = [f"the user's file {k} was deleted or changed" for k in lost]
        return Outcome(rc, o, err, problems, crashed(rc, err))

    return run


PROBES += [
    Probe("sweep_users_variant_folder", "out_user_folder", _users_variant_folder(False, False)),
    Probe(
        "sweep_users_variant_folder_force", "out_user_folder", _users_variant_folder(False, True)
    ),
    Probe(
        "sweep_variant_folder_is_a_link_force", "out_user_folder", _users_variant_folder(True, True)
    ),
]


def _copy_part(parts, folder):
    (parts / "part-0000001.parquet").write_bytes((parts / "part-0000000.parquet").read_bytes())


def _truncate_part(parts, folder):
    data_ = (parts / "part-0000000.parquet").read_bytes()
    (parts / "part-0000000.parquet").write_bytes(data_[: len(data_) // 2])


def _drop_identity(parts, folder):
    m = json.loads((parts / "manifest.json").read_text())
    del m["identity"]
    (parts / "manifest.json").write_text(json.dumps(m))


def _corrupt_manifest(parts, folder):
    (parts / "manifest.json").write_text('{"identity": "abc", "done": [0, ')


RESUME = [*PD_PLANAR, "--chunk", "1", "--out", "out", "--quiet", "--resume"]
PD_PLANAR_C1 = [*PD_PLANAR, "--chunk", "1"]
MERGE = ["merge", "out/planar/parts", "--out", "merged", "--quiet"]


def _sweep_then_c1(alter, then):
    def run(folder):
        rc, o, err = visjax([*PD_PLANAR_C1, "--out", "out", "--quiet"], folder)
        if rc != 0 or crashed(rc, err):
            return Outcome(rc, o, err, [f"the first sweep failed: exit {rc}"], crashed(rc, err))
        return _after(folder, alter, then)

    return run


def _after(folder, alter, then):
    import pyarrow.parquet as pq

    before = pq.read_table(folder / "out" / "planar" / "runs.parquet").to_pandas()
    alter(folder / "out" / "planar" / "parts", folder)

    def check(f, rc, out, err):
        if then[0] != "sweep" or rc != 0:
            return []
        after = pq.read_table(f / "out" / "planar" / "runs.parquet").to_pandas()
        return [] if after.equals(before) else ["the resumed table differs from the whole one"]

    return command_probe(lambda f: then, check=check)(folder)


PROBES += [
    Probe(
        "resume_part_copied_over_another",
        "parts_verified",
        _sweep_then_c1(_copy_part, RESUME),
        False,
    ),
    Probe("resume_truncated_part", "parts_verified", _sweep_then_c1(_truncate_part, RESUME), False),
    Probe("merge_part_copied_over_another", "parts_verified", _sweep_then_c1(_copy_part, MERGE)),
    Probe("merge_truncated_part", "parts_verified", _sweep_then_c1(_truncate_part, MERGE)),
    Probe(
        "merge_manifest_missing_identity", "parts_verified", _sweep_then_c1(_drop_identity, MERGE)
    ),
    Probe("resume_corrupt_manifest", "parts_verified", _sweep_then_c1(_corrupt_manifest, RESUME)),
]


_USER_MODULE = """
import jax.numpy as jnp
from visjax import studies
import sys
sys.path.insert(0, {root!r})
from tests.studies.slow_toy import slow_toy

studies.register_problem(
    "pathlike", lambda *, noise_px=0.1, variant=None: slow_toy(noise_px=noise_px),
    variants=("a/b", "/abs", "../up"),
)
"""


@probe("variant_names_like_paths", "output_names", mistake=False)
def _variant_paths(folder):
    (folder / "mine.py").write_text(_USER_MODULE.format(root=str(ROOT)))
    sets = ["--set", "a/b", "--set", "/abs", "--set", "../up"]
    argv = ["--import", "mine", "compare", "pathlike", *sets, "--seeds", "1", "--quiet"]
    before = set(p.name for p in folder.iterdir())
    rc, out, err = visjax([*argv, "--out", "out"], folder)
    outside = sorted(set(p.name for p in folder.iterdir()) - before - {"out", "__pycache__"})
    problems = [f"written outside --out: {outside}"] if outside else []
    if rc == 0 and not (folder / "out" / "a_b" / "summary.json").exists():
        problems.append("no out/a_b/summary.json")
    return Outcome(rc, out, err, problems, crashed(rc, err))


for name, source in (
    ("import_module_not_found", None),
    ("import_module_does_not_parse", "def broken(:\n"),
    ("import_module_raises", "raise RuntimeError('my module is broken')\n"),
    (
        "import_builder_raises",
        "from visjax import studies\n"
        "def build(*, noise_px=0.1):\n    return 1 / 0\n"
        "studies.register_problem('zero', build)\n",
    ),
):

    def build(folder, source=source):
        if source is not None:
            (folder / "usermod.py").write_text(source)
        return ["--import", "usermod", "run", "zero", "--quiet", "--out", "out"]

    PROBES.append(Probe(name, "import", command_probe(build)))


_PLUGIN = """Metadata-Version: 2.1
Name: brokenplugin
Version: 0.1
"""


def _plugin_env(folder: Path) -> dict:
    """A folder on PYTHONPATH holding an installed distribution's metadata whose
    `visjax.problems` entry point names a module that does not import."""
    site = folder / "site"
    info = site / "brokenplugin-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(_PLUGIN)
    (info / "entry_points.txt").write_text(
        "[visjax.problems]\nbroken = nosuch_plugin_module:build\n"
    )
    path = os.pathsep.join([str(site), str(ROOT)])
    return {"PYTHONPATH": path}


@probe("plugin_broken_other_commands", "plugin", mistake=False)
def _plugin_others(folder):
    rc, out, err = visjax(["--version"], folder, _plugin_env(folder))
    problems = [] if rc == 0 and "visjax" in out else [f"--version: exit {rc}"]
    rc2, out2, err2 = visjax(
        ["run", "--help"],
        folder,
        {"PYTHONPATH": os.pathsep.join([str(folder / "site"), str(ROOT)])},
    )
    problems += [] if rc2 == 0 else [f"run --help: exit {rc2}"]
    return Outcome(rc, out, err + err2, problems, crashed(rc, err) or crashed(rc2, err2))


@probe("plugin_broken_named", "plugin")
def _plugin_named(folder):
    rc, out, err = visjax(["run", "broken", "--quiet"], folder, _plugin_env(folder))
    return Outcome(rc, out, err, [], crashed(rc, err))


def _closed_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@probe("sweep_ray_closed_port", "ray")
def _ray_closed(folder):
    argv = [*PD_PLANAR, "--ray", f"127.0.0.1:{_closed_port()}", "--out", "out", "--quiet"]
    rc, out, err = visjax(argv, folder, timeout=120)
    return Outcome(rc, out, err, [], crashed(rc, err))


for name, argv in (
    ("sweep_seed_2_64", [*PD_PLANAR, "--seed", "18446744073709551616"]),
    ("sweep_seed_2_63_minus_1", [*PD_PLANAR, "--seed", "9223372036854775807"]),
    ("tune_seed_2_63", ["tune", "point_depth", *PD, "--seed", "9223372036854775808"]),
    (
        "velocity_seeds_1e6",
        [
            "velocity",
            "--duration",
            "0.1",
            "--noise",
            "0.1",
            "--seeds",
            "1000000",
            "--max-hours",
            "0.01",
        ],
    ),
):
    argv_probe(name, "seeds_range", argv)


def _uint64_ns(a):
    n = a["t"].shape[0]
    a["t"] = np.iinfo(np.uint64).max - np.arange(n, dtype=np.uint64)[::-1] * np.uint64(1_000_000)
    a["time_unit"] = np.asarray("ns")


def _int_zero_marks(a):
    p = np.round(a["pixels"]).astype(np.int32)
    p[10::7, 2] = 0
    a["pixels"] = p


def _missing_two_percent(a):
    """The docs' example file: 0.1 px of noise and 2% of the observations missing."""
    rng = np.random.default_rng(0)
    a["pixels"] = a["pixels"] + 0.1 * rng.standard_normal(a["pixels"].shape)
    lost = rng.random(a["pixels"].shape[:2]) < 0.02
    lost[0] = False
    a["pixels"] = np.where(lost[..., None], np.nan, a["pixels"])


def _collinear_from(k):
    def mutate(a):
        p = a["pixels"]
        p[k:, :, 1] = p[k:, :1, 1]  # every feature on one horizontal line

    return mutate


def _behind(a):
    a["position"] = a["position"] * np.array([1.0, 1.0, -1.0])


def _uint64_build(folder):
    arrays = data("v")
    _uint64_ns(arrays)
    save(folder / "data.npz", arrays)
    return data_cmd("v")


def _ran_from_zero(folder, rc, out, err):
    """Valid times near the uint64 limit: the run goes through, its times from 0 s."""
    if rc != 0:
        return [f"exit {rc}"]
    t = pd.read_parquet(folder / "out" / "estimates.parquet")["t"].to_numpy()
    return [] if abs(t[0]) < 1e-9 and abs(t[-1] - 0.499) < 1e-6 else [f"times {t[0]} to {t[-1]}"]


PROBES.append(
    Probe(
        "velocity_time_ns_near_uint64_limit",
        "times_exact",
        command_probe(_uint64_build, check=_ran_from_zero),
        mistake=False,
    )
)
data_probe(
    "velocity_known_length_1e300",
    "plausibility",
    "v",
    lambda a: a["known_length"].__setitem__(2, 1e300),
)
data_probe(
    "velocity_known_length_1e-300",
    "plausibility",
    "v",
    lambda a: a["known_length"].__setitem__(2, 1e-300),
)
data_probe("velocity_int_pixels_zero_marks", "plausibility", "v", _int_zero_marks)
data_probe("euclidean_int_pixels_zero_marks", "plausibility", "e", _int_zero_marks)
data_probe(
    "velocity_pixels_mirrored", "plausibility", "v", lambda a: a.__setitem__("pixels", -a["pixels"])
)
data_probe(
    "euclidean_pixels_mirrored",
    "plausibility",
    "e",
    lambda a: a.__setitem__("pixels", -a["pixels"]),
)
data_probe("structure_truth_behind_camera", "plausibility", "s", _behind)
data_probe("velocity_example_noise_and_dropouts", "quality", "v", _missing_two_percent)
data_probe("velocity_collinear_from_frame_100", "quality", "v", _collinear_from(100))
data_probe("velocity_K_2e6", "quality", "v", _set("K", np.full(6, 2e6)))


def _lagging_gains(a):
    """Gains K and rho 100 times below eq. (63)'s, no truth in the file: the estimator lags
    its measurements (its output error far above the noise), which only the innovation
    check can say."""
    from visjax.papers.chitrakaran import K_EQ63, RHO_EQ63

    a["K"], a["rho"] = np.asarray(K_EQ63) / 100, np.asarray(RHO_EQ63) / 100
    a.pop("velocity")


data_probe("velocity_lagging_gains_no_truth", "quality", "v", _lagging_gains)
argv_probe(
    "compare_velocity_noise_0_5",
    "quality",
    ["compare", "velocity", "--duration", "0.5", "--noise", "0.5", "--seeds", "2"],
)


@probe("track_npz_fps_1e-9", "track_fps")
def _track_slow(folder):
    np.savez(folder / "video.npz", frames=BASE["frames"], fps=1e-9)
    rc, out, err = visjax(["track", "video.npz", "--out", "tracks.csv", "--quiet"], folder)
    return Outcome(rc, out, err, [], crashed(rc, err))


def _tail(text: str, n: int = 800) -> str:
    lines = _lines(text)
    return "\n".join(lines[-8:])[-n:]


def run_probe(probe: Probe, root: Path) -> dict:
    folder = root / probe.name
    folder.mkdir(parents=True)
    started = time.perf_counter()
    try:
        o = probe.run(folder)
        outcome, evidence = classify(probe, o, folder)
    except Exception as e:  # the probe's own failure: reported, never hidden
        o = Outcome(None, "", f"probe error: {type(e).__name__}: {e}", [f"probe error: {e}"])
        outcome, evidence = "failed_check", None
    row = {
        "name": probe.name,
        "kind": probe.kind,
        "exit": o.exit,
        "outcome": outcome,
        "stderr_tail": _tail(o.stderr),
        "stdout_tail": _tail(o.stdout, 400),
        "seconds": round(time.perf_counter() - started, 1),
    }
    if evidence:
        row["evidence"] = evidence
    if o.problems:
        row["problems"] = o.problems
    if probe.what:
        row["what"] = probe.what
    if probe.benign:
        row["benign"] = True
    return row


def select(quick: bool, only: list[str] | None) -> list[Probe]:
    if only:
        chosen = [p for p in PROBES if p.name in only or p.kind in only]
        if not chosen:
            raise SystemExit(f"no probe or kind named {only}")
        return chosen
    if not quick:
        return list(PROBES)
    first = {}
    for p in PROBES:
        first.setdefault(p.kind, p)
    return list(first.values())


def table(counts: Counter, rows: list[dict]) -> str:
    lines = ["| outcome | probes |", "|---|---:|"]
    lines += [f"| {k} | {counts.get(k, 0)} |" for k in OUTCOMES]
    lines += [f"| **total** | **{sum(counts.values())}** |"]
    kinds = sorted({r["kind"] for r in rows}, key=[r["kind"] for r in rows].index)
    lines += ["", "| kind | " + " | ".join(OUTCOMES) + " |", "|---|" + "---:|" * len(OUTCOMES)]
    for kind in kinds:
        c = Counter(r["outcome"] for r in rows if r["kind"] == kind)
        lines.append(f"| {kind} | " + " | ".join(str(c.get(k, 0)) for k in OUTCOMES) + " |")
    bad = [r for r in rows if r["outcome"] in BAD]
    if bad:
        lines += ["", "Probes to fix:", ""]
        for r in bad:
            last = r["stderr_tail"].splitlines()
            said = r.get("problems") or (last[-1] if last else "(no stderr)")
            lines.append(f"- `{r['name']}` ({r['outcome']}, exit {r['exit']}): {said}")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the first probe of each kind")
    parser.add_argument("--only", action="append", help="a probe's name or a kind (repeatable)")
    parser.add_argument("--jobs", type=int, default=2, help="probes at once (default 2)")
    parser.add_argument("--keep", help="build the probes in this folder and keep it")
    parser.add_argument("--list", action="store_true", help="list the probes and exit")
    args = parser.parse_args(argv)
    chosen = select(args.quick, args.only)
    if args.list:
        for p in chosen:
            print(f"{p.kind:<20} {p.name}")
        return 0
    with contextlib.ExitStack() as stack:
        if args.keep:
            root = Path(args.keep).resolve()
            root.mkdir(parents=True, exist_ok=True)
        else:
            root = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="visjax-probes-")))
        (root / "_base").mkdir(exist_ok=True)
        BASE.update(make_base(root / "_base"))
        started = time.perf_counter()
        with concurrent.futures.ThreadPoolExecutor(max_workers=args.jobs) as pool:
            futures = [pool.submit(run_probe, p, root / "probes") for p in chosen]
            rows = []
            for p, f in zip(chosen, futures):
                rows.append(f.result())
                print(f"{rows[-1]['outcome']:<15} {rows[-1]['seconds']:>6.1f} s  {p.name}",
                      file=sys.stderr, flush=True)  # fmt: skip
    counts = Counter(r["outcome"] for r in rows)
    report = {
        "probes": rows,
        "counts": {k: counts.get(k, 0) for k in OUTCOMES},
        "wall_time_s": round(time.perf_counter() - started, 1),
    }
    print(json.dumps(report, indent=1))
    print("\n" + table(counts, rows), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
