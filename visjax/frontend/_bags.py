"""A ROS bag to a problem's data file: the images tracked (KLT, or AprilTag corners), the
camera info's intrinsics and distortion, the camera's velocity from the bag
(`visjax.io.read_bag`), and the constants the bag cannot tell from a camera file
(`visjax.io.data_from_tracks`): the command `visjax import-bag`."""

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..io import DataFormatError, data_from_tracks, read_bag, read_camera_file
from ..kinematics import TwoLinkArm
from ._tags import track_tags
from ._tracking import track_frames

BAG_PROBLEMS = ("velocity", "moving_point", "static_points")
"""The problems `import_bag` writes a data file for."""


def import_bag(
    bag,
    problem: str,
    *,
    image_topic: str,
    camera_info: str,
    twist: str | None = None,
    odometry: str | None = None,
    joint_states: str | None = None,
    robot=None,
    tags: str | None = None,
    camera: Mapping[str, Any] | str | Path | None = None,
    camera_from_body=None,
    max_features: int = 200,
    progress: bool = False,
):
    """The data file of `problem` (`BAG_PROBLEMS`) from a ROS 1 or ROS 2 bag.

    **Arguments:** `bag` the `.bag` file or the ROS 2 bag's folder; `image_topic`,
    `camera_info` the camera's topics; `twist`, `odometry` or `joint_states` (with `robot`:
    `"puma560"`, `"two_link"` with the camera file's `link_lengths: [l1, l2]`, or a
    `kinematics` chain) the topic of the camera's body's velocity (the moving point needs
    one; the static points, an odometry topic); `tags` an AprilTag family: the tags'
    corners as features (feature 4 i + c, `track_tags`), else KLT tracks (`track_frames`,
    planar for the velocity problem); `camera` the constants the bag cannot tell, a camera
    file or its mapping, as for `data_from_tracks` without the intrinsics (velocity:
    `features`, `coplanar` or `tag` and `tag_size`, `known_length`, `R_star`, `s1`; moving
    point: `feature`, `D`; static points: `known`, `unknown`, `known_features`, and the
    nominal mounting `R_c_nominal`, `x_c_nominal` where the bag's transform (or
    `camera_from_body`) is not to be taken as it; the platform's pose at the frames comes
    from the odometry topic's poses, interpolated); `camera_from_body` the camera's pose
    in the body frame where the bag's `/tf_static` has none (`io.read_bag`).

    **Returns:** the `VelocityData`, `MovingPointData` or `StaticPointsData` (`.save(path)`
    writes it): the pixels as the camera saw them, with the camera info's `dist`.

    **Raises:** `DataFormatError` naming what is missing or wrong."""
    if problem not in BAG_PROBLEMS:
        raise DataFormatError(f"no bag import for problem {problem!r}; choose from {BAG_PROBLEMS}.")
    base = Path(".")
    if isinstance(camera, str | Path):
        base = Path(camera).parent
        camera = read_camera_file(camera)
    camera = dict(camera or {})
    given = sorted(k for k in ("A", "fx", "fy", "cx", "cy", "dist") if k in camera)
    if given:
        raise DataFormatError(
            f"the camera file gives {given}: from a bag, the intrinsics and the distortion "
            "are the camera info's."
        )
    if robot == "two_link":
        if "link_lengths" not in camera:
            raise DataFormatError("a two-link arm needs `link_lengths: [l1, l2]` (m) in --camera.")
        l1, l2 = (float(x) for x in camera.pop("link_lengths"))
        robot = TwoLinkArm(l1, l2)
    if problem == "moving_point" and twist is None and odometry is None and joint_states is None:
        raise DataFormatError(
            "the moving point needs the camera's velocity: twist, odometry or joint states."
        )
    rec = read_bag(
        bag, image_topic=image_topic, camera_info_topic=camera_info, twist_topic=twist,
        odometry_topic=odometry, joint_states_topic=joint_states, robot=robot,
        camera_from_body=camera_from_body,
    )  # fmt: skip
    fps = 1.0 / float(np.median(np.diff(rec.t))) if len(rec.t) > 1 else 30.0
    if tags is not None:
        tracks = track_tags(rec.frames, tags, fps=fps, progress=progress)
    else:
        tracks = track_frames(
            rec.frames, fps=fps, max_features=max_features, planar=problem == "velocity",
            progress=progress,
        )  # fmt: skip
    camera["A"] = rec.A.tolist()
    if rec.dist is not None:
        camera["dist"] = rec.dist.tolist()
    if rec.velocity is not None:
        camera["camera_velocity"] = {"t": rec.velocity_t, "velocity": rec.velocity}
    if problem == "static_points":
        if rec.body_R is None:
            raise DataFormatError("the static points need the platform's pose: an odometry topic.")
        R, x = rec.body_pose_at(rec.t)
        camera["platform"] = {"platform_R": R, "platform_x": x}
        mount = np.eye(4) if rec.camera_from_body is None else rec.camera_from_body
        camera.setdefault("R_c_nominal", mount[:3, :3].tolist())
        camera.setdefault("x_c_nominal", mount[:3, 3].tolist())
    return data_from_tracks(problem, (rec.t, tracks.pixels), camera, base=base)
