"""The fuzz cases of `benchmarks/fuzz.py` on a few hundred inputs per function and kind,
in float64 here and in float32 in a subprocess with x64 off: nothing silently non-finite,
nothing silently wrong, every invalid input flagged."""

import importlib.util
import json
import os
import pathlib
import subprocess
import sys

import pytest

SCRIPT = pathlib.Path(__file__).parents[1] / "benchmarks" / "fuzz.py"


def _load():
    spec = importlib.util.spec_from_file_location("visjax_fuzz", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _check(report):
    for name, per_kind in report["functions"].items():
        for kind, counts in per_kind.items():
            assert counts["silent_nonfinite"] == 0, (name, kind, counts)
            assert counts["silently_wrong"] == 0, (name, kind, counts)
            if kind == "well_posed":
                assert counts["correct"] == sum(counts.values()), (name, counts)
    for name in (
        "euclidean_reconstruction",
        "project_checked",
        "so3_log",
        "decompose_homography",
        "decompose_homography_known_normal",
        "so3_exp",
        "L_omega",
    ):
        assert report["functions"][name]["invalid"]["correct"] == 0, name


def test_fuzz_float64():
    _check(_load().fuzz(200, 7, "float64"))


@pytest.mark.parametrize("seed", [11])
def test_fuzz_float32(seed):
    env = {**os.environ, "JAX_ENABLE_X64": "0", "JAX_PLATFORMS": "cpu"}
    done = subprocess.run(
        [sys.executable, str(SCRIPT), "--n", "200", "--dtype", "float32", "--seed", str(seed)],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    _check(json.loads(done.stdout))
