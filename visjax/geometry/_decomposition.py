"""Euclidean decomposition of a homography into rotation, scaled translation and normal.

Source: Chitrakaran et al., eq. (12): $H = \\bar R + \\bar x_h n^{*T}$, decomposed
"by various techniques (Faugeras and Lustman, 1988; Zhang and Hanson, 1995)".

Two paths:

- `decompose_homography`, the general method, returns all four solutions. It is the
  eigen-decomposition method of Ma, Soatto, Kosecka and Sastry (*An Invitation to 3-D Vision*,
  section 5.3.3), written from its equations: with $H^T H = V \\Sigma^2 V^T$,
  $\\sigma_1 \\ge \\sigma_2 = 1 \\ge \\sigma_3$, the unit vectors
  $u_{1,2} = (\\sqrt{1-\\sigma_3^2} v_1 \\pm \\sqrt{\\sigma_1^2-1} v_3)
  / \\sqrt{\\sigma_1^2-\\sigma_3^2}$
  are those whose length $H$ preserves; each gives one $(R, t, n)$, and $(R, -t, -n)$ is
  the other of its pair. It is not differentiable where singular values of $H$ coincide
  (no motion, pure rotation, translation along the normal with no rotation): pure rotations
  take a branch of their own that is NaN-free in value and gradient.
- `decompose_homography_known_normal` takes the constant plane normal $n^*$ as known. For
  two unit vectors $a, b \\perp n^*$ with $a \\times b = n^*$, $H a = \\bar R a$ and
  $H b = \\bar R b$, so $\\bar R = [Ha, Hb, Ha \\times Hb][a, b, n^*]^T$. It uses no
  eigen-decomposition and is smooth everywhere, including $H = I$.
"""

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._small import barrier, det2, det3, eigh3, inv2, inv3, mm, mv, norm, sall, smax
from .._util import as_float, check_shape


def _safe_sqrt(x):
    """`sqrt(max(x, 0))` with a zero (not infinite) derivative at 0."""
    pos = x > 0.0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def _rotation_tol(dtype) -> float:
    # Below this deviation of H^T H / det(H)^(2/3) from I, H is treated as a pure rotation.
    # The eigenvector method loses eps / gap digits, the rotation branch makes an error of
    # the order of the gap: sqrt(eps) balances the two.
    return float(jnp.finfo(dtype).eps) ** 0.5


def _det_sign(H):
    Hs, _ = _prescale(H)  # no overflow of the determinant in float32
    return jnp.where(det3(Hs) < 0.0, -1.0, 1.0).astype(H.dtype)


def _decompose_core(H):
    """All four solutions for `H` of any positive scale and the physical sign.

    Returns `(R, t, n, scale, is_rotation)` with `H / scale = R[k] + t[k] n[k]^T` for each k.
    """
    H, c = _prescale(H)
    R, t, n, scale, is_rotation = _decompose_unscaled(H)
    return R, t, n, scale * c, is_rotation


def _decompose_unscaled(H):
    dtype = H.dtype
    eye = jnp.eye(3, dtype=dtype)
    M = mm(H.T, H)
    cube = jnp.cbrt(jnp.abs(det3(H)))
    cube = jnp.where(cube > 0.0, cube, 1.0)
    dev = smax(jnp.abs(jax.lax.stop_gradient(M / cube**2) - eye))
    # explicit finiteness: a max over a large vmap batch can drop a NaN
    is_rotation = (dev < _rotation_tol(dtype)) & sall(jnp.isfinite(M))

    # Generic branch, fed a harmless matrix when H is a rotation (double-where).
    M_safe = jnp.where(is_rotation, jnp.diag(jnp.array([4.0, 1.0, 0.25], dtype)), M)
    lam, V = eigh3(M_safe)  # ascending: lam[2] = sigma_1^2 (unnormalised)
    scale_generic = jnp.sqrt(lam[1])  # the middle singular value of H
    Hn = H / scale_generic
    s1sq = lam[2] / lam[1]
    s3sq = lam[0] / lam[1]
    v1, v2, v3 = V[:, 2], V[:, 1], V[:, 0]
    a = _safe_sqrt(1.0 - s3sq)
    b = _safe_sqrt(s1sq - 1.0)
    c = jnp.sqrt(s1sq - s3sq)

    def solution(u):
        U = jnp.stack([v2, u, jnp.cross(v2, u)], axis=1)
        Hv2, Hu = mv(Hn, v2), mv(Hn, u)
        W = jnp.stack([Hv2, Hu, jnp.cross(Hv2, Hu)], axis=1)
        R = mm(W, U.T)
        n = jnp.cross(v2, u)
        t = mv(Hn - R, n)
        return R, t, n

    R1, t1, n1 = solution((a * v1 + b * v3) / c)
    R2, t2, n2 = solution((a * v1 - b * v3) / c)
    R = jnp.stack([R1, R1, R2, R2])
    t = jnp.stack([t1, -t1, t2, -t2])
    n = jnp.stack([n1, -n1, n2, -n2])

    # Pure rotation (or no motion): H / det(H)^(1/3) is the rotation; t = 0, n undefined.
    R_rot = jnp.broadcast_to(H / cube, (4, 3, 3))
    R = jnp.where(is_rotation, R_rot, R)
    t = jnp.where(is_rotation, jnp.zeros_like(t), t)
    n = jnp.where(is_rotation, jnp.zeros_like(n), n)
    scale = jnp.where(is_rotation, cube, scale_generic)
    return R, t, n, scale, is_rotation


