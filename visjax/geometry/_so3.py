"""SO(3): skew matrices, the exponential and logarithm (angle-axis), `sinc`, and `L_omega`.

Every function here is written for one instance (a 3-vector or a 3x3 matrix) and batched
with `jax.vmap`. Every singular point (angle 0 for all of them, angle pi for the
logarithm) has a Taylor branch chosen with the double-`where` pattern, so that neither the
value nor the gradient is NaN there.

Source: Chitrakaran, Dawson, Dixon, Chen, *Identification of a moving object's velocity with
a fixed camera*, eqs. (24)-(31) and (A.3).
"""

from typing import final

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._results import RESULTS
from .._small import barrier, det3, dot, from_rows, mm, rows, sall, smax, smm, sskew, ssum
from .._util import as_float, check_shape


def _small(dtype) -> float:
    # Taylor branches are used below this squared angle. With three terms kept, the
    # truncation error is O(theta^6), below machine precision for theta^2 < eps^(1/2).
    return float(jnp.finfo(dtype).eps) ** 0.5


def skew(v: Float[ArrayLike, "3"]) -> Float[Array, "3 3"]:
    """The skew-symmetric matrix $[v]_\\times$, with $[v]_\\times w = v \\times w$.

    **Arguments:**

    - `v`: a 3-vector.

    **Returns:** the 3x3 matrix $[v]_\\times$ (Chitrakaran et al., notation of eq. (27)).

    No error path: NaN in, NaN out (a NaN or inf entry reaches every output entry
    computed from it; none is turned finite).
    """
    v = as_float(v)
    check_shape(v, (3,), "v")
    return _skew(v)


# The arithmetic of the public functions, compiled after their checks: one program per
# shape when called outside `jit` (not one compiled operation per line); inlined under `jit`.
@jax.jit
def _skew(v):
    z = jnp.zeros((), v.dtype)
    return jnp.stack(
        [
            jnp.stack([z, -v[2], v[1]]),
            jnp.stack([v[2], z, -v[0]]),
            jnp.stack([-v[1], v[0], z]),
        ]
    )


def vee(S: Float[ArrayLike, "3 3"]) -> Float[Array, "3"]:
    """The inverse of `skew`: the vector of the skew-symmetric part of `S`.

    No error path: NaN in, NaN out (a NaN or inf entry reaches every output entry
    computed from it; none is turned finite).
    """
    S = as_float(S)
    check_shape(S, (3, 3), "S")
    return 0.5 * jnp.stack([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]])


def sinc(x: Float[ArrayLike, "..."]) -> Float[Array, "..."]:
    """The unnormalised sinc, $\\mathrm{sinc}(x) = \\sin(x) / x$ (Chitrakaran et al., below
    eq. (27)).

    Convention: unnormalised (unlike `numpy.sinc`, which is $\\sin(\\pi x)/(\\pi x)$);
    $\\mathrm{sinc}(0) = 1$ with a finite gradient there.

    No error path: NaN in, NaN out (a NaN or inf entry reaches every output entry
    computed from it; none is turned finite).
    """
    x = as_float(x)
    x2 = x * x
    small = x2 < _small(x.dtype)
    x_safe = jnp.where(small, jnp.ones_like(x), x)
    taylor = 1.0 - x2 / 6.0 + x2 * x2 / 120.0
    return jnp.where(small, taylor, jnp.sin(x_safe) / x_safe)


def _rotation_coefficients(t2):
    """sin(t)/t, (1 - cos t)/t^2 and (t - sin t)/t^3 from t^2, with Taylor branches at 0
    (double-`where`: finite value and gradient)."""
    small = t2 < _small(t2.dtype)
    t2_safe = jnp.where(small, jnp.ones_like(t2), t2)
    t = jnp.sqrt(t2_safe)
    a = jnp.where(small, 1.0 - t2 / 6.0 + t2**2 / 120.0, jnp.sin(t) / t)
    b = jnp.where(small, 0.5 - t2 / 24.0 + t2**2 / 720.0, (1.0 - jnp.cos(t)) / t2_safe)
    c = jnp.where(small, 1.0 / 6.0 - t2 / 120.0 + t2**2 / 5040.0, (t - jnp.sin(t)) / (t2_safe * t))
    return a, b, c


