"""Offline gain design (cvxpy; never inside jit)."""

from .._util import renamed as _renamed
from ._lmi import (
    LMIInfeasibleError as LMIInfeasibleError,
    MovingPointDesign as MovingPointDesign,
    certified_lipschitz as certified_lipschitz,
    convergence_rate as convergence_rate,
    design_uio as design_uio,
    design_uio_for_motion as design_uio_for_motion,
    max_lipschitz as max_lipschitz,
)

RENAMED = {"UIODesign": "MovingPointDesign"}
"""The names of visjax 0.3 (old -> new): still given, with a `FutureWarning`."""
__getattr__ = _renamed("visjax.design", RENAMED, globals())
