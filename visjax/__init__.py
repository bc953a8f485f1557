"""visjax: JAX-accelerated, differentiable vision-based nonlinear estimators.

The library never changes JAX's global configuration. Enable float64 yourself
(`jax.config.update("jax_enable_x64", True)`) for the papers' accuracy; the geometry also
runs in float32.

Subpackages: `geometry` (camera, SO(3), homography, decomposition, calibration, the
uncalibrated-camera regressors), `kinematics` (rigid-body motion), `sim` (scenarios),
`estimators` (the runner, the velocity estimator of seed 000, the UIO of seed 003), `design`
(the UIO's LMI, cvxpy), `frontend` (KLT tracking, OpenCV), `studies` (experiments).
"""

from . import (
    design as design,
    estimators as estimators,
    frontend as frontend,
    geometry as geometry,
    kinematics as kinematics,
    sim as sim,
    studies as studies,
)
from ._results import RESULTS as RESULTS

__version__ = "0.1.0"