def _check_H_K(H, K):
    H = as_float(H)
    check_shape(H, (3, 3), "H")
    if K is not None:
        K = as_float(K)
        check_shape(K, (3, 3), "K")
        dtype = jnp.result_type(H, K)
        H, K = H.astype(dtype), K.astype(dtype)
        H = mm(inv3(K), mm(H, K))  # K^{-1} H K: the Euclidean homography (eq. (16))
    return H


def decompose_homography(
    H: Float[ArrayLike, "3 3"], K: Float[ArrayLike, "3 3"] | None = None
) -> tuple[Float[Array, "4 3 3"], Float[Array, "4 3"], Float[Array, "4 3"]]:
    """All four Euclidean decompositions $H \\propto R + t n^T$ (Chitrakaran et al., eq. (12)).

    Convention: the same as `cv2.decomposeHomographyMat(H, K)`. With `K`, `H` is a pixel
    homography and $K^{-1} H K$ is decomposed; without, `H` is already Euclidean. `H` may
    have any scale and sign: it is divided by its middle singular value and its sign is
    chosen so that $\\det H > 0$ (the two cameras on the same side of the plane). Then
    $H = R_k + t_k n_k^T$ for every k, $t$ is the translation divided by the distance to
    the plane, and solutions come in pairs $(R, t, n)$, $(R, -t, -n)$. Ordering:
    `[(R_a, t_a, n_a), (R_a, -t_a, -n_a), (R_b, t_b, n_b), (R_b, -t_b, -n_b)]`. For a pure
    rotation (no translation) OpenCV returns one solution with $t = n = 0$; here all four
    entries are that solution.

    **Arguments:**

    - `H`: a homography, shape (3, 3).
    - `K`: optional intrinsic matrix; if given, `H` is a pixel homography.

    No error path: a non-finite entry of `H` gives NaN outputs (NaN in, NaN out), never a
    finite decomposition. Near a pure rotation the accuracy is about sqrt(eps).

    **Returns:** `(R, t, n)` with shapes (4, 3, 3), (4, 3) and (4, 3).
    """
    H = _check_H_K(H, K)
    R, t, n, _, _ = _decompose_core(_det_sign(H) * H)
    return R, t, n


def _plane_basis(n):
    """Unit vectors a, b with a x b = n, for unit n; locally smooth in n."""
    m = jnp.abs(n)
    first = (m[0] <= m[1]) & (m[0] <= m[2])  # the axis of the smallest |n_k| (the first)
    second = ~first & (m[1] <= m[2])
    e = jnp.stack([first, second, ~first & ~second]).astype(n.dtype)
    a = jnp.cross(e, n)
    a = a / norm(a)
    b = jnp.cross(n, a)
    return a, b


def _inv_sqrt_2x2(S):
    """$S^{-1/2}$ of a 2x2 symmetric positive definite matrix, in closed form."""
    rd = jnp.sqrt(det2(S))
    root = (S + rd * jnp.eye(2, dtype=S.dtype)) / jnp.sqrt(S[0, 0] + S[1, 1] + 2.0 * rd)
    return inv2(root)


def _prescale(H):
    """`H / c` and `c`, c = max |H_ij|: the decompositions are invariant to the scale of
    `H`, and `det`, `H^T H` of a matrix scaled by 1e10 or 1e-10 overflow or underflow in
    float32. `c` is held constant for the derivative (exact, by that invariance)."""
    c = jax.lax.stop_gradient(smax(jnp.abs(H)))
    c = jnp.where(c > 0.0, c, 1.0)
    return H / c, c


def _known_normal_core(H, n):
    """`(R, x_h, scale)` for `H` of positive scale and physical sign and a unit normal `n`."""
    H, c = _prescale(H)
    R, x_h, scale = _known_normal_unscaled(H, n)
    return R, x_h, scale * c


