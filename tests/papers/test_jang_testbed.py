"""The testbed twin of Jang's thesis (chapters 4-5): the PUMA's camera follows each set's
velocities, the truth obeys the perspective kinematics (2.5), the rendered marker is
tracked within 0.5 px, and the UIO from tracked pixels is within 2x of exact pixels."""

import json
from types import SimpleNamespace

import numpy as np
import pytest

from visjax.papers import jang

DURATION = 4.0


def _kinematics_residual(run, v_p):
    """max |dr/dt - (2.5)| at the camera samples: r the truth in the camera frame, u the
    camera's commanded velocities, v_p the marker's velocity in the camera frame (m/s)."""
    r, dt = run.position, run.ts[1] - run.ts[0]
    k = run.frame_index[1:-1]
    r_dot = (r[k + 1] - r[k - 1]) / (2 * dt)
    X, Y, Z = r[k].T
    u = run.velocity_true[1:-1]
    vcx, vcy, vcz, wx, wy, wz = u.T
    vp = v_p(run.ts[k])
    model = np.stack(
        [
            vp[:, 0] - vcx + wz * Y - wy * Z,  # eq. (2.5)
            vp[:, 1] - vcy + wx * Z - wz * X,
            vp[:, 2] - vcz + wy * X - wx * Y,
        ],
        axis=1,
    )
    return np.abs(r_dot - model).max()


def _check_tracking_and_observer(r):
    assert r.tracking_rms_px < 0.5
    assert np.all(np.isfinite(r.pixels))
    # the UIO from tracked pixels within 2x of the UIO from exact ones
    assert np.linalg.norm(r.rms) < 2 * np.linalg.norm(r.rms_ideal)
    assert np.all(np.isfinite(r.estimate)) and np.all(np.isfinite(r.rms_frames))


# one twin run per test (not a shared fixture): `pytest -n 2` may run the tests of a module
# in both workers, and each would build a module fixture again


@pytest.mark.slow
def test_moving_set_end_to_end():
    r = jang.testbed("II.1", duration=DURATION)
    a = np.array(jang.SETS["II.1"].vp_amplitude) * jang.UNITS["cm"]

    def v_p(t):
        return np.stack([a[0] * np.sin(0.5 * t), a[1] * np.cos(0.3 * t), 0 * t], axis=1)

    assert r.feasible and r.result == "successful"
    assert _kinematics_residual(r, v_p) < 1e-6
    assert r.q_arm is not None and np.all(np.isfinite(r.q_arm))
    # the marker moves in a plane parallel to the image plane (Assumption 3.1)
    assert np.ptp(r.position[:, 2]) < 1e-6 and np.ptp(r.position[:, 0]) > 0.01
    _check_tracking_and_observer(r)


@pytest.mark.slow
def test_metre_reading_is_infeasible_on_a_puma():
    r = jang.testbed("I.1", units="m", duration=DURATION, track=False)
    assert not r.feasible
    assert "singular_configuration" in r.reason
    assert np.all(np.isnan(r.rms)) and r.result == "not_run"


def test_bad_arguments():
    with pytest.raises(ValueError, match="unknown set"):
        jang.testbed("III.1")
    with pytest.raises(ValueError, match="units"):
        jang.testbed("I.1", units="mm")


def test_static_set_end_to_end_through_the_command(tmp_path):
    import pandas as pd

    from visjax.cli import main

    out = tmp_path / "tb"
    argv = ["testbed", "--set", "I.1", "--duration", str(DURATION), "--no-studies"]
    assert main(argv + ["--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    entry = summary["sets"]["I.1"]
    assert summary["settings"]["studies"] is False and summary["settings"]["video"] is True
    assert entry["units"] == "cm" and entry["thesis_rms"] == [0.0016, 0.0047, 0.0214]
    assert entry["feasible"] and entry["result"] == "successful"
    assert len(entry["rms"]) == 3 and all(isinstance(x, float) for x in entry["rms"])
    for name in ("testbed_I.1.png", "testbed_I.1.mp4", "testbed_I.1.npz"):
        assert (out / name).stat().st_size > 1000
    table = pd.read_csv(out / "tables.csv")
    assert list(table["axis"]) == ["x", "y", "z"]
    assert list(table["thesis_rms_m"]) == [0.0016, 0.0047, 0.0214]
    np.testing.assert_allclose(table["rms_m"], entry["rms"], rtol=1e-12)
    with np.load(out / "testbed_I.1.npz") as z:
        r = SimpleNamespace(**{k: z[k] for k in z.files})
    assert r.estimate.shape[1] == 3 and r.pixels.shape[1] == 2
    # the PUMA's camera really moves with the set's velocities (inverse velocity
    # kinematics integrated, forward kinematics read back)
    assert _kinematics_residual(r, lambda t: np.zeros((len(t), 3))) < 1e-7
    np.testing.assert_allclose(r.position[:, 2], 0.80, atol=1e-6)  # the table is level
    # the encoders: a count of 2.4e-5 rad over one camera period, plus half a period's lag
    assert np.abs(r.velocity_measured - r.velocity_true).max() < 3e-3
    _check_tracking_and_observer(
        SimpleNamespace(
            tracking_rms_px=entry["tracking_rms_px"],
            pixels=r.pixels,
            rms=np.array(entry["rms"]),
            rms_ideal=np.array(entry["rms_ideal_pixels"]),
            estimate=r.estimate,
            rms_frames=np.array(entry["rms_frames"]),
        )
    )
    with pytest.raises(SystemExit) as e:
        main(["testbed", "--set", "IX", "--out", str(tmp_path / "x")])
    assert e.value.code == 2 and not (tmp_path / "x").exists()
