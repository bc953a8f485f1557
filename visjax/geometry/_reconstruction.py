"""Euclidean reconstruction from reference and current pixels (Chitrakaran et al., section 3).

From four or more coplanar points seen in a reference image and a current image, with the
intrinsic matrix known: the normalized projective homography $G_n$ and the products
$\\alpha_i g_{33}$ (eq. (17)), the Euclidean homography $H = g_{33} A^{-1} G_n A$
(eqs. (12), (16)), its decomposition into $\\bar R$, $\\bar x_h$, $n^*$ (eq. (12)), the scale
$g_{33}$, and every depth ratio $\\alpha_i = z_i^* / z_i$.
"""

from typing import final

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from .._results import RESULTS, all_finite, intrinsics_ok, raise_or_keep
from .._small import mv, norm, sall
from .._util import as_float, check_shape
from ._camera import pixel_to_normalized, to_homogeneous
from ._decomposition import _decompose_core, _known_normal_core, select_solution
from ._homography import _check_pair, _dlt, euclidean_homography


@final
class Reconstruction(eqx.Module):
    """What the Euclidean reconstruction of Chitrakaran et al., section 3, returns.

    **Fields:**

    - `R_bar`: $\\bar R = R R^{*T}$, the rotation of the current plane frame relative to the
        reference one, expressed in the camera frame (eq. (8)).
    - `x_h`: $\\bar x_h = \\bar x_f / d^*$, the scaled translation (eq. (13)).
    - `n_star`: $n^*$, the unit normal of the reference plane in the camera frame, pointing
        away from the camera ($d^* = n^{*T}\\bar m_i^* > 0$, eq. (4)).
    - `g33`: $g_{33}$, the scale of eq. (17), so that $G = g_{33} G_n$.
    - `alpha`: the depth ratios $\\alpha_i = z_i^* / z_i$ (eq. (12)), one per point.
    - `G_n`: the normalized projective homography of eq. (17).
    - `H`: the Euclidean homography $\\bar R + \\bar x_h n^{*T}$ of eq. (12).
    - `result`: a `RESULTS` item (always `successful` when the call was made with
        `throw=True`, since a failure raises).
    """

    R_bar: Float[Array, "3 3"]
    x_h: Float[Array, "3"]
    n_star: Float[Array, "3"]
    g33: Float[Array, ""]
    alpha: Float[Array, " n"]
    G_n: Float[Array, "3 3"]
    H: Float[Array, "3 3"]
    result: RESULTS


