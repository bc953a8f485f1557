"""Pixel tracks plus a camera file to a problem's data file (`io.data_from_tracks`, the
command `visjax data`): the coplanar choice against a plane with off-plane tracks, each
problem's file from a YAML or JSON camera file, and every missing or malformed entry one
`DataFormatError` naming it. The chain from a rendered video to an estimate is
`tests/test_video_to_estimate.py` (slow)."""

import json

import numpy as np
import pytest
import yaml

from visjax import io
from visjax.geometry import distort_pixels
from visjax.io import DataFormatError

K = np.array([[300.0, 0.0, 160.0], [0.0, 300.0, 120.0], [0.0, 0.0, 1.0]])


def _plane_tracks(n_plane=8, n_off=3, frames=12, seed=0):
    """Tracks of `n_plane` points of the plane z = 1 m and `n_off` points off it (0.3-0.6
    m nearer), seen by a camera translating sideways (parallax separates them), with one
    plane track lost half way."""
    rng = np.random.default_rng(seed)
    plane = np.c_[rng.uniform(-0.25, 0.25, (n_plane, 2)), np.ones(n_plane)]
    off = np.c_[rng.uniform(-0.2, 0.2, (n_off, 2)), rng.uniform(0.4, 0.7, n_off)]
    points = np.r_[plane, off]
    t = np.arange(frames) / 30.0
    pixels = np.empty((frames, len(points), 2))
    for k, tk in enumerate(t):
        p = points - np.array([0.3 * tk, 0.1 * tk, 0.0])
        uvw = p @ K.T
        pixels[k] = uvw[:, :2] / uvw[:, 2:]
    pixels[frames // 2 :, 1] = np.nan  # a plane track lost half way
    return t, pixels


def test_coplanar_choice_keeps_the_plane_and_drops_the_rest():
    """`choose_coplanar`: tracks seen in every frame that follow one homography: never an
    off-plane track, never the lost one; spread (the farthest-point order); too few is
    one error naming the count."""
    t, pixels = _plane_tracks()
    chosen = io.choose_coplanar(pixels, 6)
    assert len(set(chosen)) == 6 and set(chosen) <= set(range(8)) - {1}
    assert sorted(io.choose_coplanar(pixels, 7)) == [0, 2, 3, 4, 5, 6, 7]
    with pytest.raises(DataFormatError, match="only 7 tracks follow one homography"):
        io.choose_coplanar(pixels, 8)
    with pytest.raises(DataFormatError, match="at least 4"):
        io.choose_coplanar(pixels, 3)


@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_velocity_file_from_tracks_and_a_camera_file(tmp_path, suffix):
    """The velocity problem's file: the chosen tracks (feature 1 first), the intrinsics
    from fx, fy, cx, cy, the known length as two reference pixels (the nearest chosen
    features), the defaults R* = I and s1 = 0; it loads as every data file does."""
    t, pixels = _plane_tracks()
    np.savez(tmp_path / "tracks.npz", t=t, pixels=pixels)
    chosen = io.choose_coplanar(pixels, 5)
    a, b = pixels[0, chosen[2]], pixels[0, chosen[4]]
    camera = {
        "fx": 300.0, "fy": 300.0, "cx": 160.0, "cy": 120.0, "coplanar": 5,
        "known_length": {"from_px": (a + 0.4).tolist(), "to_px": b.tolist(), "length_m": 0.2},
    }  # fmt: skip
    path = tmp_path / f"camera{suffix}"
    path.write_text(yaml.safe_dump(camera) if suffix == ".yaml" else json.dumps(camera))
    data = io.data_from_tracks("velocity", tmp_path / "tracks.npz", path)
    np.testing.assert_array_equal(data.pixels, pixels[:, chosen])
    np.testing.assert_array_equal(data.A, K)
    assert data.length == (2, 4, 0.2)
    np.testing.assert_array_equal(data.R_star, np.eye(3))
    np.testing.assert_array_equal(data.s1, np.zeros(3))
    saved = io.VelocityData.load(data.save(tmp_path / "plate.npz"))
    np.testing.assert_array_equal(saved.pixels, data.pixels)


LENS = np.array([-0.4, 0.1, 0.0, 0.0, 0.0])  # barrel distortion of a wide-angle lens


def test_distorted_tracks_choose_the_plane_undistorted_and_load_undistorted(tmp_path):
    """Through a lens (`dist`; up to 24 px from the pinhole's pixels here): the camera
    file's `dist` has the plane chosen among the undistorted tracks (those of a pinhole);
    the data file keeps the tracks as the lens saw them, with `dist`, and `load` gives the
    pinhole's pixels back."""
    t, ideal = _plane_tracks()
    raw = np.asarray(distort_pixels(ideal, K, LENS))
    assert np.nanmax(np.linalg.norm(raw - ideal, axis=-1)) > 20.0
    known = [0, 2, 0.2]
    camera = {"A": K.tolist(), "coplanar": 7, "known_length": known, "dist": LENS.tolist()}
    data = io.data_from_tracks("velocity", (t, raw), camera)
    assert sorted(io.choose_coplanar(ideal, 7)) == [0, 2, 3, 4, 5, 6, 7]
    chosen = io.choose_coplanar(ideal, 7)
    np.testing.assert_array_equal(data.pixels, raw[:, chosen])
    np.testing.assert_array_equal(data.dist, LENS)
    path = data.save(tmp_path / "plate.npz")
    loaded = io.VelocityData.load(path)
    assert loaded.dist is None
    np.testing.assert_allclose(loaded.pixels, ideal[:, chosen], atol=1e-9)
    kept = io.VelocityData.load(path, undistort=False)
    np.testing.assert_array_equal(kept.pixels, raw[:, chosen])
    np.testing.assert_array_equal(kept.dist, LENS)


@pytest.mark.parametrize(
    "dist, says",
    [
        (np.zeros(6), "4, 5, 8, 12 or 14 coefficients"),
        (np.array([np.nan, 0.0, 0.0, 0.0]), "`dist` must be finite"),
        # k1 = -1.2 maps no point beyond 0.35 (normalized): 105 px from the centre here
        (np.array([-1.2, 0.0, 0.0, 0.0]), "where the lens model `dist` maps no point"),
    ],
)
def test_a_file_with_bad_coefficients_is_refused_naming_them(tmp_path, dist, says):
    t, ideal = _plane_tracks()
    pixels = ideal[:, [0, 2, 3, 4]]
    pixels[:, 3] = [[160.0 + 110.0, 120.0]] * len(t)  # 110 px from the principal point
    data = io.VelocityData(
        t=t, pixels=pixels, A=K, R_star=np.eye(3), s1=np.zeros(3),
        known_length=np.array([0, 1, 0.2]), dist=dist,
    )  # fmt: skip
    np.savez(tmp_path / "plate.npz", **{k: v for k, v in vars(data).items() if v is not None})
    with pytest.raises(DataFormatError, match=says.replace("`", ".")):
        io.VelocityData.load(tmp_path / "plate.npz")


def test_a_tags_corners_with_its_side_as_the_known_length():
    """`tag: i` (the tracks of `visjax track --tags`: feature 4 i + c is corner c of tag i)
    takes tracks 4 i to 4 i + 3 as the four coplanar features, and `tag_size` their first
    side as the known length; a tag the tracks do not have is named."""
    t, pixels = _plane_tracks()  # 11 tracks: "tags" 0, 1 and the start of 2
    camera = {"A": K.tolist(), "tag": 1, "tag_size": 0.16}
    data = io.data_from_tracks("velocity", (t, pixels), camera)
    np.testing.assert_array_equal(data.pixels, pixels[:, 4:8])
    assert data.length == (0, 1, 0.16)
    with pytest.raises(DataFormatError, match="track 12 is not in the tracks file"):
        io.data_from_tracks("velocity", (t, pixels), {**camera, "tag": 3})
    with pytest.raises(DataFormatError, match="one of `features`, `coplanar` or `tag`"):
        io.data_from_tracks("velocity", (t, pixels), {**camera, "coplanar": 5})


def test_moving_point_and_static_points_files(tmp_path):
    """The moving point's file takes one track and the camera's velocity from a CSV
    (relative to the camera file); the static points' file the known and unknown tracks,
    in that order, and the platform's pose from an NPZ."""
    t, pixels = _plane_tracks()
    rows = ["t,v_x,v_y,v_z,omega_x,omega_y,omega_z"]
    rows += [f"{tk},-0.3,-0.1,0,0,0,0" for tk in t]
    (tmp_path / "velocity.csv").write_text("\n".join(rows) + "\n")
    camera = {"A": K.tolist(), "feature": 3, "camera_velocity": "velocity.csv", "D": [1, 0, 0]}
    camera["depth_guess"] = 2
    (tmp_path / "camera.json").write_text(json.dumps(camera))
    data = io.data_from_tracks("moving_point", (t, pixels), tmp_path / "camera.json")
    np.testing.assert_array_equal(data.pixels, pixels[:, 3])
    np.testing.assert_allclose(data.camera_velocity[:, :2], [[-0.3, -0.1]] * len(t))
    np.testing.assert_array_equal(data.D, [1.0, 0.0, 0.0])
    assert float(data.depth_guess) == 2.0

    n = len(t)
    np.savez(tmp_path / "platform.npz", platform_R=np.broadcast_to(np.eye(3), (n, 3, 3)),
             platform_x=np.c_[0.3 * t, 0.1 * t, np.zeros(n)])  # fmt: skip
    known = [[-0.2, -0.1, 1.0], [0.1, 0.2, 1.0], [0.2, -0.2, 1.0], [-0.1, 0.2, 1.0]]
    camera = {
        "A": K.tolist(), "known": [0, 2, 4, 5], "unknown": [6, 8], "known_features": known,
        "platform": "platform.npz", "R_c_nominal": np.eye(3).tolist(), "x_c_nominal": [0, 0, 0],
    }  # fmt: skip
    (tmp_path / "camera.yaml").write_text(yaml.safe_dump(camera))
    data = io.data_from_tracks("static_points", (t, pixels), tmp_path / "camera.yaml")
    np.testing.assert_array_equal(data.pixels, pixels[:, [0, 2, 4, 5, 6, 8]])
    assert data.n_known == 4


@pytest.mark.parametrize(
    "problem, camera, says",
    [
        ("velocity", {"fx": 300.0}, "fx, fy, cx, cy"),
        ("velocity", {"A": [[1, 2], [3, 4]]}, "`A` must have shape (3, 3)"),
        ("velocity", {"A": K.tolist()}, "`features`, `coplanar` or `tag`"),
        ("velocity", {"A": K.tolist(), "features": [0, 1, 2, 99]}, "track 99 is not"),
        ("velocity", {"A": K.tolist(), "features": [0, 2, 3]}, "at least 4"),
        ("velocity", {"A": K.tolist(), "coplanar": 5}, "needs `known_length`"),
        ("velocity", {"A": K.tolist(), "coplanar": "five"}, "whole number"),
        ("moving_point", {"A": K.tolist(), "feature": 1, "D": [1, 0, 0]}, "no `camera_velocity`"),
        ("moving_point", {"A": K.tolist(), "feature": 1, "camera_velocity": "v.csv"}, "no `D`"),
        ("moving_point", {"A": K.tolist(), "camera_velocity": "v.csv"}, "no `feature`"),
        ("static_points", {"A": K.tolist(), "known": []}, "non-empty list"),
        ("tracking", {"A": K.tolist()}, "no data file for problem 'tracking'"),
        ("velocity", {"A": K.tolist(), "coplanar": 5, "dist": [0.1, 0.2]}, "4, 5, 8, 12 or 14"),
        ("velocity", {"A": K.tolist(), "coplanar": 5, "dist": "barrel"}, "4, 5, 8, 12 or 14"),
    ],
)
def test_each_bad_camera_entry_is_one_error_naming_it(problem, camera, says):
    t, pixels = _plane_tracks()
    with pytest.raises(DataFormatError, match=says.replace("(", r"\(").replace(")", r"\)")):
        io.data_from_tracks(problem, (t, pixels), camera)


def test_unreadable_camera_and_tracks_files(tmp_path):
    (tmp_path / "bad.yaml").write_text("A: [1, 2\n")
    with pytest.raises(DataFormatError, match="not a readable camera file"):
        io.read_camera_file(tmp_path / "bad.yaml")
    (tmp_path / "list.json").write_text("[1, 2]")
    with pytest.raises(DataFormatError, match="one mapping"):
        io.read_camera_file(tmp_path / "list.json")
    np.savez(tmp_path / "t.npz", t=np.arange(3.0))
    with pytest.raises(DataFormatError, match="needs the keys t and pixels"):
        io.read_tracks(tmp_path / "t.npz")


def test_the_data_command_writes_a_file_that_loads(tmp_path, capsys):
    """`visjax data PROBLEM --tracks --camera --out`: the file written and the next
    command printed; a missing tracks file and a misspelt problem are one line, exit 2."""
    from visjax.cli import main

    t, pixels = _plane_tracks()
    io.save_tracks_csv(tmp_path / "tracks.csv", t, pixels)
    camera = {"A": K.tolist(), "features": [0, 2, 3, 4], "known_length": [0, 1, 0.3]}
    (tmp_path / "camera.yaml").write_text(yaml.safe_dump(camera))
    out = tmp_path / "plate.npz"
    argv = ["data", "velocity", "--tracks", str(tmp_path / "tracks.csv")]
    assert main([*argv, "--camera", str(tmp_path / "camera.yaml"), "--out", str(out)]) == 0
    assert f"next: visjax run velocity --data {out}" in capsys.readouterr().out
    np.testing.assert_allclose(io.VelocityData.load(out).pixels, pixels[:, [0, 2, 3, 4]])
    for bad, says in (
        (["data", "velocity", "--tracks", "nope.npz"], "--tracks 'nope.npz': no such file"),
        (["data", "velocty", "--tracks", "x"], "(did you mean 'velocity'?)"),
    ):
        with pytest.raises(SystemExit) as e:
            main([*bad, "--camera", str(tmp_path / "camera.yaml"), "--out", str(out)])
        assert e.value.code == 2 and says in capsys.readouterr().err