def _known_normal_unscaled(H, n):
    a, b = _plane_basis(n)
    Mab = mm(H, jnp.stack([a, b], axis=1))  # = [R a, R b] * scale for exact data
    S = mm(Mab.T, Mab)
    scale = jnp.sqrt(jnp.sqrt(det2(S)))  # det(S)^(1/4); two square roots, not a pow
    Q = mm(Mab / scale, _inv_sqrt_2x2(S / scale**2))  # nearest orthonormal pair
    qa, qb = Q[:, 0], Q[:, 1]
    R = (
        qa[:, None] * a[None, :]
        + qb[:, None] * b[None, :]
        + jnp.cross(qa, qb)[:, None] * n[None, :]
    )
    x_h = mv(H / scale - R, n)  # H n = R n + x_h (n . n), eq. (12)
    return barrier((R, x_h, scale))  # once per frame, as in `_dlt`


def decompose_homography_known_normal(
    H: Float[ArrayLike, "3 3"],
    n_star: Float[ArrayLike, "3"],
    K: Float[ArrayLike, "3 3"] | None = None,
) -> tuple[Float[Array, "3 3"], Float[Array, "3"]]:
    """The decomposition $H \\propto \\bar R + \\bar x_h n^{*T}$ for a known normal $n^*$.

    Smooth in `H` everywhere, including the identity (no motion), where the general
    method is not differentiable. With noisy `H`, $[Ha, Hb]$ is replaced by the nearest
    orthonormal pair (its polar factor), so $\\bar R$ is always a rotation.

    Convention: as `decompose_homography`: scale by the length `H` keeps on the plane
    $\\perp n^*$, sign so that $\\det H > 0$; with `K`, `H` is a pixel homography.

    **Arguments:**

    - `H`: a homography, shape (3, 3).
    - `n_star`: the plane normal in the reference camera frame (normalised here).
    - `K`: optional intrinsic matrix.

    No error path: a non-finite entry of `H` or `n_star` gives NaN outputs (NaN in, NaN
    out), never a finite decomposition.

    **Returns:** `(R_bar, x_h)`.
    """
    H = _check_H_K(H, K)
    n_star = as_float(n_star)
    check_shape(n_star, (3,), "n_star")
    n_star = n_star.astype(H.dtype)
    n = n_star / jnp.linalg.norm(n_star)
    R, x_h, _ = _known_normal_core(_det_sign(H) * H, n)
    return R, x_h


def select_solution(
    R: Float[ArrayLike, "4 3 3"],
    t: Float[ArrayLike, "4 3"],
    n: Float[ArrayLike, "4 3"],
    m_ref: Float[ArrayLike, "k 3"],
    n_prior: Float[ArrayLike, "3"],
):
    """The physical solution among the four of `decompose_homography`.

    First the reference points must lie in front of the plane's camera side: $d^* =
    n^{*T} \\bar m_i^* > 0$ (eq. (4)), that is $n^T m_i^* > 0$ for every normalized
    reference point $m_i^*$. This removes one of each $(R, \\pm t, \\pm n)$ pair. Of the two
    left, the one whose normal is closest to `n_prior` is returned.

    **Arguments:**

    - `R`, `t`, `n`: the four solutions.
    - `m_ref`: normalized reference points $[x, y, 1]$, shape (k, 3).
    - `n_prior`: a prior plane normal (need not be unit).

    **Returns:** `(R, t, n, ok)`, with `ok` false if no solution passes the visibility test
    or if the inputs are not finite (a NaN anywhere: never `ok` with NaN or with a choice a
    NaN decided).
    """
    R, t, n, m_ref, n_prior = (as_float(x) for x in (R, t, n, m_ref, n_prior))
    check_shape(R, (4, 3, 3), "R")
    check_shape(t, (4, 3), "t")
    check_shape(n, (4, 3), "n")
    check_shape(m_ref, (None, 3), "m_ref")
    check_shape(n_prior, (3,), "n_prior")
    visible = jnp.all(m_ref @ n.T > 0.0, axis=0)
    score = jnp.where(visible, n @ n_prior, -jnp.inf)
    k = jnp.argmax(score)
    # explicit: a NaN in `n` fails the visibility test, but one in R, t, m_ref or the prior
    # could still pick a solution; and no reduction may be trusted to keep a NaN
    finite = jnp.all(jnp.isfinite(R)) & jnp.all(jnp.isfinite(t)) & jnp.all(jnp.isfinite(n))
    finite = finite & jnp.all(jnp.isfinite(m_ref)) & jnp.all(jnp.isfinite(n_prior))
    return R[k], t[k], n[k], jnp.any(visible) & finite
