"""The papers' observers and update laws, the contract they fulfil and the runner they share."""

from ._adaptive_ls import (
    AdaptiveDiagnostics as AdaptiveDiagnostics,
    AdaptiveOutput as AdaptiveOutput,
    AdaptiveState as AdaptiveState,
    PlatformMeasurement as PlatformMeasurement,
    StaticPointsEstimator as StaticPointsEstimator,
    pe_measure as pe_measure,
    platform_measurements as platform_measurements,
    static_points_stream as static_points_stream,
)
from ._base import (
    AbstractAdjoint as AbstractAdjoint,
    AbstractEstimator as AbstractEstimator,
    AbstractJumpEstimator as AbstractJumpEstimator,
    AbstractReducer as AbstractReducer,
    CheckpointAdjoint as CheckpointAdjoint,
    DirectAdjoint as DirectAdjoint,
    SaveAt as SaveAt,
    Solution as Solution,
    Stream as Stream,
    WindowRMS as WindowRMS,
    WindowSummary as WindowSummary,
    checked_samples as checked_samples,
    integration_step as integration_step,
    run as run,
)
from ._filters import lowpass as lowpass, lowpass_delay as lowpass_delay
from ._uio import (
    THESIS_A_U as THESIS_A_U,
    MovingCameraMeasurement as MovingCameraMeasurement,
    MovingPointObserver as MovingPointObserver,
    UIOOutput as UIOOutput,
    UIOState as UIOState,
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
    paper_eq56_matrix as paper_eq56_matrix,
    plane_normal_from_frames as plane_normal_from_frames,
    velocity_measurements as velocity_measurements,
    velocity_stream as velocity_stream,
)
