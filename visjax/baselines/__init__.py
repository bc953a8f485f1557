"""Baselines on the same data as the estimators: batch nonlinear least squares
(optimistix Levenberg-Marquardt) and extended Kalman filters, returning the estimators'
own `Output` Modules in a `Solution` (OpenCV imported lazily, inside calls)."""

from ._bundle import (
    BundleDiagnostics as BundleDiagnostics,
    bundle_adjustment as bundle_adjustment,
    bundle_adjustment_residuals as bundle_adjustment_residuals,
    static_points_ekf as static_points_ekf,
)
from ._ekf import (
    AbstractEKFModel as AbstractEKFModel,
    EKFOutput as EKFOutput,
    EKFSample as EKFSample,
    EKFState as EKFState,
    ExtendedKalmanFilter as ExtendedKalmanFilter,
    ekf_stream as ekf_stream,
    extended_kalman_filter as extended_kalman_filter,
)
from ._losses import (
    Loss as Loss,
    cauchy as cauchy,
    covariance as covariance,
    huber as huber,
)
from ._opencv import (
    opencv_reconstruction as opencv_reconstruction,
    ransac_homographies as ransac_homographies,
)
from ._point_depth import InverseDepthModel as InverseDepthModel
from ._point_fit import (
    TriangulationDiagnostics as TriangulationDiagnostics,
    camera_poses as camera_poses,
    moving_point_ekf as moving_point_ekf,
    triangulate_point as triangulate_point,
    triangulation_residuals as triangulation_residuals,
)
from ._pose_fit import (
    FramePoses as FramePoses,
    SmootherDiagnostics as SmootherDiagnostics,
    fit_bandwidth_hz as fit_bandwidth_hz,
    frame_poses as frame_poses,
    half_width_for_bandwidth as half_width_for_bandwidth,
    object_features as object_features,
    reprojection_residuals as reprojection_residuals,
    velocity_covariance as velocity_covariance,
    velocity_ekf as velocity_ekf,
    velocity_smoother as velocity_smoother,
)
