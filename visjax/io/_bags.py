"""ROS bags in: the camera's images and calibration and the motion of the body carrying it,
read from a ROS 1 `.bag` or a ROS 2 bag (`.db3` or `.mcap` folder) with `rosbags`, the
pure-Python reader (the optional extra `visjax[ros]`).

What is read, per topic (the message types of ROS 1 and ROS 2 alike):

- the image topic: `sensor_msgs/Image` (`mono8`, `rgb8`, `bgr8`, `rgba8`, `bgra8`) or
  `sensor_msgs/CompressedImage`, as grey uint8 frames;
- the camera-info topic: `sensor_msgs/CameraInfo`, its first message: `K` as the
  intrinsics `A`, `D` as OpenCV's distortion coefficients `dist` (the `plumb_bob` and
  `rational_polynomial` models; a fisheye model is refused);
- a velocity topic: `geometry_msgs/TwistStamped` (the body's twist in its own frame, the
  header's `frame_id`) or `nav_msgs/Odometry` (its `twist`, in `child_frame_id`), or
  `sensor_msgs/JointState` of a robot (`ROBOTS`: the joints in the message's order; their
  rates from `velocity` where every message has them, else central differences of the
  angles), whose tool is the body (its frame `tool`), expressed in the camera frame
  through the camera's pose in the body frame: the `/tf_static` transform from the body
  frame to the camera's (the camera info's `frame_id`) when the bag has one, else
  `camera_from_body` (identity when the two frames are one).

Times: each message's header stamp (the bag's receive time where a stamp is zero), in
integer nanoseconds, less the first image's, then in seconds. A missing topic, a topic of
another message type, stamps that go backwards or repeat on a topic, and an image encoding
or a distortion model visjax cannot read are each one `DataFormatError` naming them.
"""

from dataclasses import dataclass
from pathlib import Path

import jax
import numpy as np

from .._util import did_you_mean
from ..geometry import DISTORTION_LENGTHS, so3_exp, so3_log
from ..kinematics import TwoLinkArm, puma560
from ._formats import DataFormatError

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
CAMERA_INFO_TYPE = "sensor_msgs/msg/CameraInfo"
TWIST_TYPE = "geometry_msgs/msg/TwistStamped"
ODOMETRY_TYPE = "nav_msgs/msg/Odometry"
TF_TYPE = "tf2_msgs/msg/TFMessage"
JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"
ROBOTS = ("puma560", "two_link")
"""The robots whose joint states `read_bag` turns into the tool's velocity: the PUMA 560 of
Jang's thesis (Table 4-1, `visjax.kinematics.puma560`, its sixth joint frame the body's)
and a two-link planar arm (`visjax.kinematics.TwoLinkArm`, its end link the body)."""
_CHANNELS = {"mono8": 1, "rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4}


@dataclass
class BagRecording:
    """What `read_bag` reads: `t` (N,) frame times, s, from the first frame; `frames`
    (N, H, W) uint8 grey; `A` (3, 3); `dist` OpenCV's coefficients or `None`;
    `camera_frame` the camera info's frame; `velocity_t` (M,) s and `velocity` (M, 6)
    $[v_c, \\omega_c]$ of the camera in its own frame, m/s and rad/s (`None` without a
    velocity topic); `start_ns` the first frame's stamp, ns; `body_R` (M, 3, 3) and
    `body_x` (M, 3) the body's pose at `velocity_t` (an odometry topic's, else `None`);
    `camera_from_body` (4 x 4) the camera's pose in the body frame used (`None`: the same
    frame)."""

    t: np.ndarray
    frames: np.ndarray
    A: np.ndarray
    dist: np.ndarray | None
    camera_frame: str
    velocity_t: np.ndarray | None
    velocity: np.ndarray | None
    start_ns: int
    body_R: np.ndarray | None = None
    body_x: np.ndarray | None = None
    camera_from_body: np.ndarray | None = None

    def body_pose_at(self, t) -> tuple[np.ndarray, np.ndarray]:
        """The body's pose (odometry) at times `t` (K,): `(R (K, 3, 3), x (K, 3))`,
        interpolated between the odometry's samples (linearly, and along the rotation's
        geodesic). **Raises:** `DataFormatError` for a time outside the odometry's."""
        if self.body_R is None:
            raise DataFormatError("the body's pose needs an odometry topic.")
        t, ts = np.asarray(t, float), self.velocity_t
        if t.min() < ts[0] or t.max() > ts[-1]:
            raise DataFormatError(
                f"the odometry covers {ts[0]:.6g} to {ts[-1]:.6g} s of the frames' {t.min():.6g} "
                f"to {t.max():.6g} s: the platform's pose must be known at every frame."
            )
        k = np.clip(np.searchsorted(ts, t, side="right") - 1, 0, len(ts) - 2)
        s = ((t - ts[k]) / (ts[k + 1] - ts[k]))[:, None]
        x = (1 - s) * self.body_x[k] + s * self.body_x[k + 1]
        R0, R1 = self.body_R[k], self.body_R[k + 1]
        with jax.enable_x64(True):  # along the relative rotation's axis (geometry's SO(3))
            turn = jax.vmap(lambda D: so3_log(D).omega)(np.swapaxes(R0, 1, 2) @ R1)
            R = R0 @ np.asarray(jax.vmap(so3_exp)(s * np.asarray(turn)))
        return R, x


def _stamp(msg, received: int) -> int:
    stamp = msg.header.stamp
    ns = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
    return ns if ns > 0 else int(received)


def _messages(reader, bag, topic: str, types: tuple[str, ...]):
    """`[(stamp_ns, message)]` of a topic, checked: there, of one of `types`, stamps
    strictly increasing."""
    connections = [c for c in reader.connections if c.topic == topic]
    if not connections:
        topics = sorted({c.topic for c in reader.connections})
        raise DataFormatError(
            f"{bag}: no topic {topic!r}{did_you_mean(topic, topics)}; the bag's topics are "
            f"{', '.join(topics)}."
        )
    wrong = sorted({c.msgtype for c in connections} - set(types))
    if wrong:
        raise DataFormatError(
            f"{bag}: topic {topic!r} carries {', '.join(wrong)}; expected {' or '.join(types)}."
        )
    out = [
        (_stamp(msg := reader.deserialize(raw, c.msgtype), received), msg)
        for c, received, raw in reader.messages(connections=connections)
    ]
    if not out:
        raise DataFormatError(f"{bag}: topic {topic!r} has no message.")
    stamps = np.array([s for s, _ in out], dtype=np.int64)
    steps = np.diff(stamps)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0)) + 1
        what = "repeats" if steps[k - 1] == 0 else "goes backwards"
        raise DataFormatError(
            f"{bag}: topic {topic!r}: the stamp of message {k} {what} ({stamps[k - 1]} then "
            f"{stamps[k]} ns): a recording's stamps must increase."
        )
    return out


