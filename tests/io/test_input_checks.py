"""The loaders of `visjax.io` refuse the plausible mistakes in a user's file with one
`DataFormatError` that says what is wrong, never silent garbage and never a traceback:
transposed intrinsics, times not in seconds, misspelt keys, object and complex arrays, an
archive too large once inflated, a corrupt file, a feature seen too rarely; and the data
classes report the fraction of frames with a feature missing."""

import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from visjax.io import (
    MAX_DROPPED_FRACTION,
    MIN_OBSERVATIONS,
    DataFormatError,
    MovingPointData,
    StaticPointsData,
    VelocityData,
    load_tracks_csv,
    read_npz,
    save_tracks_csv,
)

ROOT = Path(__file__).resolve().parents[2]
A = np.array([[800.0, 0.5, 320.0], [0.0, 810.0, 240.0], [0.0, 0.0, 1.0]])


def _rotation(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _velocity(N=12, n=5):
    rng = np.random.default_rng(0)
    return VelocityData(
        t=np.arange(N) / 30.0,
        pixels=rng.uniform(1, 479, (N, n, 2)),
        A=A.copy(),
        R_star=_rotation(0.3),
        s1=np.array([0.1, -0.1, 0.0]),
        known_length=np.array([0.0, 2.0, 0.25]),
    )


def _structure(N=12, M=40):
    rng = np.random.default_rng(1)
    return MovingPointData(
        t=np.arange(N) / 30.0,
        pixels=rng.uniform(1, 479, (N, 2)),
        A=A.copy(),
        camera_t=np.arange(M) / 100.0,
        camera_velocity=rng.normal(size=(M, 6)),
        D=np.array([1.0, 0.0, 0.0]),
    )


def _euclidean(N=12, n=6, k=4):
    rng = np.random.default_rng(2)
    return StaticPointsData(
        t=np.arange(N) / 30.0,
        pixels=rng.uniform(1, 479, (N, n, 2)),
        platform_R=np.stack([_rotation(0.01 * i) for i in range(N)]),
        platform_x=rng.normal(size=(N, 3)),
        known_features=rng.normal(size=(k, 3)),
        A_nominal=A.copy(),
        R_c_nominal=_rotation(-0.2),
        x_c_nominal=np.array([0.05, 0.0, 0.1]),
    )


def _arrays(data):
    return {k: v for k, v in vars(data).items() if v is not None}


def _saved(tmp_path, data, **change):
    """The data's arrays with some changed (a value of `None` drops the key), written as
    an `.npz` with `np.savez` (no validation on the way)."""
    arrays = {**_arrays(data), **change}
    path = tmp_path / "data.npz"
    np.savez(path, **{k: v for k, v in arrays.items() if v is not None})
    return path


def _refused(path, cls, *words):
    with pytest.raises(DataFormatError) as info:
        cls.load(path)
    message = str(info.value)
    assert "\n" not in message and str(path) in message, message
    for word in words:
        assert word in message, (word, message)
    return message


def test_the_valid_files_load(tmp_path):
    for make in (_velocity, _structure, _euclidean):
        data = make()
        back = type(data).load(data.save(tmp_path / "ok.npz"))
        np.testing.assert_array_equal(back.pixels, data.pixels)


# 1. intrinsics


def test_transposed_intrinsics_are_named(tmp_path):
    _refused(_saved(tmp_path, _velocity(), A=A.T), VelocityData, "`A` looks transposed", "MATLAB")
    path = _saved(tmp_path, _euclidean(), A_nominal=A.T)
    _refused(path, StaticPointsData, "`A_nominal` looks transposed", "(0, 0, 1)")


@pytest.mark.parametrize(
    "bad,words",
    [
        (A * 2.0, ["last row (0, 0, 1)", "(0, 0, 2)"]),
        (A + np.array([[0, 0, 0], [3.0, 0, 0], [0, 0, 0]]), ["upper-triangular", "A[1, 0] = 3"]),
        (np.diag([-800.0, 800.0, 1.0]), ["focal lengths", "positive", "-800"]),
    ],
)
def test_intrinsics_must_be_a_pinhole_camera(tmp_path, bad, words):
    _refused(_saved(tmp_path, _structure(), A=bad), MovingPointData, "`A`", *words)


# 2. time units


@pytest.mark.parametrize(
    "scale,unit", [(1e3, "milliseconds"), (1e6, "microseconds"), (1e9, "nanoseconds")]
)
def test_times_in_other_units_than_seconds_are_refused(tmp_path, scale, unit):
    data = _velocity()  # 30 Hz
    path = _saved(tmp_path, data, t=data.t * scale)
    _refused(path, VelocityData, "`t` does not look like seconds", f"in {unit} 30 Hz")
    path = _saved(tmp_path, _structure(), camera_t=np.arange(40) * 20.0)
    _refused(path, MovingPointData, "`camera_t` does not look", "in milliseconds 50 Hz")
    path = _saved(tmp_path, data, t=data.t / 3600)  # hours
    _refused(path, VelocityData, "`t`'s median interval", "likely not seconds")


def test_a_fast_log_in_milliseconds_needs_its_unit_declared(tmp_path):
    """A 1 kHz log in ms has intervals of 1, a plausible (slow) camera in seconds: refused
    until the file says which (`time_unit`); declared, it loads in seconds."""
    data = _velocity(N=40)
    ms = np.arange(40) * 1.0  # 1 kHz in milliseconds
    path = _saved(tmp_path, data, t=ms)
    message = _refused(path, VelocityData, "`t` does not look like seconds", "1 Hz in seconds")
    assert "in milliseconds 1 kHz" in message and 'time_unit="s"' in message
    loaded = VelocityData.load(_saved(tmp_path, data, t=ms, time_unit=np.asarray("ms")))
    np.testing.assert_allclose(loaded.t, ms * 1e-3, rtol=1e-15)
    assert loaded.time_unit == "s"
    # a genuinely slow camera (1 Hz in seconds) loads once declared
    slow = VelocityData.load(_saved(tmp_path, data, t=ms, time_unit=np.asarray("s")))
    np.testing.assert_array_equal(slow.t, ms)
    # a ROS log: int64 nanoseconds since the epoch, 30 Hz
    stamps = 1_717_000_000_000_000_000 + np.arange(40, dtype=np.int64) * 33_333_333
    ros = VelocityData.load(_saved(tmp_path, data, t=stamps, time_unit=np.asarray("ns")))
    np.testing.assert_allclose(ros.t, np.arange(40) * 0.033333333, rtol=1e-12)
    # uint64 nanoseconds near the type's limit: counted from the first, exactly
    top = np.iinfo(np.uint64).max - np.arange(40, dtype=np.uint64)[::-1] * np.uint64(33_333_333)
    near = VelocityData.load(_saved(tmp_path, data, t=top, time_unit=np.asarray("ns")))
    np.testing.assert_allclose(near.t, np.arange(40) * 0.033333333, rtol=1e-12)
    wide = np.array([0, 2**63 + 10] + [2**63 + 11 + i for i in range(38)], dtype=np.uint64)
    _refused(_saved(tmp_path, data, t=wide, time_unit=np.asarray("ns")), VelocityData, "`t`")
    # a structure file converts both of its clocks
    st = _structure()
    path = _saved(
        tmp_path, st, t=st.t * 1e3, camera_t=st.camera_t * 1e3, time_unit=np.asarray("ms")
    )
    loaded = MovingPointData.load(path)
    np.testing.assert_allclose(loaded.camera_t, st.camera_t, rtol=1e-12)
    np.testing.assert_allclose(loaded.t, st.t, rtol=1e-12)
    # beyond MAX_INTERVAL_S even a declaration does not help; an unknown unit is named
    _refused(_saved(tmp_path, data, t=ms * 20, time_unit=np.asarray("s")), VelocityData, "0.05 Hz")
    _refused(_saved(tmp_path, data, time_unit=np.asarray("min")), VelocityData, "`time_unit`")
    data.time_unit = "ms"  # in memory, times are seconds
    with pytest.raises(DataFormatError, match="in memory, times are seconds"):
        data.validate()
    # CSV tracks declare it as an argument
    csv = tmp_path / "tracks.csv"
    csv.write_text("t,feature,u,v\n0,0,1,2\n1,0,3,4\n2,0,5,6\n")
    with pytest.raises(DataFormatError, match="in milliseconds 1 kHz"):
        load_tracks_csv(csv)
    t, _ = load_tracks_csv(csv, time_unit="ms")
    np.testing.assert_allclose(t, [0.0, 1e-3, 2e-3])


def test_dates_and_durations_are_refused(tmp_path):
    data = _velocity()
    stamps = np.datetime64("2024-05-01T12:00:00") + (data.t * 1e9).astype("timedelta64[ns]")
    _refused(_saved(tmp_path, data, t=stamps), VelocityData, "`t` holds dates (datetime64)")
    durations = stamps - stamps[0]
    _refused(_saved(tmp_path, data, t=durations), VelocityData, "`t` holds durations")
    data.t = durations  # in Python too: `save` validates
    with pytest.raises(DataFormatError, match="timedelta64"):
        data.save(tmp_path / "again.npz")


# 3. unknown keys


def test_a_misspelt_key_is_named_with_the_closest_valid_one(tmp_path):
    data = _velocity()
    path = _saved(tmp_path, data, pixels=None, pixel=data.pixels)
    _refused(path, VelocityData, "unknown key `pixel` (did you mean 'pixels'?)")
    path = _saved(tmp_path, _structure(), camera_vel=np.zeros((40, 6)), notes=np.zeros(1))
    message = _refused(path, MovingPointData, "`camera_vel` (did you mean 'camera_velocity'?)")
    assert "`notes`;" in message  # no close match: named alone, then the valid keys


# 4. object and complex arrays


def test_object_and_complex_arrays_are_refused_naming_the_key(tmp_path):
    data = _euclidean()
    objects = np.empty(3, dtype=object)
    objects[:] = [1, "a", None]
    path = _saved(tmp_path, data, x_c_nominal=objects)
    message = _refused(path, StaticPointsData, "`x_c_nominal` holds Python objects")
    assert "pickle" not in message
    path = _saved(tmp_path, data, pixels=data.pixels * (1 + 1j))
    _refused(path, StaticPointsData, "`pixels` is complex: its imaginary part would be lost")


# 5. archive sizes


def test_an_archive_that_would_inflate_past_the_limit_is_refused_unread(tmp_path, monkeypatch):
    path = tmp_path / "large.npz"
    np.savez_compressed(path, pixels=np.zeros(300 * 1024**2, np.uint8))
    assert path.stat().st_size < 2 * 1024**2  # a small file...
    monkeypatch.setenv("VISJAX_MAX_DATA_BYTES", str(100 * 1024**2))  # ...inflating to 300 MiB

    def no_reading(*args, **kwargs):
        raise AssertionError("an array was read")

    monkeypatch.setattr("numpy.lib.format.read_array", no_reading)
    for load in (VelocityData.load, read_npz):
        with pytest.raises(DataFormatError) as info:
            load(path)
        assert "would take 300 MiB (limit 100 MiB" in str(info.value)
        assert "VISJAX_MAX_DATA_BYTES" in str(info.value)
    monkeypatch.setenv("VISJAX_MAX_DATA_BYTES", "lots")
    with pytest.raises(DataFormatError, match="positive number of bytes"):
        read_npz(path)


# 6. corrupt files


def _corrupt_files(tmp_path) -> dict[str, Path]:
    good = _velocity().save(tmp_path / "good.npz")
    raw = good.read_bytes()
    files = {"empty": b"", "truncated": raw[: len(raw) // 2], "text": b"t,feature,u,v\n0,0,1,2\n"}
    damaged = bytearray(raw)
    damaged[60:200] = b"\xff" * 140  # the first member's .npy header
    files["damaged"] = bytes(damaged)
    paths = {}
    for name, content in files.items():
        paths[name] = tmp_path / f"{name}.npz"
        paths[name].write_bytes(content)
    np.save(tmp_path / "array.npy", np.zeros((3, 3)))
    paths["renamed npy"] = (tmp_path / "array.npy").rename(tmp_path / "renamed.npz")
    paths["not .npy members"] = tmp_path / "zip.npz"
    with zipfile.ZipFile(paths["not .npy members"], "w") as zf:
        zf.writestr("readme.txt", "hello")
    return paths


WHY = {
    "empty": "the file is empty",
    "truncated": "truncated or damaged zip",
    "text": "not a zip archive; pixel tracks in CSV load with visjax.io.load_tracks_csv",
    "damaged": "`t`:",
    "renamed npy": "a single .npy array",
    "not .npy members": "`readme.txt` is not a .npy array",
}


def test_corrupt_files_are_one_line(tmp_path):
    for name, path in _corrupt_files(tmp_path).items():
        for load in (VelocityData.load, StaticPointsData.load, read_npz):
            if name == "damaged" and load == StaticPointsData.load:
                continue  # its keys are not the format's: refused before any is read
            with pytest.raises(DataFormatError) as info:
                load(path)
            message = str(info.value)
            assert "not a readable .npz file" in message and WHY[name] in message, message
            assert "\n" not in message and "allow_pickle" not in message


@pytest.mark.parametrize(
    "content,words",
    [
        (b"", "empty"),
        (b"\x00\x9f\xff\xfe binary", "not UTF-8"),
        (b"t,feature,u,v\n0,0,1,2\n0.1,0,1\n", "line 3 has 3 values"),
        (b"t,feature,u,v\n0,0,1,2\n0,0,3,4\n", "line 3 repeats feature 0"),
        (b"t,feature,u,v\n0,0,1,2\n33,0,3,4\n", "in milliseconds 30.3 Hz"),
        (b"t,feature,u,v\nnan,0,1,2\n", "finite"),
    ],
)
def test_corrupt_csv_is_one_line(tmp_path, content, words):
    path = tmp_path / "tracks.csv"
    path.write_bytes(content)
    with pytest.raises(DataFormatError, match="tracks.csv") as info:
        load_tracks_csv(path)
    assert words in str(info.value) and "\n" not in str(info.value)


def test_csv_with_a_byte_order_mark_loads(tmp_path):
    data = _velocity()
    path = save_tracks_csv(tmp_path / "tracks.csv", data.t, data.pixels)
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())  # as a spreadsheet saves it
    t, pixels = load_tracks_csv(path)
    np.testing.assert_array_equal(pixels, data.pixels)


# 7. coverage


def test_a_feature_seen_too_rarely_is_named_with_its_count(tmp_path):
    data = _euclidean()
    pixels = data.pixels.copy()
    pixels[1:, 5] = np.nan  # seen once: no depth
    message = _refused(_saved(tmp_path, data, pixels=pixels), StaticPointsData, "feature 5")
    assert f"seen in 1 image(s); each needs at least MIN_OBSERVATIONS = {MIN_OBSERVATIONS}" in (
        message
    )
    pixels[:, 4] = np.nan
    _refused(_saved(tmp_path, data, pixels=pixels), StaticPointsData, "feature 4", "never seen")
    data = _velocity()
    pixels = data.pixels.copy()
    pixels[1:, 3] = np.nan  # only in the reference frame: no motion
    _refused(_saved(tmp_path, data, pixels=pixels), VelocityData, "feature 3", "seen in 1")
    ref = data.pixels[0].copy()  # with a separate reference image, it counts
    pixels[:, 3] = np.nan
    pixels[4, 3] = 10.0
    VelocityData.load(_saved(tmp_path, data, pixels=pixels, reference_pixels=ref))
    data = _structure()
    pixels = data.pixels.copy()
    pixels[1:] = np.nan
    _refused(_saved(tmp_path, data, pixels=pixels), MovingPointData, "the point is seen in 1")


def test_dropped_fraction_and_coverage():
    assert 0 < MAX_DROPPED_FRACTION < 1
    data = _velocity(N=10)
    assert data.dropped_fraction() == 0.0 and data.coverage == 1.0
    data.pixels[2, 1, 0] = np.nan  # one coordinate is enough
    data.pixels[[2, 5, 7], 3] = np.nan
    assert data.dropped_fraction() == pytest.approx(0.3) and data.coverage == pytest.approx(0.7)
    data = _structure(N=8)
    data.pixels[[1, 2]] = np.nan
    assert data.dropped_fraction() == pytest.approx(0.25)
    data = _euclidean(N=10)
    data.pixels[:6, 0] = np.nan
    assert data.dropped_fraction() == pytest.approx(0.6)
    assert data.dropped_fraction() > MAX_DROPPED_FRACTION


# 8. the command line: one line, no traceback


def test_the_command_line_says_one_line(tmp_path, capsys):
    from visjax.cli import main

    paths = _corrupt_files(tmp_path)
    commands = [[c] for c in ("velocity", "moving_point", "static_points")]
    commands += [[v, p] for v in ("run", "compare", "sweep", "tune") for p in ("velocity",)]
    commands += [["run", "moving_point"], ["run", "static_points"]]
    for name in ("empty", "renamed npy", "damaged"):
        for argv in commands:
            code = main([*argv, "--data", str(paths[name]), "--quiet"])
            err = capsys.readouterr().err
            assert code == 2, (argv, name, code)
            assert err.startswith("visjax: error:") and err.count("\n") == 1, err
            # the damaged file is a velocity file: other formats name its keys first
            assert "not a readable .npz file" in err or (
                name == "damaged" and "unknown key" in err
            ), err
        # `track` reads a video from an .npz too
        out = tmp_path / "tracks.npz"
        try:
            code = main(["track", str(paths[name]), "--out", str(out), "--quiet"])
        except SystemExit as e:  # refused by the parser (e.g. an empty file)
            code = e.code
        err = capsys.readouterr().err
        assert code == 2, (name, code, err)
        assert err.startswith("visjax: error:") and err.count("\n") == 1, err
        assert not out.exists()

    proc = subprocess.run(  # a real process: nothing escapes as a traceback
        [sys.executable, "-m", "visjax.cli", "run", "velocity", "--quiet"]
        + ["--data", str(paths["truncated"]), "--out", str(tmp_path / "out")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1 and lines[0].startswith("visjax: error:"), proc.stderr
    assert "Traceback" not in proc.stderr and "truncated or damaged zip" in lines[0]
    assert not (tmp_path / "out").exists()


# physical plausibility (issue 44)


@pytest.mark.parametrize("length", [1e300, 1e-300, 250.0e3 * 1e3, 2e-5])
def test_a_known_length_outside_the_plausible_range_is_refused(tmp_path, length):
    data = _velocity()
    path = _saved(tmp_path, data, known_length=np.array([0.0, 2.0, length]))
    _refused(path, VelocityData, "`known_length[2]`", "outside the plausible", "0.0001 to 10000 m")
    ok = _saved(tmp_path, data, known_length=np.array([0.0, 2.0, 1e-3]))
    assert VelocityData.load(ok).length[2] == 1e-3


def test_pixels_outside_the_image_the_intrinsics_imply_are_refused(tmp_path):
    """Negative pixels (a mirrored export) or beyond twice the principal point, in each
    format, name the key and the span."""
    for data, cls in ((_velocity(), VelocityData), (_euclidean(), StaticPointsData)):
        mirrored = -np.asarray(data.pixels)
        _refused(_saved(tmp_path, data, pixels=mirrored), cls, "`pixels`'s u", "mirrored")
        shifted = np.asarray(data.pixels) + np.array([0.0, 300.0])
        _refused(_saved(tmp_path, data, pixels=shifted), cls, "`pixels`'s v", "0 to 480 px")
    st = _structure()
    _refused(_saved(tmp_path, st, pixels=-st.pixels), MovingPointData, "`pixels`'s u")
    v = _velocity()
    ref = np.asarray(v.pixels[0]) * np.array([1.0, -1.0])
    _refused(_saved(tmp_path, v, reference_pixels=ref), VelocityData, "`reference_pixels`'s v")


def test_integer_pixels_with_zero_marks_need_missing_value(tmp_path):
    """Integer pixels with lost features stored as (0, 0) (a common export) are refused;
    declared with `missing_value`, those observations load as missing (NaN) and count in
    `dropped_fraction`."""
    data = _velocity(N=20)
    pixels = np.round(np.asarray(data.pixels)).astype(np.int32)
    pixels[[3, 7], 2] = 0
    path = _saved(tmp_path, data, pixels=pixels, t=np.arange(20) / 30.0)
    _refused(path, VelocityData, "2 observation(s) at exactly (0, 0)", "missing_value")
    path = _saved(tmp_path, data, pixels=pixels, t=np.arange(20) / 30.0, missing_value=0)
    loaded = VelocityData.load(path)
    assert np.isnan(loaded.pixels[[3, 7], 2]).all() and np.isfinite(loaded.pixels[0]).all()
    assert loaded.dropped_fraction() == pytest.approx(2 / 20)
    path = _saved(tmp_path, data, missing_value=np.array([0, 0]))
    _refused(path, VelocityData, "`missing_value` must be one finite number")
    st = _euclidean()
    marks = np.asarray(st.pixels).copy()
    marks[5, 1] = 0.0
    _refused(_saved(tmp_path, st, pixels=marks), StaticPointsData, "exactly (0, 0)")


def test_a_moving_point_truth_behind_the_camera_is_refused(tmp_path):
    st = _structure()
    position = np.tile([0.1, 0.0, 2.0], (12, 1))
    assert MovingPointData.load(_saved(tmp_path, st, position=position)).position is not None
    position[4, 2] = -2.0  # another sign convention from frame 4
    path = _saved(tmp_path, st, position=position)
    _refused(path, MovingPointData, "`position`", "behind the camera at frame 4", "z = -2")


def test_a_csv_whose_feature_index_would_need_gibibytes_is_refused(tmp_path):
    """Issue 44: 2 rows with feature index 999999999 would ask for 29.8 GiB: refused
    before any allocation, naming the size."""
    csv = tmp_path / "tracks.csv"
    csv.write_text("t,feature,u,v\n0,0,1,2\n0.033,999999999,3,4\n")
    with pytest.raises(DataFormatError, match=r"999999999|1000000000 features.*GiB"):
        load_tracks_csv(csv)
