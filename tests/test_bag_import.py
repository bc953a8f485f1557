"""A ROS bag to an estimate: the testbed twin of Jang's thesis (set I.1, its marker an
AprilTag) written as ROS 1 and ROS 2 bags with `rosbags`' writers (the rendered frames, the
camera info, the camera's velocity from the encoders), then `visjax import-bag` and
`visjax run moving_point --data`: the data file equals the direct path's (the same frames
tracked, the same constants), and the run succeeds."""

import numpy as np
import pytest
import yaml

from tests.bag_writer import write_bag
from visjax import io
from visjax.cli import main
from visjax.frontend import track_tags
from visjax.papers import jang

pytestmark = pytest.mark.slow  # the twin's rendering and tracking, two bags: about 20 s
pytest.importorskip("rosbags")

T0 = 1_700_000_000_000_000_000


@pytest.fixture(scope="module")
def twin():
    return jang.testbed("I.1", duration=2.0, marker="36h11", keep_frames=True)


@pytest.mark.parametrize("ros", ["1", "2"])
def test_a_bag_of_the_twin_imports_to_the_direct_paths_file_and_runs(twin, ros, tmp_path):
    stamps = T0 + np.rint(np.asarray(twin.frame_ts) * 1e9).astype(np.int64)
    K = np.asarray(jang.KC_REFINED)
    bag = tmp_path / ("twin.bag" if ros == "1" else "twin")
    write_bag(bag, ros, twin.frames, stamps, K, velocity=twin.velocity_measured,
              stamps_velocity_ns=stamps)  # fmt: skip
    camera = {"feature": 0, "D": [1.0, 0.0, 0.0]}  # tag 0's corner 0; the marker is static
    (tmp_path / "point.yaml").write_text(yaml.safe_dump(camera))
    out = tmp_path / "point.npz"
    argv = ["import-bag", str(bag), "--problem", "moving_point", "--image-topic",
            "/camera/image", "--camera-info", "/camera/camera_info", "--twist",
            "/body/velocity", "--tags", "36h11", "--camera", str(tmp_path / "point.yaml"),
            "--quiet", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0

    # the direct path: the same frames tracked, the same constants
    tracks = track_tags(twin.frames, "36h11", fps=30.0)
    t = (stamps - T0) / 1e9
    velocity = {"t": t, "velocity": twin.velocity_measured}
    constants = {**camera, "A": K.tolist(), "camera_velocity": velocity}
    direct = io.data_from_tracks("moving_point", (t, tracks.pixels), constants)
    imported = io.MovingPointData.load(out)
    for key, value in vars(direct).items():
        mine = getattr(imported, key)
        assert (mine is None) == (value is None), key
        if value is not None:
            np.testing.assert_array_equal(mine, value, err_msg=key)
    assert main(["run", "moving_point", "--data", str(out), "--quiet"]) == 0


def test_the_pumas_joint_states_give_the_cameras_velocity(twin, tmp_path):
    """The twin's PUMA joint angles at 100 Hz as /joint_states: with the camera 10 cm out
    along S6 (`--camera-from-body`), their central differences through the Jacobian (4.4)
    and (4.5) give the camera's exact velocity to 1e-4 (m/s, rad/s) at the joint sample
    after each frame (set I.1's velocities are constant)."""
    every = 10  # 1 kHz -> 100 Hz
    ts = np.asarray(twin.ts)[::every]
    stamps = T0 + np.rint(ts * 1e9).astype(np.int64)
    frame_stamps = T0 + np.rint(np.asarray(twin.frame_ts) * 1e9).astype(np.int64)
    bag = tmp_path / "joints"
    write_bag(bag, "2", twin.frames[:3], frame_stamps[:3], np.asarray(jang.KC_REFINED),
              joints=np.asarray(twin.q_puma)[::every], stamps_joints_ns=stamps)  # fmt: skip
    rec = io.read_bag(bag, image_topic="/camera/image", camera_info_topic="/camera/camera_info",
                      joint_states_topic="/joint_states", robot="puma560",
                      camera_from_body="0 0 0.1 0 0 0 1")  # fmt: skip
    inner = slice(1, -1)  # central differences inside the record
    at = np.searchsorted(rec.velocity_t[inner], np.asarray(twin.frame_ts)[5:-5])
    exact = np.asarray(twin.velocity_true)[5:-5]
    np.testing.assert_allclose(rec.velocity[inner][at], exact, atol=1e-4)
