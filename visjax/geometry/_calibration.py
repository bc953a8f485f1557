"""Least-squares refinement of the camera matrix (seed 003, section 2.3).

Model: $[u, v, 1]^T = K_c [m_1, m_2, 1]^T$ with $K_c = [[f, 0, c_x], [0, a f, c_y], [0, 0, 1]]$.
The linear regression $S\\theta = \\beta$, $\\theta = [f, af, c_x, c_y]$, rows of $S$
$[m_{1i}, 0, 1, 0]$ and $[0, m_{2i}, 0, 1]$, $\\beta = [u_1, v_1, \\dots]$; the thesis takes
$\\hat\\theta = S^+\\beta$. The two image axes decouple, so each is a 2x2 normal-equation
solve here: the same minimiser, smooth in the data (no SVD).
"""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._util import as_float


def camera_matrix_lstsq(
    m: Float[ArrayLike, "n 2"], p: Float[ArrayLike, "n 2"]
) -> Float[Array, "4"]:
    """$\\hat\\theta = [f, af, c_x, c_y]$ by least squares from normalized coordinates `m` and
    pixels `p` of the same points (seed 003, section 2.3).

    Raises at run time if the normalized coordinates do not vary along an axis (the
    regression is then singular).
    """
    m, p = as_float(m), as_float(p)
    if m.ndim != 2 or m.shape[-1] != 2 or m.shape != p.shape or m.shape[0] < 2:
        raise ValueError(
            f"`m` and `p` must both have shape (n, 2) with n >= 2; got {m.shape} and {p.shape}."
        )

    def axis(x, y):
        n = x.shape[0]
        sxx, sx, sxy, sy = jnp.sum(x * x), jnp.sum(x), jnp.sum(x * y), jnp.sum(y)
        det = n * sxx - sx * sx
        det = eqx.error_if(
            det,
            ~(det > 1e-12 * n * sxx),
            "camera_matrix_lstsq: the normalized coordinates do not vary along an axis.",
        )
        return (n * sxy - sx * sy) / det, (sxx * sy - sx * sxy) / det

    f, cx = axis(m[:, 0], p[:, 0])
    af, cy = axis(m[:, 1], p[:, 1])
    return jnp.stack([f, af, cx, cy])


def camera_matrix(theta: Float[ArrayLike, "4"]) -> Float[Array, "3 3"]:
    """$K_c$ from $\\theta = [f, af, c_x, c_y]$ (seed 003, section 2.2)."""
    theta = as_float(theta)
    f, af, cx, cy = theta[0], theta[1], theta[2], theta[3]
    z, o = jnp.zeros_like(f), jnp.ones_like(f)
    return jnp.stack([jnp.stack([f, z, cx]), jnp.stack([z, af, cy]), jnp.stack([z, z, o])])
