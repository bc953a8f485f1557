"""The geometry in float32, in a subprocess with x64 off (the test process runs in float64)."""

import json
import os
import pathlib
import subprocess
import sys

import pytest


@pytest.fixture(scope="module")
def measured():
    script = pathlib.Path(__file__).with_name("float32_checks.py")
    env = {**os.environ, "JAX_ENABLE_X64": "0", "JAX_PLATFORMS": "cpu"}
    done = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, env=env, timeout=600
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout)


def test_everything_stays_float32(measured):
    assert set(measured["dtypes"]) == {"float32"}


def test_float32_accuracy(measured):
    # float32 pixels carry ~3e-5 px of rounding
    assert measured["camera_round_trip"] < 1e-6
    assert measured["homography_rel"] < 1e-4
    assert measured["decomposition_recomposed"] < 2e-5
    assert measured["known_normal_R"] < 1e-5 and measured["known_normal_x"] < 1e-5
    assert measured["known_normal_scaled"] < 1e-5  # NaN (a failure) compares False
    # measured about 2e-6
    assert measured["reconstruction_general"] < 5e-5
    assert measured["reconstruction_known"] < 5e-5
    assert measured["so3_round_trip"] < 3e-5
    assert measured["so3_grad_at_identity_finite"]
    # version 1 returned af = 0 for a flat axis, and a 0.14 relative error on narrow data
    assert measured["lstsq_flat_axis_detected"]
    assert measured["lstsq_narrow_rel"] < 1e-3
    assert measured["large_pixels_successful"]