def euclidean_reconstruction(
    p_ref: Float[ArrayLike, "n 2"],
    p_cur: Float[ArrayLike, "n 2"],
    A: Float[ArrayLike, "3 3"],
    n_prior: Float[ArrayLike, "3"] | None = None,
    *,
    n_star: Float[ArrayLike, "3"] | None = None,
    visible: Bool[ArrayLike, " n"] | None = None,
    throw: bool = True,
) -> Reconstruction:
    """Euclidean reconstruction of Chitrakaran et al., section 3, from pixels and $A$.

    Steps: $G_n$ by the normalized DLT of eq. (17); $\\alpha_i g_{33} = 1/(G_n p_i^*)_3$;
    $H / g_{33} = A^{-1} G_n A$ (eq. (16)); the decomposition of eq. (12), which also fixes
    $|g_{33}|$ (the middle singular value of $H$ is 1), while the sign of $g_{33}$ is that
    of $\\alpha_i g_{33}$ since $\\alpha_i > 0$; finally $\\alpha_i = (\\alpha_i g_{33}) / g_{33}$.

    Two decomposition paths:

    - `n_star=None` (default): the general four-solution decomposition, then the physical
      solution (reference points in front of the camera, then the normal closest to
      `n_prior`, default $[0, 0, 1]$: a plane roughly facing the camera). With no
      translation the normal is unobservable; then $\\bar x_h = 0$, $\\bar R$ is the rotation
      and `n_star` returns the normalised prior.
    - `n_star` given (the plane normal is known and constant, as in the paper once it has
      been measured): the smooth known-normal path, differentiable at $H = I$.

    **Arguments:**

    - `p_ref`: reference pixels $p_i^*$, shape (n, 2), n >= 4, coplanar points.
    - `p_cur`: current pixels $p_i$, shape (n, 2).
    - `A`: the intrinsic matrix.
    - `n_prior`: the prior normal used to choose between the two physical solutions.
    - `n_star`: a known plane normal; switches to the known-normal path.
    - `visible`: optional (n,) booleans: the current pixels of the points marked `False`
        (features out of view, occluded) are ignored, whatever they hold (NaN included);
        the homography comes from the others (at least 4, of more than 4 points), and
        every $\alpha_i$ still follows, from the reference pixels (eq. (17)).
    - `throw`: if `True` (default), degenerate points, non-finite pixels, a point behind
        the camera or no physical solution raise at run time; with `False` the failure is
        reported in `result` instead.

    **Returns:** a `Reconstruction`.
    """
    p_ref, p_cur = _check_pair(p_ref, p_cur)
    A = as_float(A)
    check_shape(A, (3, 3), "A")
    dtype = jnp.result_type(p_ref, A)
    p_ref, p_cur, A = p_ref.astype(dtype), p_cur.astype(dtype), A.astype(dtype)
    if n_prior is None:
        n_prior = jnp.array([0.0, 0.0, 1.0], dtype)
    n_prior = as_float(n_prior)
    check_shape(n_prior, (3,), "n_prior")
    n_prior = n_prior.astype(dtype)
    n_prior = n_prior / norm(n_prior)

    if visible is not None:
        visible = jnp.asarray(visible)
        if visible.shape != p_ref.shape[:1] or visible.dtype != bool:
            raise ValueError(
                f"`visible` must be booleans of shape ({p_ref.shape[0]},); got "
                f"{visible.dtype} {tuple(visible.shape)}."
            )
    G_n, result = _dlt(p_ref, p_cur, visible)

    # alpha_i g33 of eq. (17): all of one sign, the sign of g33, since alpha_i > 0.
    w = mv(to_homogeneous(p_ref), G_n[2])
    at_infinity = ~sall(jnp.abs(w) > 0.0)
    w = jnp.where(jnp.abs(w) > 0.0, w, 1.0)
    beta = 1.0 / w
    sign = jnp.where(beta[0] < 0.0, -1.0, 1.0).astype(dtype)
    behind = at_infinity | ~sall(sign * beta > 0.0)

    H_over_g33 = euclidean_homography(G_n, A)
    Hs = sign * H_over_g33  # a positive multiple of H
    m_ref = to_homogeneous(pixel_to_normalized(p_ref, A))

    if n_star is not None:
        n_star = as_float(n_star)
        check_shape(n_star, (3,), "n_star")
        n = n_star.astype(dtype) / norm(n_star.astype(dtype))
        R, x_h, scale = _known_normal_core(Hs, n)
        physical = sall(mv(m_ref, n) > 0.0)
    else:
        Rs, ts, ns, scale, is_rotation = _decompose_core(Hs)
        R, x_h, n, physical = select_solution(Rs, ts, ns, m_ref, n_prior)
        R = jnp.where(is_rotation, Rs[0], R)
        x_h = jnp.where(is_rotation, jnp.zeros_like(x_h), x_h)
        n = jnp.where(is_rotation, n_prior, n)
        physical = physical | is_rotation

    g33 = sign / scale
    alpha = beta / g33
    H = Hs / scale

    result = RESULTS.where(
        result != RESULTS.successful,
        result,
        RESULTS.where(
            behind,
            RESULTS.behind_camera,
            RESULTS.where(physical, RESULTS.successful, RESULTS.no_physical_solution),
        ),
    )
    # The camera and plane parameters, and the outputs, are tested with an explicit
    # isfinite: no reduction decides this code (XLA's CPU max can drop a NaN in a batch).
    params_ok = intrinsics_ok(A) & all_finite((n_prior, n))
    result = RESULTS.where(params_ok, result, RESULTS.invalid_intrinsics)
    outputs_ok = all_finite((R, x_h, n, g33, alpha, G_n, Hs))
    result = RESULTS.where(
        (result == RESULTS.successful) & ~outputs_ok, RESULTS.nonfinite_output, result
    )
    out = Reconstruction(
        R_bar=R, x_h=x_h, n_star=n, g33=g33, alpha=alpha, G_n=G_n, H=H, result=result
    )
    return raise_or_keep(result, out, throw)