def so3_exp(omega: Float[ArrayLike, "3"]) -> Float[Array, "3 3"]:
    """The exponential map from a rotation vector $\\theta u$ to a rotation matrix.

    Implements the Rodrigues form of Chitrakaran et al., eq. (A.3),
    $R = I_3 + \\sin\\theta [u]_\\times + 2 \\sin^2(\\theta/2) [u]_\\times^2$,
    written in $\\omega = \\theta u$ so that it is smooth at $\\theta = 0$.

    **Arguments:**

    - `omega`: the rotation vector $\\theta u$ (radians).

    No error path: a non-finite entry gives NaN (NaN in, NaN out).

    **Returns:** $R \\in SO(3)$.
    """
    omega = as_float(omega)
    check_shape(omega, (3,), "omega")
    return _so3_exp(omega)


@jax.jit
def _so3_exp(omega):
    a, b, _ = _rotation_coefficients(ssum(omega**2))
    W = skew(omega)
    return jnp.eye(3, dtype=omega.dtype) + a * W + b * mm(W, W)


@final
class RotationVector(eqx.Module):
    """What `so3_log` returns.

    **Fields:** `omega` (3,): the rotation vector $u\\theta$, NaN where it is not defined
    (never a finite placeholder); `result`: a `RESULTS` item, `successful`, or (with
    `throw=False`) `nonfinite_matrix` (a non-finite entry in `R`) or `not_a_rotation`.
    """

    omega: Float[Array, "3"]
    result: RESULTS


def so3_log(R: Float[ArrayLike, "3 3"], *, throw: bool = True) -> RotationVector:
    """The logarithm of a rotation matrix as a rotation vector $e_\\omega = u\\theta$.

    Implements Chitrakaran et al., eqs. (24) and (28):
    $\\theta = \\cos^{-1}((\\mathrm{tr} R - 1)/2)$, $[u]_\\times = (R - R^T) / (2 \\sin\\theta)$,
    with $0 \\le \\theta \\le \\pi$ (eq. (29)).

    Convention: the angle is computed as `atan2(|vee(R - R^T)|/2, (tr R - 1)/2)`, which is
    accurate at every angle (the `arccos` of eq. (28) loses half the digits near 0 and pi).
    Near $\\theta = \\pi$ the axis is read from the symmetric part
    $(R + R^T)/2 - \\cos\\theta\\, I = (1 - \\cos\\theta)\\, u u^T$ and its sign from the
    skew part, since eq. (28) divides by $\\sin\\theta \\to 0$ there. At exactly
    $\\theta = \\pi$ both $u\\pi$ and $-u\\pi$ are valid; one is returned.

    **Arguments:**

    - `R`: a rotation matrix.
    - `throw`: if `True` (default), a finite matrix that is not a rotation ($R^TR \\ne I$
        or $\\det R \\ne 1$ beyond $10\\sqrt{\\epsilon}$) raises at run time; with `False`
        it is the result `not_a_rotation` (and `omega` NaN). A non-finite entry is NaN in,
        NaN out, with the result `nonfinite_matrix` either way (it never raises: a failed
        frame upstream has already said why).

    **Returns:** a `RotationVector`: `omega`, $u\\theta$ with $\\|u\\theta\\| \\in [0, \\pi]$,
    and `result`.
    """
    if not isinstance(throw, bool):
        raise ValueError(f"`throw` must be a bool; got {throw!r}.")
    R = as_float(R)
    check_shape(R, (3, 3), "R")
    return _so3_log_result(R, throw)


