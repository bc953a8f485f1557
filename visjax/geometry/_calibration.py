"""Least-squares refinement of the camera matrix (Jang's thesis, section 2.3).

Model: $[u, v, 1]^T = K_c [m_1, m_2, 1]^T$ with $K_c = [[f, 0, c_x], [0, a f, c_y], [0, 0, 1]]$.
The linear regression $S\\theta = \\beta$, $\\theta = [f, af, c_x, c_y]$, rows of $S$
$[m_{1i}, 0, 1, 0]$ and $[0, m_{2i}, 0, 1]$, $\\beta = [u_1, v_1, \\dots]$; the thesis takes
$\\hat\\theta = S^+\\beta$. The two image axes decouple, so each is a 2x2 normal-equation
solve here: the same minimiser, smooth in the data (no SVD).
"""

from typing import final

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._results import RESULTS
from .._util import as_float, check_shape


@final
class CameraFit(eqx.Module):
    """What `camera_matrix_lstsq` returns.

    **Fields:** `theta` (4,): $[f, af, c_x, c_y]$, NaN when the fit failed (never a finite
    placeholder); `result`: a `RESULTS` item, `successful`, or (with `throw=False`)
    `nonfinite_pixels` (a coordinate not finite) or `degenerate_points` (the normalized
    coordinates do not vary along an axis: the regression is singular).
    """

    theta: Float[Array, "4"]
    result: RESULTS


def camera_matrix_lstsq(
    m: Float[ArrayLike, "n 2"], p: Float[ArrayLike, "n 2"], *, throw: bool = True
) -> CameraFit:
    """$\\hat\\theta = [f, af, c_x, c_y]$ by least squares from normalized coordinates `m` and
    pixels `p` of the same points (Jang's thesis, section 2.3). Each axis is solved from
    centred sums.

    `throw`: if `True` (default), a coordinate that is not finite, or normalized
    coordinates that do not vary along an axis (the regression is then singular), raise at
    run time; with `False` the failure is the `result` (and `theta` NaN), so that one bad
    frame of a `jax.vmap` batch leaves the others intact.

    **Returns:** a `CameraFit`: `theta` and `result`.
    """
    m, p = as_float(m), as_float(p)
    if m.ndim != 2 or m.shape[-1] != 2 or m.shape != p.shape or m.shape[0] < 2:
        raise ValueError(
            f"`m` and `p` must both have shape (n, 2) with n >= 2; got {m.shape} and {p.shape}."
        )
    if not isinstance(throw, bool):
        raise ValueError(f"`throw` must be a bool; got {throw!r}.")
    return _camera_matrix_lstsq(m, p, throw)


@eqx.filter_jit  # one program per shape and `throw`; its error_if raised as equinox's
# runtime error
def _camera_matrix_lstsq(m, p, throw: bool):
    finite = jnp.all(jnp.isfinite(m)) & jnp.all(jnp.isfinite(p))
    # a non-finite input is swapped for a regular one before the sums (finite gradients)
    m_safe = jnp.where(finite, m, jnp.arange(m.size, dtype=m.dtype).reshape(m.shape))
    p_safe = jnp.where(finite, p, 0.0)

    def axis(x, y):
        # centred sums: the raw normal equations lose digits on offset, narrow data
        n = x.shape[0]
        x_mean, y_mean = jnp.mean(x), jnp.mean(y)
        dx, dy = x - x_mean, y - y_mean
        sxx = jnp.sum(dx * dx)
        # no variation: below what rounding the mean leaves (dtype-aware, not a fixed 1e-12)
        floor = n * (100.0 * jnp.finfo(x.dtype).eps * jnp.max(jnp.abs(x))) ** 2
        varies = sxx > floor
        slope = jnp.sum(dx * dy) / jnp.where(varies, sxx, 1.0)
        return slope, y_mean - slope * x_mean, varies

    f, cx, ok_x = axis(m_safe[:, 0], p_safe[:, 0])
    af, cy, ok_y = axis(m_safe[:, 1], p_safe[:, 1])
    result = RESULTS.where(
        finite,
        RESULTS.where(ok_x & ok_y, RESULTS.successful, RESULTS.degenerate_points),
        RESULTS.nonfinite_pixels,
    )
    theta = jnp.where(result == RESULTS.successful, jnp.stack([f, af, cx, cy]), jnp.nan)
    if throw:
        theta = eqx.error_if(
            theta, ~finite, "camera_matrix_lstsq: a coordinate is not finite (NaN or inf)."
        )
        theta = eqx.error_if(
            theta,
            ~(ok_x & ok_y),
            "camera_matrix_lstsq: the normalized coordinates do not vary along an axis.",
        )
    return CameraFit(theta, result)


def camera_matrix(theta: Float[ArrayLike, "4"]) -> Float[Array, "3 3"]:
    """$K_c$ from $\\theta = [f, af, c_x, c_y]$ (Jang's thesis, section 2.2).

    No error path: NaN in, NaN out (a NaN or inf entry reaches every output entry
    computed from it; none is turned finite).
    """
    theta = as_float(theta)
    check_shape(theta, (4,), "theta")
    f, af, cx, cy = theta[0], theta[1], theta[2], theta[3]
    z, o = jnp.zeros_like(f), jnp.ones_like(f)
    return jnp.stack([jnp.stack([f, z, cx]), jnp.stack([z, af, cy]), jnp.stack([z, z, o])])
