"""visjax: JAX-accelerated, differentiable vision-based nonlinear estimators.

The library never changes JAX's global configuration. Enable float64 yourself
(`jax.config.update("jax_enable_x64", True)`) for the papers' accuracy; the geometry also
runs in float32. One exception: XLA options set on import (a scheduler option that avoids
a deadlock of XLA's CPU runtime, and on jaxlib 0.10 the older loop emitter, which compiles
faster): see `_xla_workaround`.

Subpackages, from the bottom layer up: `geometry` (camera, SO(3), homography,
decomposition, calibration, the uncalibrated-camera model), `kinematics` (rigid-body motion,
perspective dynamics), `sim` (general scene builders), `estimators` (the contract, the
runner, the three papers' estimators), `baselines` (the same problems solved otherwise),
`design` (the UIO's LMI, cvxpy imported lazily), `frontend` (KLT tracking, OpenCV imported
lazily), `io` (each estimator's input as a documented file format), `papers` (each paper's
numbers, scenario and experiment), `studies` (generic studies), and the modules `report`,
`plots` and `cli`.
"""

from . import (
    _xla_workaround,  # noqa: F401  (first: before any JAX backend starts)
    baselines as baselines,
    design as design,
    estimators as estimators,
    frontend as frontend,
    geometry as geometry,
    io as io,
    kinematics as kinematics,
    papers as papers,
    sim as sim,
    studies as studies,
)
from ._results import RESULTS as RESULTS, result_names as result_names

__version__ = "0.3.0"
