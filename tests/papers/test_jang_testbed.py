"""The testbed twin of Jang's thesis (chapters 4-5): the PUMA's camera follows each set's
velocities, the truth obeys the perspective kinematics (2.5), the rendered marker is
tracked within 0.5 px, and the UIO from tracked pixels is within 2x of exact pixels."""

import numpy as np
import pytest

from tests.helpers import check_testbed_tracking, twin_kinematics_residual
from visjax.papers import jang

DURATION = 4.0


@pytest.mark.slow
def test_moving_set_end_to_end():
    r = jang.testbed("II.1", duration=DURATION)
    a = np.array(jang.SETS["II.1"].vp_amplitude) * jang.UNITS["cm"]

    def v_p(t):
        return np.stack([a[0] * np.sin(0.5 * t), a[1] * np.cos(0.3 * t), 0 * t], axis=1)

    assert r.feasible and r.result == "successful"
    assert twin_kinematics_residual(r, v_p) < 1e-6
    assert r.q_arm is not None and np.all(np.isfinite(r.q_arm))
    # the marker moves in a plane parallel to the image plane (Assumption 3.1)
    assert np.ptp(r.position[:, 2]) < 1e-6 and np.ptp(r.position[:, 0]) > 0.01
    check_testbed_tracking(r)


@pytest.mark.slow
def test_an_apriltag_as_the_twins_marker():
    """The twin's marker drawn as the AprilTag 0 of the 36h11 family (the same side):
    found, tracked within 0.5 px, and the UIO from its tracked centre within 2x of the
    exact pixels', as with the ArUco marker."""
    r = jang.testbed("I.1", duration=DURATION, marker="36h11")
    assert r.feasible and r.result == "successful"
    check_testbed_tracking(r)


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
    for bad, match in (
        (dict(dist=(-0.3, 0.0, 0.0)), "dist"),
        (dict(dist=(np.nan, 0.0, 0.0, 0.0)), "dist"),
        (dict(time_offset_s=-0.01), "time_offset_s"),
        (dict(time_offset_s=1e-4), "rounds to no sample"),
        (dict(image_noise=np.inf), "image_noise"),
        (dict(blur_px=-1.0), "blur_px"),
        (dict(encoder_resolution=(1e-4,) * 5), "encoder_resolution"),
        (dict(encoder_resolution=0.0), "encoder_resolution"),
    ):
        with pytest.raises(ValueError, match=match):
            jang.testbed("I.1", **bad)
    with pytest.raises(ValueError, match="unknown error source"):
        jang.testbed_error_budget(sources=["clock_skew"])


def test_error_sources_are_stated_and_sourced():
    """Every error source turns on only options `testbed` takes, says its value and what
    it rests on, with a basis; the PUMA 560's encoder resolution is the published counts
    per degree, coarser than the twin's default at every joint."""
    import inspect

    options = set(inspect.signature(jang.testbed).parameters)
    assert set(jang.ERROR_SOURCES) == {
        "lens_distortion", "calibration", "time_offset", "detection", "encoders"
    }  # fmt: skip
    for name, source in jang.ERROR_SOURCES.items():
        assert source.name == name and source.basis in ("thesis", "literature", "assumption")
        assert source.value and source.rests_on
        assert set(source.options) <= options
        for _, other in source.other:
            assert set(other) <= options and other != source.options
    res = np.asarray(jang.ERROR_SOURCES["encoders"].options["encoder_resolution"])
    np.testing.assert_allclose(res * np.asarray(jang.PUMA560_COUNTS_PER_DEGREE), np.pi / 180)
    assert np.all(res > jang.TESTBED["encoder_resolution"])
    calibration = jang.ERROR_SOURCES["calibration"].options
    assert calibration == {"Kc_true": jang.KC_TOOLBOX, "Kc_observer": jang.KC_REFINED}


@pytest.mark.slow
def test_time_offset_delays_the_velocities_by_whole_frames():
    """With 25 Hz frames at 1 kHz (40 samples apart), an offset of 40 ms pairs each frame
    with the encoders' velocity of the frame before (a time-varying set, I.3); the truth and
    the frames are untouched."""
    # encoders fine enough that no count flips between the two integrations of the PUMA
    # (their backward halves end at different times)
    fine = dict(duration=2.0, camera_hz=25, track=False, encoder_resolution=1e-12)
    base = jang.testbed("I.3", **fine)
    late = jang.testbed("I.3", time_offset_s=0.04, **fine)
    np.testing.assert_allclose(late.velocity_measured[1:], base.velocity_measured[:-1], atol=1e-8)
    assert np.abs(late.velocity_measured - base.velocity_measured).max() > 1e-5
    np.testing.assert_allclose(late.position, base.position, atol=1e-9)
    np.testing.assert_array_equal(late.frame_ts, base.frame_ts)


