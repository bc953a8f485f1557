"""The fuzz cases of `tests/fuzzing.py` in the test suite: every public geometry
function and the three stream builders, well-posed, near-degenerate and invalid inputs;
float64 here at batch sizes 1,000 and 1, float32 in a subprocess with x64 off. Nothing
silently non-finite, nothing silently wrong, every invalid input flagged."""

import inspect
import json
import os
import pathlib
import subprocess
import sys

import pytest

from tests.fuzzing import PARTS, fuzz

SCRIPT = pathlib.Path(__file__).parents[1] / "benchmarks" / "fuzz.py"  # its command line


def _check(report, complete=True, streams=True):
    for name, per_kind in report["functions"].items():
        for kind, counts in per_kind.items():
            assert counts["silent_nonfinite"] == 0, (name, kind, counts)
            assert counts["silently_wrong"] == 0, (name, kind, counts)
            if kind == "well_posed":
                assert counts["correct"] == sum(counts.values()), (name, counts)
    if not complete:
        return
    # every public geometry function and the three stream builders are covered
    import visjax.geometry

    public = {n for n, f in vars(visjax.geometry).items() if inspect.isfunction(f) and n[0] != "_"}
    covered = set(report["functions"]) | {
        "L_omega_inv",  # fuzzed with L_omega
    }
    assert public <= covered, public - covered
    if streams:
        for builder in ("velocity_stream", "moving_point_stream", "static_points_stream"):
            assert builder in report["functions"]
    for name, per_kind in report["functions"].items():
        # the invalid reconstruction inputs include bad intrinsics, which the homography
        # from pixels alone rightly ignores
        if name not in ("find_homography", "find_homography_robust"):
            assert per_kind["invalid"]["correct"] == 0, name


@pytest.mark.slow
def test_fuzz_float64_batch_1000():
    report = fuzz(1000, 7, "float64")
    assert report["batch"] == 1000
    _check(report)


@pytest.mark.slow  # the unit tier's time: fuzzing is a slow-tier job (batch 1000, float32)
def test_fuzz_float64_batch_1():
    """One input per call, for the functions whose results come from reductions over points
    or matrix factorisations (what a large batch could hide); the rest, and the stream
    builders, are fuzzed at batch 1 by `python benchmarks/fuzz.py --batch 1`."""
    parts = ["fuzz_reconstruction", "fuzz_decomposition", "fuzz_select_solution"]
    report = fuzz(5, 8, "float64", batch=1, parts=parts)
    assert report["batch"] == 1
    _check(report, complete=False)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [11])
def test_fuzz_float32(seed):
    """The geometry in float32 (docs/architecture.md: the geometry must be usable with x64 off). The
    stream builders are float64 estimator inputs; `python benchmarks/fuzz.py --dtype
    float32` fuzzes them in float32 too."""
    env = {**os.environ, "JAX_ENABLE_X64": "0", "JAX_PLATFORMS": "cpu"}
    parts = [p for p in PARTS if p != "fuzz_streams"]
    done = subprocess.run(
        [sys.executable, str(SCRIPT), "--n", "200", "--dtype", "float32", "--seed", str(seed)]
        + ["--parts", *parts],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    _check(json.loads(done.stdout), streams=False)
