"""The input formats of `visjax.io`: every format round-trips exactly, the keys are the
documented ones, and a bad file is refused with a message naming the key."""

import numpy as np
import pytest

from visjax.io import (
    DataFormatError,
    MovingPointData,
    StaticPointsData,
    VelocityData,
    load_tracks_csv,
    save_tracks_csv,
)

RNG = np.random.default_rng(0)


def _rotations(n):
    q = RNG.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def _velocity(N=20, n=6):
    pixels = RNG.uniform(1, 479, (N, n, 2))
    pixels[3, 2] = np.nan  # a feature out of view
    return VelocityData(
        t=np.arange(N) * 1e-3,
        pixels=pixels,
        A=np.array([[800.0, 1.0, 320], [0, 810, 240], [0, 0, 1]]),
        R_star=_rotations(1)[0],
        s1=np.array([0.1, -0.1, 0.0]),
        known_length=np.array([0.0, 2.0, 0.25]),
        velocity=RNG.normal(size=(N, 6)),
    )


def _structure(N=20, M=70):
    return MovingPointData(
        t=np.arange(N) / 50.0,
        pixels=RNG.uniform(1, 479, (N, 2)),
        A=np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]]),
        camera_t=np.arange(M) / 200.0,
        camera_velocity=RNG.normal(size=(M, 6)),
        D=np.array([1.0, 0.0, 0.0]),
        position=RNG.normal(size=(N, 3)) + np.array([0.0, 0.0, 5.0]),  # in front
    )


def _euclidean(N=20, n=8, k=5):
    return StaticPointsData(
        t=np.arange(N) * 1e-3,
        pixels=RNG.uniform(1, 479, (N, n, 2)),
        platform_R=_rotations(N),
        platform_x=RNG.normal(size=(N, 3)),
        known_features=RNG.normal(size=(k, 3)),
        A_nominal=np.array([[900.0, 10, 500], [0, 900, 370], [0, 0, 1]]),
        R_c_nominal=_rotations(1)[0],
        x_c_nominal=np.array([0.05, 0.0, 0.1]),
        features=RNG.normal(size=(n - k, 3)),
    )


KEYS = {
    VelocityData: {"t", "pixels", "A", "R_star", "s1", "known_length", "velocity"},
    MovingPointData: {"t", "pixels", "A", "camera_t", "camera_velocity", "D", "position"},
    StaticPointsData: {
        "t",
        "pixels",
        "platform_R",
        "platform_x",
        "known_features",
        "A_nominal",
        "R_c_nominal",
        "x_c_nominal",
        "features",
    },
}


@pytest.mark.parametrize("make", [_velocity, _structure, _euclidean])
def test_round_trip_with_the_documented_keys(make, tmp_path):
    data = make()
    path = data.save(tmp_path / "d.npz")
    with np.load(path) as z:
        assert set(z.files) == KEYS[type(data)]
    back = type(data).load(path)
    for key in KEYS[type(data)]:
        np.testing.assert_array_equal(getattr(back, key), getattr(data, key))
    # truth keys are optional
    truth = {"velocity", "position", "features"} & KEYS[type(data)]
    for key in truth:
        setattr(data, key, None)
    data.save(tmp_path / "no_truth.npz")
    assert all(getattr(type(data).load(tmp_path / "no_truth.npz"), k) is None for k in truth)


@pytest.mark.parametrize(
    "make,change,message",
    [
        (_velocity, dict(pixels=np.zeros((20, 3, 2))), "at least 4"),
        (_velocity, dict(R_star=np.eye(3) * 2), "R_star"),
        (_velocity, dict(known_length=np.array([0.0, 0.0, 1.0])), "two different"),
        (_velocity, dict(known_length=np.array([0.0, 1.0, -1.0])), "positive"),
        (_velocity, dict(t=np.zeros(20)), "increasing"),
        (_velocity, dict(velocity=np.zeros((19, 6))), "velocity"),
        (_structure, dict(D=np.zeros(3)), "`D`"),
        (_structure, dict(camera_velocity=np.zeros((5, 6))), "camera_velocity"),
        (_structure, dict(camera_t=np.arange(70) / 200.0 + 1.0), "first frame"),
        (_euclidean, dict(known_features=np.zeros((8, 3))), "known_features"),
        (_euclidean, dict(platform_R=np.zeros((20, 3, 3))), "platform_R"),
        (_euclidean, dict(x_c_nominal=np.zeros(2)), "x_c_nominal"),
    ],
)
def test_bad_data_is_refused_naming_the_key(make, change, message, tmp_path):
    data = make()
    arrays = {k: getattr(data, k) for k in KEYS[type(data)]}
    arrays.update(change)
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(DataFormatError, match=message):
        type(data).load(tmp_path / "bad.npz")


def test_missing_key_and_unreadable_file(tmp_path):
    arrays = {k: getattr(_velocity(), k) for k in KEYS[VelocityData] - {"A"}}
    np.savez(tmp_path / "x.npz", **arrays)
    with pytest.raises(DataFormatError, match="missing \\['A'\\]"):
        VelocityData.load(tmp_path / "x.npz")
    (tmp_path / "junk.npz").write_text("not a zip")
    with pytest.raises(DataFormatError, match="readable"):
        VelocityData.load(tmp_path / "junk.npz")


def test_pixel_tracks_csv_round_trip(tmp_path):
    data = _velocity()
    path = save_tracks_csv(tmp_path / "tracks.csv", data.t, data.pixels)
    t, pixels = load_tracks_csv(path)
    np.testing.assert_array_equal(t, data.t)
    np.testing.assert_array_equal(pixels, data.pixels)  # NaN where no row, exact floats
    lines = path.read_text().splitlines()
    assert lines[0] == "t,feature,u,v" and len(lines) == 1 + 20 * 6 - 1
    (tmp_path / "bad.csv").write_text("time,u,v\n0,1,2\n")
    with pytest.raises(DataFormatError, match="columns"):
        load_tracks_csv(tmp_path / "bad.csv")
