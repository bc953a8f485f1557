"""General scene builders: trajectories, camera rigs, sampling, pixel noise; no paper here.

The papers' own scenarios are built from these in `visjax.papers`. A catalogue of canonical
scenes that are none of the papers' (the ones the tests, the benchmarks and the example data
files use) is here too: `sinusoidal_plate_scene`, `spline_board_scene`,
`sideways_camera_scene`, `circling_camera_scene`, `tilted_platform_scene`,
`side_looking_platform_scene`, and their data-file forms (`*_record`); and the scenes of
the landmark problems, `point_depth_scene` and `homography_scene`.
"""

from ._catalogue import (
    MOVING_TARGET_FRAME_HZ as MOVING_TARGET_FRAME_HZ,
    MOVING_TARGET_IMAGE as MOVING_TARGET_IMAGE,
    MOVING_TARGET_K as MOVING_TARGET_K,
    MOVING_TARGET_RATE_HZ as MOVING_TARGET_RATE_HZ,
    MOVING_TARGET_SCENES as MOVING_TARGET_SCENES,
    circling_camera_scene as circling_camera_scene,
    moving_target_camera as moving_target_camera,
    moving_target_scene as moving_target_scene,
    side_looking_platform_scene as side_looking_platform_scene,
    sideways_camera_record as sideways_camera_record,
    sideways_camera_scene as sideways_camera_scene,
    sinusoidal_plate_record as sinusoidal_plate_record,
    sinusoidal_plate_scene as sinusoidal_plate_scene,
    spline_board_scene as spline_board_scene,
    tilted_platform_record as tilted_platform_record,
    tilted_platform_scene as tilted_platform_scene,
)
from ._landmarks import (
    HOMOGRAPHY_ANGULAR_VELOCITY as HOMOGRAPHY_ANGULAR_VELOCITY,
    HOMOGRAPHY_CAMERA as HOMOGRAPHY_CAMERA,
    HOMOGRAPHY_PLANE_DISTANCE as HOMOGRAPHY_PLANE_DISTANCE,
    HOMOGRAPHY_PLANE_POINTS as HOMOGRAPHY_PLANE_POINTS,
    HOMOGRAPHY_START as HOMOGRAPHY_START,
    HOMOGRAPHY_START_ROTATION as HOMOGRAPHY_START_ROTATION,
    HOMOGRAPHY_VELOCITY as HOMOGRAPHY_VELOCITY,
    POINT_DEPTH_CAMERA as POINT_DEPTH_CAMERA,
    POINT_DEPTH_POINTS as POINT_DEPTH_POINTS,
    POINT_DEPTH_TWIST as POINT_DEPTH_TWIST,
    HomographyScene as HomographyScene,
    PointDepthScene as PointDepthScene,
    homography_scene as homography_scene,
    plane_group_velocity as plane_group_velocity,
    point_depth_scene as point_depth_scene,
)
from ._moving_point import (
    MovingPointScene as MovingPointScene,
    moving_point_scene as moving_point_scene,
)
from ._planar import (
    PlanarScenes as PlanarScenes,
    random_planar_scenes as random_planar_scenes,
    rotation_from_vector as rotation_from_vector,
)
from ._rigs import (
    add_pixel_noise as add_pixel_noise,
    fixed_camera_pixels as fixed_camera_pixels,
    hold_indices as hold_indices,
    moving_camera_point as moving_camera_point,
    platform_camera_pixels as platform_camera_pixels,
)
from ._robots import (
    JointTrajectory as JointTrajectory,
    encoder_twist as encoder_twist,
    follow_tool_twist as follow_tool_twist,
    planar_path as planar_path,
    quantise as quantise,
)
from ._scene import (
    CameraRig as CameraRig,
    Sampler as Sampler,
    box_features as box_features,
    constant_twist_trajectory as constant_twist_trajectory,
    intrinsics as intrinsics,
    object_points as object_points,
    planar_features as planar_features,
    points_in_camera as points_in_camera,
    sinusoidal_trajectory as sinusoidal_trajectory,
    spline_trajectory as spline_trajectory,
    view as view,
)
from ._trajectory import (
    Trajectory as Trajectory,
    integrate_twist as integrate_twist,
    sample_times as sample_times,
)
