"""ROS bags in (`visjax.io.read_bag`): ROS 1 and ROS 2 (sqlite3 and MCAP) bags written by
`rosbags`' own writers read back to the same recording; the body's velocity expressed in
the camera frame through /tf_static or a given pose, against finite differences of the
camera's path; one line for each thing wrong with a bag."""

import sys

import numpy as np
import pytest

from tests.bag_writer import write_bag
from visjax import io
from visjax.cli import main
from visjax.frontend import (
    Plane,
    fiducial_marker,
    import_bag,
    project_points,
    render_planes,
    track_tags,
)
from visjax.io import DataFormatError
from visjax.kinematics import TwoLinkArm

pytest.importorskip("rosbags")

K = np.array([[300.0, 0.0, 32.0], [0.0, 300.0, 24.0], [0.0, 0.0, 1.0]])
D = [-0.1, 0.01, 1e-3, 0.0, 0.0]
FRAMES = np.random.default_rng(0).integers(0, 256, (5, 48, 64), dtype=np.uint8)
T0 = 1_700_000_000_123_456_789  # ns: a real epoch, read exactly
STAMPS = T0 + np.arange(5) * 33_333_333
V_STAMPS = T0 - 5_000_000 + np.arange(12) * 16_666_667  # from before the first frame
VELOCITY = np.c_[0.1 * np.ones(12), np.zeros((12, 3)), 0.05 * np.ones(12), 0.2 * np.ones(12)]
TOPICS = {"image_topic": "/camera/image", "camera_info_topic": "/camera/camera_info"}


def _read(path, **kw):
    return io.read_bag(path, **TOPICS, **kw)


@pytest.mark.parametrize(
    "ros, storage, encoding",
    [("1", None, "mono8"), ("2", "sqlite3", "rgb8"), ("2", "mcap", "mono8")],
)
def test_ros1_and_ros2_bags_read_the_same_recording(tmp_path, ros, storage, encoding):
    path = tmp_path / ("run.bag" if ros == "1" else "run")
    write_bag(path, ros, FRAMES, STAMPS, K, D, velocity=VELOCITY, stamps_velocity_ns=V_STAMPS,
              encoding=encoding, storage=storage or "sqlite3")  # fmt: skip
    rec = _read(path, twist_topic="/body/velocity")
    np.testing.assert_array_equal(rec.frames, FRAMES)  # grey, exactly (rgb8: equal channels)
    np.testing.assert_array_equal(rec.t, (STAMPS - T0) / 1e9)
    assert rec.start_ns == T0 and rec.camera_frame == "camera"
    np.testing.assert_array_equal(rec.A, K)
    np.testing.assert_array_equal(rec.dist, D)
    np.testing.assert_array_equal(rec.velocity_t, (V_STAMPS - T0) / 1e9)
    np.testing.assert_allclose(rec.velocity, VELOCITY)  # the camera's own frame: as written


def _rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    W = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * W + (1 - np.cos(angle)) * W @ W


def test_the_bodys_velocity_in_the_camera_frame_from_tf_static_or_a_given_pose(tmp_path):
    """A camera mounted on a body (turned 0.7 rad, 0.3 m off its origin): its velocity,
    from the body's twist, against central differences of the camera's own path in the
    world while the body moves with that twist (its frame the world's at t = 0)."""
    T_bc = np.eye(4)
    T_bc[:3, :3], T_bc[:3, 3] = _rotation([0.2, 1.0, 0.3], 0.7), [0.3, -0.1, 0.05]
    v_b = VELOCITY[0]
    h = 1e-6

    def camera_at(t):  # the camera's pose in the world: body motion, then the mounting
        R_b = _rotation(v_b[3:], np.linalg.norm(v_b[3:]) * t)
        return R_b @ T_bc[:3, :3], v_b[:3] * t + R_b @ T_bc[:3, 3]  # (v_b small: first order)

    (R_p, c_p), (R_m, c_m) = camera_at(h), camera_at(-h)
    R_c = T_bc[:3, :3]
    v_c = R_c.T @ ((c_p - c_m) / (2 * h))
    W = R_c.T @ ((R_p - R_m) / (2 * h))  # skew(omega_c) = R_c^T dR_c/dt at t = 0
    expected = np.r_[v_c, W[2, 1], W[0, 2], W[1, 0]]

    path = tmp_path / "mounted"  # ROS 2: /tf_static's type
    write_bag(path, "2", FRAMES, STAMPS, K, velocity=VELOCITY, stamps_velocity_ns=V_STAMPS,
              body_frame="base_link", camera_from_body=T_bc)  # fmt: skip
    rec = _read(path, twist_topic="/body/velocity")
    np.testing.assert_allclose(rec.velocity[0], expected, atol=1e-8)
    assert rec.dist is None  # no distortion coefficients: a pinhole
    # without /tf_static: the pose given; neither: one line asking for it
    bare = tmp_path / "bare.bag"
    write_bag(bare, "1", FRAMES, STAMPS, K, velocity=VELOCITY, stamps_velocity_ns=V_STAMPS,
              velocity_kind="odometry", body_frame="base_link")  # fmt: skip
    q = np.r_[np.sin(0.35) * np.array([0.2, 1.0, 0.3]) / np.linalg.norm([0.2, 1.0, 0.3]),
              np.cos(0.35)]  # fmt: skip
    pose = " ".join(str(x) for x in [*T_bc[:3, 3], *q])
    given = _read(bare, odometry_topic="/body/velocity", camera_from_body=pose)
    np.testing.assert_allclose(given.velocity, rec.velocity, atol=1e-12)
    with pytest.raises(DataFormatError, match="--camera-from-body"):
        _read(bare, odometry_topic="/body/velocity")


