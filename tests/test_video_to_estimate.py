"""From a video to an estimate, as `docs/your-own-data.md` does it: a textured plate moving
before a fixed camera is rendered (30 Hz, 2 s), tracked (`visjax track --planar`), turned
into the velocity problem's data file with six coplanar tracks chosen (`visjax data`), and
run (`visjax run velocity --method batch`); the estimate over the second half is held
against the plate's known motion."""

import numpy as np
import pandas as pd
import pytest
import yaml

from visjax import io
from visjax.cli import main
from visjax.frontend import (
    Plane,
    fiducial_marker,
    project_points,
    render_planes,
    textured_table,
    write_video,
)

pytestmark = pytest.mark.slow  # rendering, tracking and two compiles: about 15 s

K = np.array([[300.0, 0.0, 159.5], [0.0, 300.0, 119.5], [0.0, 0.0, 1.0]])
FPS, FRAMES = 30.0, 61
AXES = ["v_x", "v_y", "v_z", "omega_x", "omega_y", "omega_z"]


def _rot(axis: int, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    i, j = [k for k in range(3) if k != axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def _pose(t):
    """The plate's frame in the camera frame: turning about the optical axis at 0.1 rad/s
    (tilted 0.25 rad about x), its origin moving at (0.05, 0.02 cos t, 0.05) m/s."""
    x = np.array([-0.2 + 0.05 * t, -0.15 + 0.02 * np.sin(t), 0.9 + 0.05 * t])
    return _rot(2, 0.1 * t) @ _rot(0, 0.25), x


def _velocity(t):
    return np.array([0.05, 0.02 * np.cos(t), 0.05, 0.0, 0.0, 0.1])


def _klt_camera(pixels):
    """The camera file of six coplanar KLT tracks, with what the user knows: the
    intrinsics, the plate's orientation at the first frame, and one length on it (here the
    first two chosen features', from the rendering's truth); and the tracks chosen."""
    chosen = io.choose_coplanar(pixels, 6)
    R0, x0 = _pose(0.0)
    rays = np.c_[pixels[0, chosen], np.ones(6)] @ np.linalg.inv(K).T
    points = rays * ((x0 @ R0[:, 2]) / (rays @ R0[:, 2]))[:, None]  # on the plate
    camera = {
        "fx": 300.0, "fy": 300.0, "cx": 159.5, "cy": 119.5, "coplanar": 6,
        "known_length": [0, 1, float(np.linalg.norm(points[0] - points[1]))],
        "R_star": R0.tolist(), "s1": ((points[0] - x0) @ R0).tolist(),
    }  # fmt: skip
    return camera, chosen


def test_a_rendered_video_to_the_velocity_of_the_plate(tmp_path, capsys):
    texture = textured_table((160, 200), seed=3)  # 0.4 m x 0.32 m at 2 mm a pixel
    frames = []
    for k in range(FRAMES):
        R, x = _pose(k / FPS)
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, x
        frames.append(
            render_planes([Plane(texture, 0.002, T)], K, np.eye(3), np.zeros(3), (240, 320))
        )
    write_video(tmp_path / "plate.npz", np.stack(frames), FPS)
    tracks = tmp_path / "tracks.npz"
    argv = ["track", str(tmp_path / "plate.npz"), "--planar", "--max-features", "40"]
    assert main([*argv, "--quiet", "--out", str(tracks)]) == 0

    t, pixels = io.read_tracks(tracks)
    camera, chosen = _klt_camera(pixels)
    (tmp_path / "camera.yaml").write_text(yaml.safe_dump(camera))
    data = tmp_path / "data.npz"
    argv = ["data", "velocity", "--tracks", str(tracks), "--camera", str(tmp_path / "camera.yaml")]
    assert main([*argv, "--out", str(data)]) == 0
    np.testing.assert_array_equal(io.VelocityData.load(data).pixels, pixels[:, chosen])

    out = tmp_path / "run"
    argv = ["run", "velocity", "--data", str(data), "--method", "batch", "--quiet"]
    assert main([*argv, "--out", str(out)]) == 0
    table = pd.read_parquet(out / "estimates.parquet")
    half = table[table["t"] >= 1.0]
    error = half[AXES].to_numpy() - np.array([_velocity(tk) for tk in half["t"]])
    rms = np.sqrt(np.mean(error**2, axis=0))
    assert np.all(rms[:3] < 0.01), rms  # m/s, of 0.05
    assert np.all(rms[3:] < 0.03), rms  # rad/s, of 0.1


def _plate(t, texture) -> Plane:
    R, x = _pose(t)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, x
    return Plane(texture, 0.002, T)


def _rms_of_run(tmp_path, name, tracks, camera) -> np.ndarray:
    """`visjax data velocity` then `visjax run velocity --method batch`: the RMS error of
    the estimate over the second half, per axis (m/s, rad/s)."""
    (tmp_path / f"{name}.yaml").write_text(yaml.safe_dump(camera))
    data = tmp_path / f"{name}_data.npz"
    argv = ["data", "velocity", "--tracks", str(tracks), "--camera", str(tmp_path / f"{name}.yaml")]
    assert main([*argv, "--quiet", "--out", str(data)]) == 0
    out = tmp_path / f"{name}_run"
    argv = ["run", "velocity", "--data", str(data), "--method", "batch", "--quiet"]
    assert main([*argv, "--out", str(out)]) == 0
    half = pd.read_parquet(out / "estimates.parquet").query("t >= 1.0")
    error = half[AXES].to_numpy() - np.array([_velocity(tk) for tk in half["t"]])
    return np.sqrt(np.mean(error**2, axis=0))


def test_an_apriltag_on_the_plate_against_klt_on_the_same_frames(tmp_path, capsys):
    """An AprilTag (36h11, id 0, 16 cm) drawn on the 40 cm plate: `visjax track --tags
    36h11` finds its corners in every frame within 0.5 px of their projections (measured
    0.25 px RMS, 0.35 px at most), and its four corners with the tag's side as the known
    length (`tag`, `tag_size`) give the plate's velocity over the second half to 0.6-2.2
    cm/s (of 5 cm/s) and 0.01-0.06 rad/s (of 0.1): four corners 16 cm apart, detected anew
    in each frame, against six KLT tracks spread over the plate on the same frames, which
    give 2.4-3.8 mm/s and 0.007-0.010 rad/s. Bounds: 1.5 times those measured."""
    texture = textured_table((160, 200), seed=3)
    tag, corners = fiducial_marker(0, cell=10, dictionary="36h11")  # 10 cells of 2 cm
    top, left = 30, 90
    texture[top : top + tag.shape[0], left : left + tag.shape[1]] = tag
    corners = corners + [left, top]  # texture coordinates (x_t, y_t) on the plate
    frames = [
        render_planes([_plate(k / FPS, texture)], K, np.eye(3), np.zeros(3), (240, 320))
        for k in range(FRAMES)
    ]
    write_video(tmp_path / "plate.npz", np.stack(frames), FPS)

    tags = tmp_path / "tags.npz"
    assert main(["track", str(tmp_path / "plate.npz"), "--tags", "36h11", "--out", str(tags)]) == 0
    assert "36h11 tags found: 0 (100% of frames)" in capsys.readouterr().out
    t, pixels = io.read_tracks(tags)
    truth = np.stack(
        [project_points(K, np.eye(3), np.zeros(3), _plate(tk, texture).world_points(corners))
         for tk in t]
    )  # fmt: skip
    corner_error = np.linalg.norm(pixels[:, :4] - truth, axis=-1)
    assert corner_error.max() < 0.5, corner_error.max()
    R0, x0 = _pose(0.0)
    side = 0.002 * float(np.linalg.norm(corners[1] - corners[0]))
    in_plate = np.r_[0.002 * (corners[0] + 0.5), 0.0]  # corner 0 in the plate's frame
    camera = {
        "fx": 300.0, "fy": 300.0, "cx": 159.5, "cy": 119.5, "tag": 0, "tag_size": side,
        "R_star": R0.tolist(), "s1": in_plate.tolist(),
    }  # fmt: skip
    rms_tag = _rms_of_run(tmp_path, "tag", tags, camera)

    klt = tmp_path / "klt.npz"
    argv = ["track", str(tmp_path / "plate.npz"), "--planar", "--max-features", "40"]
    assert main([*argv, "--quiet", "--out", str(klt)]) == 0
    rms_klt = _rms_of_run(tmp_path, "klt", klt, _klt_camera(io.read_tracks(klt)[1])[0])
    rms_px = np.sqrt(np.mean(corner_error**2))
    print(f"corner error max {corner_error.max():.3f} px, RMS {rms_px:.3f} px")
    print("velocity RMS, tag:", np.round(rms_tag, 4), "KLT:", np.round(rms_klt, 4))
    assert np.all(rms_tag[:3] < 0.033) and np.all(rms_tag[3:] < 0.09), rms_tag
    assert np.all(rms_klt[:3] < 0.006) and np.all(rms_klt[3:] < 0.015), rms_klt
