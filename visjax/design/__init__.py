"""Offline gain design (cvxpy; never inside jit)."""

from ._lmi import (
    LMIInfeasibleError as LMIInfeasibleError,
    UIODesign as UIODesign,
    design_uio as design_uio,
    max_lipschitz as max_lipschitz,
)