def _bad_bag(tmp_path, what):
    """A ROS 1 bag whose image headers go backwards or repeat (received in order)."""
    headers = STAMPS.copy()
    if what == "backwards":
        headers[3] = headers[1]
    if what == "repeats":
        headers[2] = headers[1]
    path = tmp_path / f"{what}.bag"
    write_bag(path, "1", FRAMES, STAMPS, K, velocity=VELOCITY, stamps_velocity_ns=V_STAMPS,
              image_header_ns=headers)  # fmt: skip
    return path


@pytest.mark.parametrize(
    "what, topics, says",
    [
        ("fine", {"image_topic": "/camera/imag"}, r"no topic '/camera/imag' \(did you mean"),
        ("fine", {"image_topic": "/body/velocity"}, "carries geometry_msgs/msg/TwistStamped"),
        ("backwards", {}, "message 3 goes backwards"),
        ("repeats", {}, "message 2 repeats"),
    ],
)
def test_each_thing_wrong_with_a_bag_is_one_line(tmp_path, what, topics, says):
    path = _bad_bag(tmp_path, what)
    with pytest.raises(DataFormatError, match=says):
        io.read_bag(path, **{**TOPICS, **topics})


def test_not_a_bag_and_the_command_lines_one_line(tmp_path, capsys):
    (tmp_path / "notes.bag").write_text("not a bag")
    with pytest.raises(DataFormatError, match="not a readable ROS bag"):
        _read(tmp_path / "notes.bag")
    path = _bad_bag(tmp_path, "fine")
    argv = ["import-bag", str(path), "--problem", "moving_point", "--image-topic", "/img",
            "--camera-info", "/camera/camera_info", "--twist", "/body/velocity",
            "--out", str(tmp_path / "point.npz")]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no topic '/img'" in err[0], err
    assert not (tmp_path / "point.npz").exists()


def test_without_rosbags_the_error_says_how_to_install_it(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)  # as if not installed
    with pytest.raises(ImportError, match=r"pip install 'visjax\[ros\]'"):
        _read(tmp_path / "any.bag")


def test_a_bag_of_a_tag_to_the_velocity_problems_file(tmp_path):
    """A plate with an AprilTag seen through a lens (the camera info's `D`): `import_bag`
    takes the tag's corners as the four features, its side as the known length and the
    lens' coefficients as `dist`, and the file loads undistorted."""
    K2 = np.array([[300.0, 0.0, 159.5], [0.0, 300.0, 119.5], [0.0, 0.0, 1.0]])
    tex, corners = fiducial_marker(2, cell=10, dictionary="36h11")
    frames = []
    for k in range(4):
        T = np.eye(4)
        T[:3, 3] = [-0.05 + 0.01 * k, -0.05, 0.6]
        frames.append(render_planes([Plane(tex, 0.001, T)], K2, np.eye(3), np.zeros(3),
                                    (240, 320), dist=np.array(D)))  # fmt: skip
    path = write_bag(tmp_path / "tag.bag", "1", np.stack(frames), STAMPS[:4], K2, D)
    side = 0.001 * float(corners[1, 0] - corners[0, 0])
    topics = {"image_topic": "/camera/image", "camera_info": "/camera/camera_info"}
    data = import_bag(path, "velocity", **topics, tags="36h11", camera={"tag": 2, "tag_size": side})
    assert data.pixels.shape == (4, 4, 2) and data.length == (0, 1, side)
    np.testing.assert_array_equal(data.dist, D)
    loaded = io.VelocityData.load(data.save(tmp_path / "plate.npz"))
    truth = [0.001 * (corners + 0.5) + [-0.05 + 0.01 * k, -0.05] for k in range(4)]
    ideal = np.stack([np.c_[c / 0.6 * 300 + [159.5, 119.5]] for c in truth])  # pinhole
    assert np.abs(loaded.pixels - ideal).max() < 0.5  # undistorted: the pinhole's pixels
    with pytest.raises(DataFormatError, match="the intrinsics and the distortion"):
        import_bag(path, "velocity", **topics, camera={"A": K2.tolist(), "tag": 2})