@eqx.filter_jit  # one program per shape, dtype and `throw`; its error_if raised as
# equinox's runtime error
def _so3_log_result(R, throw: bool):
    omega, rotation = _so3_log_checked(R)
    finite = sall(jnp.isfinite(R))
    result = RESULTS.where(
        finite,
        RESULTS.where(rotation, RESULTS.successful, RESULTS.not_a_rotation),
        RESULTS.nonfinite_matrix,
    )
    if throw:  # only a finite non-rotation raises (NaN in, NaN out)
        omega = eqx.error_if(
            omega, ~rotation, "so3_log: the matrix is not a rotation (R^T R != I or det R != 1)."
        )
    return RotationVector(jnp.where(rotation, omega, jnp.nan), result)


@jax.jit
def _so3_log_checked(R):
    """`(omega, is_rotation)`: the rotation vector (NaN for a non-finite `R`) and whether a
    finite `R` is a rotation within the tolerance (`True` for a non-finite one)."""
    dtype = R.dtype
    w = vee(R)  # = sin(theta) u
    c = jnp.clip(0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0), -1.0, 1.0)  # = cos(theta)
    s2 = ssum(w**2)  # = sin^2(theta)

    # Branch 1 (cos >= 0, theta <= pi/2): theta u = w * theta / sin(theta), where
    # theta / sin(theta) = asin(s)/s = 1 + s^2/6 + 3 s^4/40 + ... for small s = sin(theta).
    near_zero = s2 < _small(dtype)
    s2_safe = jnp.where(near_zero, jnp.ones_like(s2), s2)
    s_safe = jnp.sqrt(s2_safe)
    factor = jnp.where(
        near_zero, 1.0 + s2 / 6.0 + 3.0 * s2**2 / 40.0, jnp.arctan2(s_safe, c) / s_safe
    )
    small_branch = w * factor

    # Branch 2 (cos < 0): axis from the symmetric part, sign from the skew part.
    use_large = c < 0.0
    R_safe = jnp.where(use_large, R, jnp.diag(jnp.array([1.0, -1.0, -1.0], dtype)))
    c_safe = jnp.where(use_large, c, -1.0)
    w_safe = vee(R_safe)
    B = 0.5 * (R_safe + R_safe.T) - c_safe * jnp.eye(3, dtype=dtype)  # (1 - c) u u^T
    # the column of the largest diagonal entry (the first on ties, as argmax), by selects:
    # a gather per frame is slow under vmap
    d = jnp.diag(B)
    first = (d[0] >= d[1]) & (d[0] >= d[2])
    second = ~first & (d[1] >= d[2])
    col = jnp.where(first, B[:, 0], jnp.where(second, B[:, 1], B[:, 2]))
    b_kk = jnp.where(first, d[0], jnp.where(second, d[1], d[2]))
    u = col / jnp.sqrt(b_kk * (1.0 - c_safe))
    u = jnp.where(dot(u, w_safe) >= 0.0, u, -u)
    sw2 = ssum(w_safe**2)
    sw = jnp.where(sw2 > 0.0, jnp.sqrt(jnp.where(sw2 > 0.0, sw2, 1.0)), 0.0)
    theta_large = jnp.arctan2(sw, c_safe)
    large_branch = theta_large * u

    out = jnp.where(use_large, large_branch, small_branch)
    # a non-finite entry never becomes a finite vector (the clip and argmax above would
    # hide it): NaN in, NaN out
    finite = sall(jnp.isfinite(R))
    out = barrier(jnp.where(finite, out, jnp.nan))  # once per frame
    # not a rotation: R^T R = I and det R = 1 within a dtype-aware tolerance, 10 sqrt(eps)
    # (1.5e-7 in float64, 3.5e-3 in float32; the reconstruction's rotations meet it to
    # ~1e-15 and ~1e-6)
    tol = 10.0 * float(jnp.finfo(dtype).eps) ** 0.5
    off = smax(jnp.abs(mm(R.T, R) - jnp.eye(3, dtype=dtype))) + jnp.abs(det3(R) - 1.0)
    return out, jax.lax.stop_gradient(~(finite & (off > tol)))


