"""Rigid-body motion: the pose of an object moving with a given velocity.

Source: Chitrakaran et al., eq. (A.1), $[\\omega_e]_\\times = \\dot R R^T$, and $\\dot x_f = v_e$
(the derivative of eq. (5) for the origin of $\\mathcal F$): both velocities are expressed in
the fixed frame $\\mathcal I$.
"""

from collections.abc import Callable

import diffrax
import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._util import as_float, check_shape
from ..geometry import skew


class _PoseField(eqx.Module):
    """$(\\dot x, \\dot R) = (v, [\\omega]_\\times R)$ of a twist `velocity(t)`. A Module, so that
    diffrax's compiled solve is reused by every call with an equal `velocity` (a Module's
    arrays are arguments of the compiled program; a new Python closure would compile it
    again)."""

    velocity: Callable

    def __call__(self, t, y, args):
        x, R = y
        v = self.velocity(t)
        return (v[:3], skew(v[3:]) @ R)


def integrate_pose(
    velocity: Callable[[Array], Array],
    x0: Float[ArrayLike, "3"],
    R0: Float[ArrayLike, "3 3"],
    ts: Float[ArrayLike, " N"],
    *,
    rtol: float = 1e-12,
    atol: float = 1e-12,
) -> tuple[Float[Array, "N 3"], Float[Array, "N 3 3"]]:
    """Integrate $\\dot x = v_e(t)$, $\\dot R = [\\omega_e(t)]_\\times R$ accurately.

    An 8th-order Dormand-Prince solve with tight tolerances (default 1e-12, raised to
    100 eps of the dtype: 1.2e-5 in float32, where 1e-12 cannot be met), independent of any
    estimator's discretisation; the rotation is re-projected onto SO(3) at the output times
    (its drift is at the tolerance).

    **Arguments:**

    - `velocity`: $t \\mapsto [v_e, \\omega_e]$ (6,), in the fixed frame.
    - `x0`, `R0`: the pose at `ts[0]`.
    - `ts`: output times, increasing.

    **Returns:** `(x, R)` at `ts`, shapes (N, 3) and (N, 3, 3).
    """
    x0, R0, ts = as_float(x0), as_float(R0), as_float(ts)
    check_shape(x0, (3,), "x0")
    check_shape(R0, (3, 3), "R0")
    check_shape(ts, (None,), "ts")

    floor = 100.0 * float(jnp.finfo(jnp.result_type(x0, R0, ts)).eps)
    return _integrate_pose(velocity, x0, R0, ts, max(rtol, floor), max(atol, floor))


# the solve and its re-projection, one program per velocity field (a Module: per shape)
@eqx.filter_jit
def _integrate_pose(velocity, x0, R0, ts, rtol, atol):
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(_PoseField(velocity)),
        diffrax.Dopri8(),
        ts[0],
        ts[-1],
        dt0=None,
        y0=(x0, R0),
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        max_steps=100_000,
    )
    x, R = sol.ys
    # one Newton step towards the polar factor removes the tolerance-level drift, smoothly
    # (an SVD would have a NaN derivative: the singular values of a rotation repeat)
    R = 1.5 * R - 0.5 * R @ jnp.swapaxes(R, -1, -2) @ R
    return x, R
