"""visjax: JAX-accelerated, differentiable vision-based nonlinear estimators.

The library never changes JAX's global configuration. Enable float64 yourself
(`jax.config.update("jax_enable_x64", True)`) for the papers' accuracy; the geometry also
runs in float32.
"""

from . import geometry as geometry, sim as sim
from ._results import RESULTS as RESULTS

__version__ = "0.1.0"