def _grey(msg, bag, topic) -> np.ndarray:
    import cv2

    if msg.__msgtype__.endswith("CompressedImage"):
        image = cv2.imdecode(np.frombuffer(bytes(msg.data), np.uint8), cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise DataFormatError(f"{bag}: topic {topic!r}: an image that cannot be decoded.")
        return image
    channels = _CHANNELS.get(msg.encoding)
    if channels is None:
        raise DataFormatError(
            f"{bag}: topic {topic!r}: image encoding {msg.encoding!r}; visjax reads "
            f"{', '.join(_CHANNELS)} (8 bits a channel)."
        )
    rows = np.frombuffer(bytes(msg.data), np.uint8).reshape(msg.height, msg.step)
    image = rows[:, : msg.width * channels].reshape(msg.height, msg.width, channels)
    code = {"rgb8": cv2.COLOR_RGB2GRAY, "bgr8": cv2.COLOR_BGR2GRAY, "rgba8": cv2.COLOR_RGBA2GRAY}
    if channels == 1:
        return image[..., 0].copy()
    return cv2.cvtColor(image, code.get(msg.encoding, cv2.COLOR_BGRA2GRAY))


def _field(msg, name: str):
    """A CameraInfo field, ROS 1 (`K`, `D`) or ROS 2 (`k`, `d`)."""
    return getattr(msg, name, None) if hasattr(msg, name) else getattr(msg, name.lower())


def _calibration(msg, bag, topic) -> tuple[np.ndarray, np.ndarray | None]:
    A = np.asarray(_field(msg, "K"), float).reshape(3, 3)
    model = str(msg.distortion_model)
    d = np.asarray(_field(msg, "D"), float)
    if model not in ("", "plumb_bob", "rational_polynomial") and d.size and np.any(d):
        raise DataFormatError(
            f"{bag}: topic {topic!r}: distortion model {model!r}; visjax reads OpenCV's "
            "(plumb_bob, rational_polynomial), not a fisheye model."
        )
    if not d.size or not np.any(d):
        return A, None
    if d.size not in DISTORTION_LENGTHS:
        raise DataFormatError(
            f"{bag}: topic {topic!r}: {d.size} distortion coefficients; OpenCV's model takes "
            "4, 5, 8, 12 or 14."
        )
    return A, d


def _quaternion_matrix(q) -> np.ndarray:
    x, y, z, w = (float(v) for v in q) if not hasattr(q, "w") else (q.x, q.y, q.z, q.w)
    n = np.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def pose_from_text(values) -> np.ndarray:
    """A pose `x y z qx qy qz qw` (the camera in the body frame: position, m, and
    orientation, a unit quaternion, ROS's order) as a 4 x 4 matrix.

    **Raises:** `ValueError` for anything but seven finite numbers."""
    v = np.asarray([float(x) for x in (values.split() if isinstance(values, str) else values)])
    if v.shape != (7,) or not np.all(np.isfinite(v)) or not np.linalg.norm(v[3:]) > 0:
        raise ValueError("a pose is seven numbers: x y z qx qy qz qw (a nonzero quaternion)")
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = _quaternion_matrix(v[3:]), v[:3]
    return T


def _static_transform(reader, parent: str, child: str) -> np.ndarray | None:
    """The `/tf_static` transform from `parent` to `child` (4 x 4, the child's pose in the
    parent), or `None`."""
    static = [c for c in reader.connections if c.topic == "/tf_static"]
    for c, _, raw in reader.messages(connections=static) if static else ():  # ([]: all)
        for tf in reader.deserialize(raw, c.msgtype).transforms:
            if tf.header.frame_id.strip("/") == parent and tf.child_frame_id.strip("/") == child:
                tr, q = tf.transform.translation, tf.transform.rotation
                T = np.eye(4)
                T[:3, :3], T[:3, 3] = _quaternion_matrix(q), [tr.x, tr.y, tr.z]
                return T
    return None


def _camera_twist(v_b: np.ndarray, T_body_camera: np.ndarray) -> np.ndarray:
    """A body's twist (M, 6), linear first, in the body frame, as the twist of a camera
    rigidly mounted at `T_body_camera`, in the camera frame:
    $\\omega_c = R^T \\omega_b$, $v_c = R^T (v_b + \\omega_b \\times p)$."""
    R, p = T_body_camera[:3, :3], T_body_camera[:3, 3]
    v, w = v_b[:, :3], v_b[:, 3:]
    return np.concatenate([(v + np.cross(w, p)) @ R, w @ R], axis=1)


def _joint_twists(msgs, robot, bag, topic) -> np.ndarray:
    """The tool's twist (M, 6), linear first, in the tool's frame, from joint states."""
    n = 2 if isinstance(robot, TwoLinkArm) else 6
    q = [np.asarray(m.position, float) for _, m in msgs]
    if any(x.shape[0] < n for x in q):
        raise DataFormatError(f"{bag}: topic {topic!r}: a message has fewer than {n} joints.")
    q = np.stack([x[:n] for x in q])
    rates = [np.asarray(m.velocity, float) for _, m in msgs]
    if all(r.shape[0] >= n for r in rates):
        qdot = np.stack([r[:n] for r in rates])
    else:
        qdot = np.gradient(q, np.array([s for s, _ in msgs], np.int64) / 1e9, axis=0)
    with jax.enable_x64(True):  # every sample at once, in the recording's precision
        if isinstance(robot, TwoLinkArm):  # the end link turns by q1 + q2 about the base z
            v = np.einsum("mij,mj->mi", np.asarray(jax.vmap(robot.jacobian)(q)), qdot)
            c, s_ = np.cos(q.sum(1)), np.sin(q.sum(1))
            zero = np.zeros(len(q))
            return np.stack([c * v[:, 0] + s_ * v[:, 1], -s_ * v[:, 0] + c * v[:, 1], zero,
                             zero, zero, qdot.sum(1)], axis=1)  # fmt: skip
        chain = puma560() if isinstance(robot, str) else robot
        return np.asarray(jax.vmap(lambda a, b: chain.tool_twist(a, b, local=True))(q, qdot))


def read_bag(
    path,
    *,
    image_topic: str,
    camera_info_topic: str,
    twist_topic: str | None = None,
    odometry_topic: str | None = None,
    joint_states_topic: str | None = None,
    robot=None,
    camera_from_body=None,
) -> BagRecording:
    """Read a camera's recording from a ROS 1 or ROS 2 bag (the module docstring).

    **Arguments:** `path` the `.bag` file or the ROS 2 bag's folder; the topics; at most
    one of `twist_topic`, `odometry_topic` and `joint_states_topic` (with `robot`:
    `"puma560"`, a `kinematics.SerialChain` or a `kinematics.TwoLinkArm`);
    `camera_from_body` the camera's pose in the body frame (4 x 4, or `x y z qx qy qz
    qw`), used where `/tf_static` has none.

    **Raises:** `DataFormatError` naming what is missing or wrong; `ImportError` saying
    how to install `rosbags` when it is not."""
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise ImportError(
            "reading ROS bags needs the optional extra: pip install 'visjax[ros]'"
        ) from None
    if sum(x is not None for x in (twist_topic, odometry_topic, joint_states_topic)) > 1:
        raise ValueError("give one velocity topic: twist, odometry or joint states.")
    if (joint_states_topic is None) != (robot is None):
        raise ValueError("joint states need their robot, and a robot its joint states.")
    if isinstance(robot, str) and robot != "puma560":
        raise ValueError(
            f"robot {robot!r}: by name, only 'puma560' (a two-link arm needs its link "
            "lengths: give a kinematics.TwoLinkArm)."
        )
    path = Path(path)
    if not path.exists():
        raise DataFormatError(f"{path}: no such bag.")
    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.LATEST))
        reader.open()
    except Exception as e:  # rosbags' errors: not a bag, a damaged one
        raise DataFormatError(f"{path}: not a readable ROS bag ({e}).") from None
    try:
        images = _messages(reader, path, image_topic, IMAGE_TYPES)
        info = _messages(reader, path, camera_info_topic, (CAMERA_INFO_TYPE,))[0][1]
        A, dist = _calibration(info, path, camera_info_topic)
        frames = np.stack([_grey(m, path, image_topic) for _, m in images])
        start = images[0][0]
        t = (np.array([s for s, _ in images], np.int64) - start) / 1e9
        velocity_t = velocity = body_R = body_x = T = None
        topic = twist_topic or odometry_topic or joint_states_topic
        camera_frame = info.header.frame_id.strip("/")
        if topic is not None:
            kind = (TWIST_TYPE if twist_topic is not None else ODOMETRY_TYPE
                    if odometry_topic is not None else JOINT_STATE_TYPE)  # fmt: skip
            msgs = _messages(reader, path, topic, (kind,))
            first = msgs[0][1]
            if kind == JOINT_STATE_TYPE:
                v_b, body = _joint_twists(msgs, robot, path, topic), "tool"
            else:
                twists = [m.twist if kind == TWIST_TYPE else m.twist.twist for _, m in msgs]
                v_b = np.array([[w.linear.x, w.linear.y, w.linear.z, w.angular.x, w.angular.y,
                                 w.angular.z] for w in twists])  # fmt: skip
                body = first.header.frame_id if kind == TWIST_TYPE else first.child_frame_id
            body = body.strip("/")
            T = None if body == camera_frame else _static_transform(reader, body, camera_frame)
            if T is None and body != camera_frame:
                if camera_from_body is None:
                    raise DataFormatError(
                        f"{path}: the velocities are of frame {body!r}, the camera's is "
                        f"{camera_frame!r}, and /tf_static has no transform between them: "
                        "give the camera's pose in the body frame (--camera-from-body)."
                    )
                T = camera_from_body
            if T is not None and not isinstance(T, np.ndarray):
                T = pose_from_text(T)
            velocity = v_b if T is None else _camera_twist(v_b, np.asarray(T, float))
            velocity_t = (np.array([s for s, _ in msgs], np.int64) - start) / 1e9
            if kind == ODOMETRY_TYPE:  # the body's pose in the odometry's frame
                poses = [m.pose.pose for _, m in msgs]
                body_R = np.stack([_quaternion_matrix(p.orientation) for p in poses])
                body_x = np.array([[p.position.x, p.position.y, p.position.z] for p in poses])
    finally:
        reader.close()
    return BagRecording(
        t, frames, A, dist, camera_frame, velocity_t, velocity, start, body_R, body_x,
        None if T is None else np.asarray(T, float),
    )  # fmt: skip