def _L_omega_coefficient(t2):
    # (1 - sinc(theta) / sinc^2(theta/2)) / theta^2 of eq. (27), and its Taylor series
    # 1/12 + theta^2/720 + theta^4/30240 at theta -> 0.
    small = t2 < _small(t2.dtype)
    t2_safe = jnp.where(small, jnp.ones_like(t2), t2)
    t = jnp.sqrt(t2_safe)
    exact = (1.0 - sinc(t) / sinc(0.5 * t) ** 2) / t2_safe
    return jnp.where(small, 1.0 / 12.0 + t2 / 720.0 + t2**2 / 30240.0, exact)


def L_omega(e_omega: Float[ArrayLike, "3"]) -> Float[Array, "3 3"]:
    """The rotational Jacobian $L_\\omega$ with $\\dot e_\\omega = L_\\omega \\omega_e$.

    Implements Chitrakaran et al., eq. (27),
    $L_\\omega = I_3 - \\frac{\\theta}{2}[u]_\\times
    + \\left(1 - \\frac{\\mathrm{sinc}\\theta}{\\mathrm{sinc}^2(\\theta/2)}\\right)[u]_\\times^2$,
    written in $e_\\omega = u\\theta$ so that it is smooth (value and gradient) at
    $\\theta = 0$, where $L_\\omega = I_3$.

    Convention: $\\omega_e$ is the angular velocity in the fixed frame,
    $[\\omega_e]_\\times = \\dot{\\bar R} \\bar R^T$ (eq. (A.2)), and $e_\\omega$ is
    `so3_log(R_bar)`. Its determinant is $1/\\mathrm{sinc}^2(\\theta/2)$; eq. (31) of the
    paper prints $1/\\sin^2(\\theta/2)$, which cannot hold at $\\theta \\to 0$ where
    $L_\\omega \\to I_3$. Either way it is singular only at multiples of $2\\pi$.

    **Arguments:**

    - `e_omega`: the rotation vector $u\\theta$ of eq. (24).

    No error path: a non-finite entry gives NaN (NaN in, NaN out).

    **Returns:** the 3x3 matrix $L_\\omega$.
    """
    e_omega = as_float(e_omega)
    check_shape(e_omega, (3,), "e_omega")
    return _L_omega(e_omega)


@jax.jit
def _L_omega(e_omega):
    return from_rows(_L_omega_rows(rows(e_omega)), e_omega.dtype)


def _eye_plus(a, W, b, W2):
    """$I + a W + b W^2$ for rows of scalars (W skew, given by `sskew`)."""
    return [[float(i == j) + a * W[i][j] + b * W2[i][j] for j in range(3)] for i in range(3)]


def _L_omega_rows(e):
    """`L_omega` (eq. (27)) of a 3-list of scalars, as rows."""
    W = sskew(e)
    c = _L_omega_coefficient(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    return _eye_plus(-0.5, W, c, smm(W, W))


def _L_omega_inv_rows(e):
    """`L_omega_inv` of a 3-list of scalars, as rows."""
    _, b, c = _rotation_coefficients(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    W = sskew(e)
    return _eye_plus(b, W, c, smm(W, W))


def L_omega_inv(e_omega: Float[ArrayLike, "3"]) -> Float[Array, "3 3"]:
    """The inverse of `L_omega`, so that $\\omega_e = L_\\omega^{-1} \\dot e_\\omega$ (eq. (A.14)).

    Closed form (the left Jacobian of SO(3)):
    $L_\\omega^{-1} = I_3 + \\frac{1 - \\cos\\theta}{\\theta^2}[e_\\omega]_\\times
    + \\frac{\\theta - \\sin\\theta}{\\theta^3}[e_\\omega]_\\times^2$, with Taylor branches at 0.
    No error path: a non-finite entry gives NaN (NaN in, NaN out).
    """
    e_omega = as_float(e_omega)
    check_shape(e_omega, (3,), "e_omega")
    return _L_omega_inv(e_omega)


@jax.jit
def _L_omega_inv(e_omega):
    return from_rows(_L_omega_inv_rows(rows(e_omega)), e_omega.dtype)
