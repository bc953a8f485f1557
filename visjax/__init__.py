"""visjax: JAX-accelerated, differentiable vision-based nonlinear estimators.

Importing visjax changes no global state of the process: no environment variable, no JAX
config. Enable float64 yourself (`jax.config.update("jax_enable_x64", True)`) for the
papers' accuracy; the geometry also runs in float32. For large batches on a CPU, call
`visjax.apply_xla_cpu_workarounds()` before any JAX computation (XLA options that avoid a
hang of XLA's CPU runtime with jaxlib 0.10 and compile faster); the command line does.

Subpackages, from the bottom layer up: `geometry` (camera, SO(3), homography,
decomposition, calibration, the uncalibrated-camera model), `kinematics` (rigid-body motion,
perspective dynamics), `sim` (general scene builders), `estimators` (the contract, the
runner, the three papers' estimators), `baselines` (the same problems solved otherwise),
`design` (the UIO's LMI, cvxpy imported lazily), `frontend` (KLT tracking, OpenCV imported
lazily), `io` (each estimator's input as a documented file format), `studies` (generic
studies over any problem, the registry of problems), `papers` (each paper's numbers,
scenario, experiment and problems), and the modules `report`, `verbs`,
`plots` and `cli`.
"""

from . import (
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
from ._version import __version__ as __version__
from ._xla_workaround import (
    apply_xla_cpu_workarounds as apply_xla_cpu_workarounds,
    xla_cpu_options as xla_cpu_options,
)
