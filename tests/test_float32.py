"""Every method of every registered problem in float32 against float64 (issue 47): what
docs/gpu.md states, checked on short scenes by `benchmarks/float32_accuracy.py` (a float64
process and a float32 one, the same keys)."""

import json
import os
import pathlib
import subprocess
import sys

import pytest

SCRIPT = pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "float32_accuracy.py"

# Noise free, float32's error of a method is at most float64's plus 10% and 1e-4 (of the
# metric's own unit: relative depth, metres, the velocity's units): the arithmetic's
# rounding, eps = 1.2e-7 carried through each scene's conditioning, is far below both.
# One method is known to lose more, and docs/gpu.md says so: the windowed least-squares
# triangulation of the point-depth problem (float32: 0.2% depth error noise-free, float64:
# 0.002%), held here to 1%.
SLACK, FLOOR = 0.10, 1e-4
KNOWN = {("point_depth", "least_squares"): 1e-2}


@pytest.fixture(scope="module")
def rows():
    env = dict(os.environ, JAX_PLATFORMS=os.environ.get("JAX_PLATFORMS", "cpu"))
    out = subprocess.run(
        [sys.executable, str(SCRIPT), "--seeds", "2", "--duration", "0.5"],
        capture_output=True, text=True, env=env, check=False, timeout=1500,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout)["rows"]


@pytest.mark.slow
def test_every_method_of_every_problem_runs_in_float32(rows):
    problems = {r["problem"] for r in rows}
    assert problems == {"velocity", "moving_point", "static_points", "point_depth", "homography"}
    errors = [r for r in rows if "error64" in r]
    assert not errors, errors  # float32 (or float64) could not serve: never hidden
    for r in rows:  # float32 fails no more often than float64 (no max-steps stops, no NaN)
        assert r["failed32"] <= r["failed64"], r


@pytest.mark.slow
def test_float32_error_noise_free_is_float64s_to_rounding(rows):
    for r in rows:
        if r["noise_px"] != 0.0:
            continue  # with noise the keys' draws differ between the dtypes
        bound = KNOWN.get((r["problem"], r["method"]))
        if bound is None:
            bound = (1.0 + SLACK) * r["median64"] + FLOOR
        assert r["median32"] <= bound, r
