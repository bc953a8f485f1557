"""The papers' observers and update laws, and the runner they share."""

from ..kinematics import (
    camera_term as camera_term,
    known_input_term as known_input_term,
    perspective_dynamics as perspective_dynamics,
)
from ._adaptive_ls import (
    AdaptiveStructureEstimator as AdaptiveStructureEstimator,
    PlatformMeasurement as PlatformMeasurement,
    pe_measure as pe_measure,
    platform_measurements as platform_measurements,
)
from ._base import (
    AbstractEstimator as AbstractEstimator,
    Reducer as Reducer,
    Solution as Solution,
    Stream as Stream,
    run as run,
    summary_rms as summary_rms,
    window_rms_reducer as window_rms_reducer,
)
from ._uio import (
    UnknownInputObserver as UnknownInputObserver,
    rank_condition as rank_condition,
    uio_matrices as uio_matrices,
    uio_residuals as uio_residuals,
)
from ._velocity import (
    VelocityEstimator as VelocityEstimator,
    VelocityMeasurement as VelocityMeasurement,
    depth_from_known_length as depth_from_known_length,
    diagonal_intersection as diagonal_intersection,
    error_signal as error_signal,
    fixed_camera_stream as fixed_camera_stream,
    kinematics_jacobian as kinematics_jacobian,
    paper_eq56_matrix as paper_eq56_matrix,
    plane_normal_from_frames as plane_normal_from_frames,
    velocity_measurements as velocity_measurements,
)
