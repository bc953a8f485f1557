"""ROS bags for the tests, written with `rosbags`' own writers (ROS 1 `.bag`, ROS 2 sqlite3
or MCAP): a camera's images, its CameraInfo, a body's velocity (TwistStamped or Odometry)
and /tf_static, each stamped with the given nanoseconds."""

from pathlib import Path

import numpy as np


def _quaternion(R) -> np.ndarray:
    """(x, y, z, w) of a rotation matrix (its trace is positive here)."""
    w = np.sqrt(max(1.0 + np.trace(R), 1e-12)) / 2
    return np.array(
        [
            (R[2, 1] - R[1, 2]) / (4 * w),
            (R[0, 2] - R[2, 0]) / (4 * w),
            (R[1, 0] - R[0, 1]) / (4 * w),
            w,
        ]
    )


def write_bag(
    path,
    ros: str,
    frames,
    stamps_ns,
    K,
    D=(),
    *,
    velocity=None,
    velocity_kind: str = "twist",
    body_frame: str = "camera",
    camera_from_body=None,
    image_topic: str = "/camera/image",
    info_topic: str = "/camera/camera_info",
    velocity_topic: str = "/body/velocity",
    stamps_velocity_ns=None,
    encoding: str = "mono8",
    storage: str = "sqlite3",
    image_header_ns=None,
    joints=None,
    stamps_joints_ns=None,
    poses=None,
) -> Path:
    """Write a bag: `ros` "1" (a `.bag` file) or "2" (a folder; `storage` sqlite3 or mcap).
    `velocity` (M, 6), linear first, in `body_frame`, stamped `stamps_velocity_ns`;
    `camera_from_body` (4 x 4) written to /tf_static (body -> "camera"; ROS 2 only: ROS 1's
    type store has no tf2_msgs). `image_header_ns`: the images' header stamps, when they
    differ from the times the bag received them. `joints` (M, n) joint angles, rad, as
    /joint_states (positions only), stamped `stamps_joints_ns`. `poses` (M, 4, 4) the
    body's pose in "odom" with an odometry `velocity` (default the identity)."""
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC if ros == "1" else Stores.ROS2_HUMBLE)
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    path = Path(path)

    def header(ns, frame):
        stamp = Time(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))
        return (
            Header(seq=0, stamp=stamp, frame_id=frame)
            if ros == "1"
            else Header(stamp=stamp, frame_id=frame)
        )

    def vec(x):
        return T["geometry_msgs/msg/Vector3"](x=float(x[0]), y=float(x[1]), z=float(x[2]))

    if ros == "1":
        from rosbags.rosbag1 import Writer

        writer, serialize = Writer(path), ts.serialize_ros1
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        writer, serialize = Writer(path, version=9, storage_plugin=plugin), ts.serialize_cdr
    names = {"Image": "sensor_msgs/msg/Image", "Info": "sensor_msgs/msg/CameraInfo"}
    with writer:
        image_c = writer.add_connection(image_topic, names["Image"], typestore=ts)
        info_c = writer.add_connection(info_topic, names["Info"], typestore=ts)
        roi = T["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        )
        h, w = np.asarray(frames).shape[1:]
        upper = ros == "1"  # ROS 1 names the calibration's fields in capitals
        fields = {
            "K" if upper else "k": np.asarray(K, float).reshape(9),
            "D" if upper else "d": np.asarray(D, float),
            "R" if upper else "r": np.eye(3).reshape(9),
            "P" if upper else "p": np.c_[np.asarray(K, float), np.zeros(3)].reshape(12),
        }
        info = T[names["Info"]](
            header=header(int(stamps_ns[0]), "camera"), height=h, width=w,
            distortion_model="plumb_bob" if len(D) <= 5 else "rational_polynomial",
            binning_x=0, binning_y=0, roi=roi, **fields,
        )  # fmt: skip
        writer.write(info_c, int(stamps_ns[0]), serialize(info, names["Info"]))
        headers = stamps_ns if image_header_ns is None else image_header_ns
        for ns, stamp, frame in zip(stamps_ns, headers, frames):
            frame = np.asarray(frame, np.uint8)
            data = frame if encoding == "mono8" else np.repeat(frame[..., None], 3, axis=2)
            step = w * (1 if encoding == "mono8" else 3)
            msg = T[names["Image"]](
                header=header(int(stamp), "camera"), height=h, width=w, encoding=encoding,
                is_bigendian=0, step=step, data=data.reshape(-1),
            )  # fmt: skip
            writer.write(image_c, int(ns), serialize(msg, names["Image"]))
        if velocity is not None:
            kind = (
                "geometry_msgs/msg/TwistStamped"
                if velocity_kind == "twist"
                else "nav_msgs/msg/Odometry"
            )
            conn = writer.add_connection(velocity_topic, kind, typestore=ts)
            for i, (ns, v) in enumerate(zip(stamps_velocity_ns, np.asarray(velocity, float))):
                twist = T["geometry_msgs/msg/Twist"](linear=vec(v[:3]), angular=vec(v[3:]))
                if velocity_kind == "twist":
                    msg = T[kind](header=header(int(ns), body_frame), twist=twist)
                else:
                    P = np.eye(4) if poses is None else np.asarray(poses[i], float)
                    qx, qy, qz, qw = _quaternion(P[:3, :3])
                    pose = T["geometry_msgs/msg/PoseWithCovariance"](
                        pose=T["geometry_msgs/msg/Pose"](
                            position=T["geometry_msgs/msg/Point"](x=P[0, 3], y=P[1, 3], z=P[2, 3]),
                            orientation=T["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
                        ),
                        covariance=np.zeros(36),
                    )
                    cov = T["geometry_msgs/msg/TwistWithCovariance"](
                        twist=twist, covariance=np.zeros(36)
                    )
                    msg = T[kind](
                        header=header(int(ns), "odom"),
                        child_frame_id=body_frame,
                        pose=pose,
                        twist=cov,
                    )
                writer.write(conn, int(ns), serialize(msg, kind))
        if joints is not None:
            kind = "sensor_msgs/msg/JointState"
            conn = writer.add_connection("/joint_states", kind, typestore=ts)
            for ns, q in zip(stamps_joints_ns, np.asarray(joints, float)):
                names = [f"joint_{i + 1}" for i in range(len(q))]
                msg = T[kind](header=header(int(ns), ""), name=names, position=q,
                              velocity=np.zeros(0), effort=np.zeros(0))  # fmt: skip
                writer.write(conn, int(ns), serialize(msg, kind))
        if camera_from_body is not None:
            kind = "tf2_msgs/msg/TFMessage"
            conn = writer.add_connection("/tf_static", kind, typestore=ts)
            q = _quaternion(camera_from_body[:3, :3])
            tf = T["geometry_msgs/msg/TransformStamped"](
                header=header(int(stamps_ns[0]), body_frame), child_frame_id="camera",
                transform=T["geometry_msgs/msg/Transform"](
                    translation=vec(camera_from_body[:3, 3]),
                    rotation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
                ),
            )  # fmt: skip
            writer.write(conn, int(stamps_ns[0]), serialize(T[kind](transforms=[tf]), kind))
    return path