@pytest.mark.slow
def test_lens_and_detection_sources_on_the_rendered_frames():
    """The frames rendered through a k1 = -0.3 lens: the tracked centre is the lens' image
    of the marker's centre (within 0.5 px), displaced from the pinhole projection by what
    `distort_pixels` says; noise and blur cost the tracker accuracy but keep it within
    0.5 px. The budget's rows are `testbed`'s own runs."""
    from visjax.geometry import distort_pixels

    K = np.asarray(jang.KC_REFINED)
    lens = jang.testbed("I.1", duration=2.0, dist=(-0.3, 0.0, 0.0, 0.0))
    assert lens.result == "successful" and lens.tracking_rms_px < 0.5
    seen = np.asarray(distort_pixels(lens.pixels_true, K, np.array([-0.3, 0.0, 0.0, 0.0])))
    shift = np.linalg.norm(seen - lens.pixels_true, axis=1)
    moved = np.linalg.norm(lens.pixels - lens.pixels_true, axis=1)
    np.testing.assert_allclose(moved, shift, atol=0.5)
    assert shift.max() > 0.5  # the lens moves the marker by more than the tolerance
    table = jang.testbed_error_budget(
        ("I.1",), duration=2.0, sources=["detection", "time_offset"], other_readings=False
    )
    assert list(table.columns) == [
        "set", "sources", "reading", "axis", "rms_m", "thesis_rms_m", "tracking_rms_px", "result"
    ]  # fmt: skip
    runs = table.drop_duplicates(["sources", "reading"])
    assert list(runs["sources"]) == ["none", "detection", "time_offset", "all"]
    none = table[table["sources"] == "none"]
    base = jang.testbed("I.1", duration=2.0)
    np.testing.assert_allclose(none["rms_m"], base.rms, rtol=1e-12)
    np.testing.assert_allclose(none["thesis_rms_m"], jang.SETS["I.1"].thesis_rms)
    noisy = table[table["sources"] == "detection"]["tracking_rms_px"].iloc[0]
    assert base.tracking_rms_px < noisy < 0.5
    both = jang.testbed("I.1", duration=2.0, image_noise=2.0, blur_px=1.0, time_offset_s=1 / 60)
    np.testing.assert_allclose(table[table["sources"] == "all"]["rms_m"], both.rms, rtol=1e-12)
    lines = jang.error_budget_lines(table)
    assert any(line.startswith("the thesis (measured") for line in lines)


@pytest.mark.slow
def test_testbed_studies_write_the_error_budget(tmp_path, monkeypatch):
    """`visjax testbed`'s studies run the error budget for the sets of `BUDGET_SETS` they
    are given, print it beside the thesis' error and write `error_budget.parquet`, its CSV
    and its figure (the budget cut to one source, so that the test stays short)."""
    import pandas as pd

    from visjax.io import TABLES, write_outputs

    full = jang.testbed_error_budget

    def short(sets, **kw):
        assert list(sets) == ["I.1"]  # I.2 is not a budget set
        return full(sets, sources=["encoders"], other_readings=False, **kw)

    monkeypatch.setattr(jang, "testbed_error_budget", short)
    lines = jang.testbed_studies(
        {}, ["I.1", "I.2"], "cm", 2.0, 0, write=lambda o: write_outputs(o, tmp_path)
    )
    assert "error budget, set I.1: RMS over the second half (mm)" in lines
    assert any(line.startswith("encoders") for line in lines)
    table = pd.read_parquet(tmp_path / "error_budget.parquet")
    assert list(table.columns) == list(TABLES["testbed/error_budget.parquet"])  # documented
    assert list(table["sources"].unique()) == ["none", "encoders"] and len(table) == 6
    assert table["result"].eq("successful").all() and table["rms_m"].notna().all()
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "error_budget.csv"), table)
    assert (tmp_path / "error_budget.png").stat().st_size > 0
