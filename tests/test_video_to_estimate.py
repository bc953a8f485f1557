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
from visjax.frontend import Plane, render_planes, textured_table, write_video

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

    # what the user knows: the intrinsics, the plate's orientation at the first frame, and
    # one length on it (here the first two chosen features', from the rendering's truth)
    t, pixels = io.read_tracks(tracks)
    chosen = io.choose_coplanar(pixels, 6)
    R0, x0 = _pose(0.0)
    rays = np.c_[pixels[0, chosen], np.ones(6)] @ np.linalg.inv(K).T
    points = rays * ((x0 @ R0[:, 2]) / (rays @ R0[:, 2]))[:, None]  # on the plate
    camera = {
        "fx": 300.0, "fy": 300.0, "cx": 159.5, "cy": 119.5, "coplanar": 6,
        "known_length": [0, 1, float(np.linalg.norm(points[0] - points[1]))],
        "R_star": R0.tolist(), "s1": ((points[0] - x0) @ R0).tolist(),
    }  # fmt: skip
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
