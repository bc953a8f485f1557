"""Offline gain design (cvxpy; never inside jit)."""

from ._lmi import (
    LMIInfeasibleError as LMIInfeasibleError,
    UIODesign as UIODesign,
    certified_lipschitz as certified_lipschitz,
    convergence_rate as convergence_rate,
    design_uio as design_uio,
    design_uio_for_motion as design_uio_for_motion,
    max_lipschitz as max_lipschitz,
)