def test_a_two_link_arms_joint_states_give_its_end_links_twist(tmp_path):
    """A camera on a two-link planar arm's end link (the same frame): its twist from
    /joint_states (central differences of the angles) against central differences of the
    end link's pose from the forward kinematics, in the link's frame."""
    arm = TwoLinkArm(0.5, 0.4)
    t = np.arange(40) / 200.0
    q = np.c_[0.3 + 0.2 * t + 0.1 * t**2, 0.5 - 0.1 * t]
    stamps = T0 + np.rint(t * 1e9).astype(np.int64)
    path = write_bag(tmp_path / "arm.bag", "1", FRAMES, STAMPS, K, joints=q,
                     stamps_joints_ns=stamps)  # fmt: skip
    rec = _read(path, joint_states_topic="/joint_states", robot=arm,
                camera_from_body="0 0 0 0 0 0 1")  # fmt: skip
    k, h = 20, 1e-6

    def angles(tk):
        return np.array([0.3 + 0.2 * tk + 0.1 * tk**2, 0.5 - 0.1 * tk])

    v = (np.asarray(arm.forward(angles(t[k] + h))) - np.asarray(arm.forward(angles(t[k] - h)))) / (
        2 * h
    )
    theta = angles(t[k]).sum()
    R = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    expected = np.r_[R.T @ v, 0.0, 0.0, 0.0, 0.2 + 0.2 * t[k] - 0.1]
    np.testing.assert_allclose(rec.velocity[k], expected, atol=1e-6)  # q'' small: O(h^2)
    with pytest.raises(ValueError, match="needs its link lengths"):
        _read(path, joint_states_topic="/joint_states", robot="two_link")


def test_a_bag_of_a_moving_platform_to_the_static_points_file(tmp_path):
    """A camera mounted on a moving platform (/tf_static) sees two AprilTags: tag 0's
    corners known, tag 1's unknown. `import_bag` takes the platform's pose from the
    odometry, interpolated to the frames (here half way between its samples), and the
    nominal mounting from /tf_static; the corners are where the camera projects them."""
    K2 = np.array([[300.0, 0.0, 159.5], [0.0, 300.0, 119.5], [0.0, 0.0, 1.0]])
    mount = np.eye(4)
    mount[:3, :3], mount[:3, 3] = _rotation([1.0, 0.0, 0.0], 0.1), [0.05, 0.0, 0.0]

    def body(t):
        P = np.eye(4)
        P[:3, :3], P[:3, 3] = _rotation([0.0, 1.0, 0.0], 0.2 * t), [0.1 * t, 0.0, 0.0]
        return P

    tags, corners = [], []
    for i, x in enumerate((-0.16, 0.02)):
        tex, c = fiducial_marker(i, cell=12, dictionary="36h11")  # 10 cm at 1 m
        T = np.eye(4)
        T[:3, 3] = [x, -0.04, 1.0]
        tags.append(Plane(tex, 0.001, T))
        corners.append(tags[-1].world_points(c))
    t_frames = np.arange(4) / 10.0 + 0.025  # between the 20 Hz odometry samples
    frames = []
    for tk in t_frames:
        camera = body(tk) @ mount
        frames.append(render_planes(tags, K2, camera[:3, :3], camera[:3, 3], (240, 320)))
    t_odom = np.arange(12) / 20.0
    stamps = T0 + np.rint(t_frames * 1e9).astype(np.int64)
    path = write_bag(tmp_path / "platform", "2", np.stack(frames), stamps, K2,
                     velocity=np.zeros((12, 6)), velocity_kind="odometry", body_frame="base",
                     stamps_velocity_ns=T0 + np.rint(t_odom * 1e9).astype(np.int64),
                     poses=[body(tk) for tk in t_odom], camera_from_body=mount)  # fmt: skip
    constants = {"known": [0, 1, 2, 3], "unknown": [4, 5, 6, 7],
                 "known_features": corners[0].tolist()}  # fmt: skip
    topics = {"image_topic": "/camera/image", "camera_info": "/camera/camera_info"}
    data = import_bag(path, "static_points", **topics, odometry="/body/velocity", tags="36h11",
                      camera=constants)  # fmt: skip
    np.testing.assert_allclose(data.R_c_nominal, mount[:3, :3], atol=1e-12)
    np.testing.assert_allclose(data.x_c_nominal, mount[:3, 3], atol=1e-12)
    t_abs = data.t + t_frames[0]  # the file's times count from the first frame
    truth = np.stack([body(tk) for tk in t_abs])
    np.testing.assert_allclose(data.platform_x, truth[:, :3, 3], atol=1e-12)  # linear motion
    np.testing.assert_allclose(data.platform_R, truth[:, :3, :3], atol=1e-12)  # one axis
    np.testing.assert_array_equal(data.pixels, track_tags(np.stack(frames)).pixels)
    for k, tk in enumerate(t_frames):  # where the camera projects them (10 cm tags a metre
        camera = body(tk) @ mount  # away: their corners found to 0.6 px at most)
        seen = np.concatenate(
            [project_points(K2, camera[:3, :3], camera[:3, 3], c) for c in corners]
        )
        assert np.abs(data.pixels[k] - seen).max() < 1.0
