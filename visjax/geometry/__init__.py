"""Camera model, SO(3) and SL(3), homography estimation and decomposition: pure JAX functions."""

from .._util import renamed as _renamed
from ._calibration import (
    CameraFit as CameraFit,
    camera_matrix as camera_matrix,
    camera_matrix_lstsq as camera_matrix_lstsq,
)
from ._camera import (
    Projection as Projection,
    extended_intrinsics as extended_intrinsics,
    intrinsic_matrix as intrinsic_matrix,
    normalized_to_pixel as normalized_to_pixel,
    pixel_to_normalized as pixel_to_normalized,
    project as project,
    to_homogeneous as to_homogeneous,
)
from ._decomposition import (
    decompose_homography as decompose_homography,
    decompose_homography_known_normal as decompose_homography_known_normal,
    select_solution as select_solution,
)
from ._distortion import (
    DISTORTION_LENGTHS as DISTORTION_LENGTHS,
    distort_pixels as distort_pixels,
    undistort_pixels as undistort_pixels,
)
from ._homography import (
    Homography as Homography,
    alpha_g33 as alpha_g33,
    euclidean_homography as euclidean_homography,
    find_homography as find_homography,
    projective_homography as projective_homography,
)
from ._reconstruction import (
    Reconstruction as Reconstruction,
    euclidean_reconstruction as euclidean_reconstruction,
)
from ._robust import (
    RobustHomography as RobustHomography,
    find_homography_robust as find_homography_robust,
)
from ._sl3 import (
    sl3_exp as sl3_exp,
    sl3_normalize as sl3_normalize,
    sl3_project as sl3_project,
)
from ._so3 import (
    L_omega as L_omega,
    L_omega_inv as L_omega_inv,
    RotationVector as RotationVector,
    sinc as sinc,
    skew as skew,
    so3_exp as so3_exp,
    so3_log as so3_log,
    vee as vee,
)
from ._uncalibrated import (
    camera_from_parameters as camera_from_parameters,
    camera_parameters as camera_parameters,
    feature_in_camera as feature_in_camera,
    intrinsics_from_camera as intrinsics_from_camera,
    known_feature_regressors as known_feature_regressors,
    unknown_feature_regressors as unknown_feature_regressors,
)

RENAMED = {"intrinsics_eq4": "intrinsics_from_camera"}
"""The names of visjax 0.3 (old -> new): still given, with a `FutureWarning`."""
__getattr__ = _renamed("visjax.geometry", RENAMED, globals())
