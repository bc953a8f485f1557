"""The special linear group SL(3) and its Lie algebra sl(3): the homographies of the plane
as unit-determinant 3x3 matrices, and the trace-free matrices that generate them.

The observer of Hamel, Mahony, Trumpf, Morin and Hua (*Homography estimation on the Special
Linear group based on direct point correspondence*, IEEE CDC-ECC 2011) evolves its estimate
on SL(3): a homography is defined up to scale, and the representative of unit determinant
turns it into a group element, $\\dot H = H A$ with $A \\in \\mathfrak{sl}(3)$. These are the
group's standard operations (no equation of the paper is transcribed here):

- `sl3_project(M)`: the orthogonal projection onto $\\mathfrak{sl}(3)$ for the Frobenius inner
  product $\\langle A, B \\rangle = \\mathrm{tr}(A^T B)$, $P(M) = M - \\frac{\\mathrm{tr} M}{3} I$;
- `sl3_exp(X)`: the group exponential $\\exp(P(X))$, $\\det = e^{\\mathrm{tr} P(X)} = 1$;
- `sl3_normalize(H)`: the representative $H / \\det(H)^{1/3}$ of a homography in SL(3).
"""

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._small import det3, mm
from .._util import as_float, check_shape

_TAYLOR_ORDER = 12  # the remainder of exp at norm 1/2: 0.5**13 / 13! e^0.5 < 2e-14
_MAX_SQUARINGS = 12  # scaling by up to 2**12: norms up to 2048 (exp(2048) overflows anyway)


def _check(M, name):
    M = as_float(M)
    check_shape(M, (3, 3), name)
    return M


def sl3_project(M: Float[ArrayLike, "3 3"]) -> Float[Array, "3 3"]:
    """The orthogonal projection of a 3x3 matrix onto $\\mathfrak{sl}(3)$ (trace-free
    matrices) for the Frobenius inner product: $P(M) = M - \\frac{\\mathrm{tr} M}{3} I$.

    $P$ is linear and idempotent, $\\mathrm{tr} P(M) = 0$, and $M - P(M)$ is orthogonal to
    every trace-free matrix.

    No error path: NaN in, NaN out.
    """
    return _sl3_project(_check(M, "M"))


def sl3_exp(X: Float[ArrayLike, "3 3"]) -> Float[Array, "3 3"]:
    """The exponential of SL(3): $\\exp(P(X))$, with $P$ = `sl3_project` (so any 3x3 `X`
    is accepted and its trace ignored), a matrix of determinant 1.

    Scaling and squaring: $\\exp(Y) = \\exp(Y / 2^s)^{2^s}$ with the smallest $s \\le 12$
    that brings the 1-norm of $Y / 2^s$ to at most 1/2, the exponential of the scaled
    matrix by its Taylor series to order 12 (relative remainder below 2e-14). Smooth in
    `X` (the number of squarings is piecewise constant and held under differentiation).

    No error path: a non-finite entry gives NaN; a norm beyond about 700 overflows to inf
    as the exponential itself does.
    """
    return _sl3_exp(_check(X, "X"))


def sl3_normalize(H: Float[ArrayLike, "3 3"]) -> Float[Array, "3 3"]:
    """The representative of the homography `H` (defined up to scale) in SL(3):
    $H / \\det(H)^{1/3}$ (the real cube root, so a negative determinant gives $-H$ scaled).

    A non-invertible `H` (determinant 0) or a non-finite entry gives NaN, never a finite
    matrix.
    """
    return _sl3_normalize(_check(H, "H"))


# The arithmetic, compiled after the checks: one program per shape when called outside
# `jit`; inlined under `jit`.
@jax.jit
def _sl3_project(M):
    return M - (M[0, 0] + M[1, 1] + M[2, 2]) / 3.0 * jnp.eye(3, dtype=M.dtype)


@jax.jit
def _sl3_exp(X):
    Y = _sl3_project(X)
    eye = jnp.eye(3, dtype=Y.dtype)
    norm = jnp.max(jnp.sum(jnp.abs(jax.lax.stop_gradient(Y)), axis=0))  # the 1-norm
    finite = jnp.isfinite(norm)
    safe = jnp.where(finite & (norm > 0.5), norm, 0.5)
    s = jnp.clip(jnp.ceil(jnp.log2(safe / 0.5)), 0, _MAX_SQUARINGS)
    Z = Y / 2.0**s
    # Horner: I + Z (I + Z/2 (I + Z/3 (... (I + Z/12))))
    E = eye
    for k in range(_TAYLOR_ORDER, 0, -1):
        E = eye + mm(Z, E) / k
    for k in range(_MAX_SQUARINGS):
        E = jnp.where(k < s, mm(E, E), E)
    return jnp.where(finite, E, jnp.nan)


@jax.jit
def _sl3_normalize(H):
    # scaled by its largest entry first: the determinant of a matrix of entries 1e-12 or
    # 1e12 would under- or overflow (float32 already at 1e-13 and 1e13), the result is
    # the same
    m = jnp.max(jnp.abs(H))
    m_ok = jnp.isfinite(m) & (m > 0)
    H1 = H / jnp.where(m_ok, m, 1.0)
    d = det3(H1)
    ok = m_ok & jnp.isfinite(d) & (d != 0.0)
    d_safe = jnp.where(ok, d, 1.0)
    scale = jnp.sign(d_safe) * jnp.abs(d_safe) ** (1.0 / 3.0)
    return jnp.where(ok, H1 / scale, jnp.nan)
