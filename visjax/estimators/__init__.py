"""The papers' observers and update laws, the contract they fulfil and the runner they share."""

from .._util import renamed as _renamed
from ._active_point_depth import (
    ActivePointDepth as ActivePointDepth,
    ActivePointDepthOutput as ActivePointDepthOutput,
    ActivePointDepthState as ActivePointDepthState,
    active_sigma2 as active_sigma2,
    active_velocity as active_velocity,
    servo_angular_velocity as servo_angular_velocity,
)
from ._adaptive_ls import (
    StaticPointsDiagnostics as StaticPointsDiagnostics,
    StaticPointsEstimator as StaticPointsEstimator,
    StaticPointsMeasurement as StaticPointsMeasurement,
    StaticPointsOutput as StaticPointsOutput,
    StaticPointsState as StaticPointsState,
    pe_measure as pe_measure,
    platform_measurements as platform_measurements,
    static_points_stream as static_points_stream,
)
from ._base import (
    MAX_SAVED_BYTES as MAX_SAVED_BYTES,
    MAX_STEPS as MAX_STEPS,
    AbstractAdjoint as AbstractAdjoint,
    AbstractEstimator as AbstractEstimator,
    AbstractJumpEstimator as AbstractJumpEstimator,
    AbstractReducer as AbstractReducer,
    CheckpointAdjoint as CheckpointAdjoint,
    DirectAdjoint as DirectAdjoint,
    Innovation as Innovation,
    SaveAt as SaveAt,
    Solution as Solution,
    Stream as Stream,
    WindowRMS as WindowRMS,
    WindowSummary as WindowSummary,
    checked_samples as checked_samples,
    innovation as innovation,
    integration_step as integration_step,
    reject_mask as reject_mask,
    rejected_samples as rejected_samples,
    run as run,
)
from ._filters import lowpass as lowpass, lowpass_delay as lowpass_delay
from ._homography import (
    HomographyEstimator as HomographyEstimator,
    HomographyMeasurement as HomographyMeasurement,
    HomographyOutput as HomographyOutput,
    HomographyState as HomographyState,
    homography_bearings as homography_bearings,
    homography_innovation as homography_innovation,
    homography_stream as homography_stream,
    unit_bearings as unit_bearings,
)
from ._point_depth import (
    PointDepthEstimator as PointDepthEstimator,
    PointDepthMeasurement as PointDepthMeasurement,
    PointDepthOutput as PointDepthOutput,
    PointDepthState as PointDepthState,
    point_depth_rate as point_depth_rate,
    point_depth_stream as point_depth_stream,
    point_model as point_model,
)
from ._uio import (
    MOVING_POINT_A_U as MOVING_POINT_A_U,
    MovingPointEstimator as MovingPointEstimator,
    MovingPointMeasurement as MovingPointMeasurement,
    MovingPointOutput as MovingPointOutput,
    MovingPointState as MovingPointState,
    moving_point_innovation as moving_point_innovation,
    moving_point_stream as moving_point_stream,
    rank_condition as rank_condition,
    uio_matrices as uio_matrices,
    uio_residuals as uio_residuals,
)
from ._velocity import (
    FixedCamera as FixedCamera,
    FrameMeasure as FrameMeasure,
    VelocityDiagnostics as VelocityDiagnostics,
    VelocityEstimator as VelocityEstimator,
    VelocityMeasurement as VelocityMeasurement,
    VelocityOutput as VelocityOutput,
    VelocityState as VelocityState,
    depth_from_feature_length as depth_from_feature_length,
    depth_from_known_length as depth_from_known_length,
    diagonal_intersection as diagonal_intersection,
    error_signal as error_signal,
    fixed_camera as fixed_camera,
    kinematics_jacobian as kinematics_jacobian,
    plane_normal_from_frames as plane_normal_from_frames,
    velocity_innovation as velocity_innovation,
    velocity_measurements as velocity_measurements,
    velocity_stream as velocity_stream,
)

RENAMED = {
    "UIOState": "MovingPointState",
    "UIOOutput": "MovingPointOutput",
    "MovingCameraMeasurement": "MovingPointMeasurement",
    "MovingPointObserver": "MovingPointEstimator",
    "AdaptiveState": "StaticPointsState",
    "AdaptiveOutput": "StaticPointsOutput",
    "AdaptiveDiagnostics": "StaticPointsDiagnostics",
    "PlatformMeasurement": "StaticPointsMeasurement",
    "THESIS_A_U": "MOVING_POINT_A_U",
}
"""The names of visjax 0.3 (old -> new): still given, with a `FutureWarning`."""
MOVED = {"paper_eq56_matrix": "visjax.papers.chitrakaran.eq56_matrix"}
"""Names that moved to another package (old -> where they are now)."""
__getattr__ = _renamed("visjax.estimators", RENAMED, globals(), moved=MOVED)
