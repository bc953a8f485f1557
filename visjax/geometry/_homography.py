"""Homography from point correspondences: normalized DLT and the products alpha_i g33.

Source: Chitrakaran et al., section 3, eqs. (12), (16) and (17).

Convention: the projective homography $G$ maps reference pixels to current pixels,
$p_i = \\alpha_i G p_i^*$ (eq. (16)), with $p = [u, v, 1]^T$ and $\\alpha_i = z_i^*/z_i$.
`find_homography` returns $G_n = G / g_{33}$ (eq. (17)) in its field `G`, the same
normalisation as `cv2.findHomography`. The Euclidean homography acts on normalized
coordinates, $H = A^{-1} G A$.
"""

from typing import final

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
from jaxtyping import Array, ArrayLike, Float

from .._results import RESULTS, intrinsics_ok, raise_or_keep
from .._small import (
    barrier,
    det3,
    inv3,
    mm,
    mv,
    sadjugate,
    sall,
    scross,
    sdot,
    smax,
    smm,
    ssum,
    total,
)
from .._util import as_float, check_points, check_shape
from ._camera import to_homogeneous


def _rcond_tol(dtype) -> float:
    # Reject designs whose reciprocal condition number is below this. The relative error
    # of the solution is about eps / rcond, and the decomposition amplifies it further:
    # sqrt(eps) in float64 (1.5e-8: errors near 1e-8), eps^(1/3) in float32 (4.9e-3; with
    # sqrt(eps), 3.4e-4, near-collinear points passed with errors in H up to 5e-2).
    eps = float(jnp.finfo(dtype).eps)
    return eps**0.5 if eps < 1e-10 else eps ** (1.0 / 3.0)


def _normalising_transform(p, w=None):
    """Hartley's similarity: centroid to the origin, RMS distance to sqrt(2); with weights
    `w` (0 or 1 per point), over the points of weight 1 only."""
    if w is None:
        c = ssum(p, 0) / p.shape[0]
        d = p - c[None, :]
        ms = ssum(d**2) / p.shape[0]
    else:
        total = jnp.maximum(ssum(w), 1.0)
        c = ssum(w[:, None] * p, 0) / total
        d = (p - c[None, :]) * w[:, None]
        ms = ssum(d**2) / total
    ms_safe = jnp.where(ms > 0.0, ms, 1.0)
    s = jnp.sqrt(2.0 / ms_safe)
    return c, s, d * s


# The four-point path works on scalars (lists of per-frame numbers), not on small arrays:
# under `vmap` every operation is then one elementwise operation over the batch, which
# XLA's CPU compiler fuses into a few loops; the same formulas on (4, 2) and (3, 3) arrays
# compile to ~40 small fusions of slices and concatenations, each a pass over the batch.


def _normalising_scalars(u, v, w=None):
    """`_normalising_transform` on scalars: `(c_u, c_v, s, x, y)` with x, y the lists of
    normalised coordinates."""
    if w is None:
        count = float(len(u))
        cu, cv = total(u) / count, total(v) / count
        du = [a - cu for a in u]
        dv = [b - cv for b in v]
    else:
        count = jnp.maximum(total(w), 1.0)
        cu = total([wi * a for wi, a in zip(w, u)]) / count
        cv = total([wi * b for wi, b in zip(w, v)]) / count
        du = [(a - cu) * wi for a, wi in zip(u, w)]
        dv = [(b - cv) * wi for b, wi in zip(v, w)]
    ms = total([a * a + b * b for a, b in zip(du, dv)]) / count
    s = jnp.sqrt(2.0 / jnp.where(ms > 0.0, ms, 1.0))
    return cu, cv, s, [a * s for a in du], [b * s for b in dv]


def _min_triangle_area(x, y):
    """The smallest of the four triangle areas of four 2D points."""

    def area(i, j, k):
        return jnp.abs((x[j] - x[i]) * (y[k] - y[i]) - (y[j] - y[i]) * (x[k] - x[i]))

    a = (area(0, 1, 2), area(0, 1, 3), area(0, 2, 3), area(1, 2, 3))
    return 0.5 * jnp.minimum(jnp.minimum(a[0], a[1]), jnp.minimum(a[2], a[3]))


_SQUARE = ((-1.0, 1.0, 1.0, -1.0), (-1.0, -1.0, 1.0, 1.0))  # x and y of a unit square


def _projective_basis(x, y):
    """$B$ (rows of scalars) with $B e_i \\sim p_i$ ($i = 1, 2, 3$) and $B (e_1 + e_2 + e_3)
    \\sim p_4$ for four points, no three collinear: the columns $p_1, p_2, p_3$
    (homogeneous) scaled by $\\lambda = \\mathrm{adj}([p_1 p_2 p_3])\\, p_4 \\propto
    [p_1 p_2 p_3]^{-1} p_4$. The homography of four correspondences is then
    $B_{cur} B_{ref}^{-1} \\propto B_{cur}\\, \\mathrm{adj}(B_{ref})$, the same as the exact
    DLT of eq. (17)."""
    c = [(x[i], y[i], 1.0) for i in range(3)]
    p4 = (x[3], y[3], 1.0)
    lam = (sdot(scross(c[1], c[2]), p4), sdot(scross(c[2], c[0]), p4), sdot(scross(c[0], c[1]), p4))
    return [[lam[j] * c[j][i] for j in range(3)] for i in range(3)]


def _undo_normalisation(G, ref, cur):
    """$G = T_{cur}^{-1} \\hat G T_{ref}$ for rows of scalars, $T [u, v, 1]^T = [s (u - c_u),
    s (v - c_v), 1]^T$, written out: `ref` and `cur` are `(c_u, c_v, s)`."""
    cu, cv, s = ref
    X = [[g[0] * s, g[1] * s, g[2] - s * (cu * g[0] + cv * g[1])] for g in G]
    cu, cv, s = cur
    return [
        [X[0][j] / s + cu * X[2][j] for j in range(3)],
        [X[1][j] / s + cv * X[2][j] for j in range(3)],
        X[2],
    ]


def _design(q_ref, q_cur):
    """The 2n x 8 inhomogeneous DLT system $M h = b$ for $\\hat g_{33} = 1$.

    Eq. (17) for one point gives three equations in $G_n$ and $\\alpha_i g_{33}$; the third,
    $\\alpha_i g_{33} = 1 / (G_n p_i^*)_3$, eliminates the depth product from the first two.
    """
    x0, y0 = q_ref[:, 0], q_ref[:, 1]
    x1, y1 = q_cur[:, 0], q_cur[:, 1]
    one = jnp.ones_like(x0)
    zero = jnp.zeros_like(x0)
    rows_u = jnp.stack([x0, y0, one, zero, zero, zero, -x1 * x0, -x1 * y0], axis=1)
    rows_v = jnp.stack([zero, zero, zero, x0, y0, one, -y1 * x0, -y1 * y0], axis=1)
    M = jnp.concatenate([rows_u, rows_v], axis=0)
    b = jnp.concatenate([x1, y1], axis=0)
    return M, b


def _four_point(p_ref, p_cur, w, ref_bad, cur_bad, tol):
    """The exactly determined fit of four correspondences, on scalars: `(G, degenerate)`
    with G the rows of $T_{cur}^{-1} \\hat G T_{ref}$."""
    ws = None if w is None else [w[i] for i in range(4)]
    ref = _normalising_scalars([p_ref[i, 0] for i in range(4)], [p_ref[i, 1] for i in range(4)], ws)
    cur = _normalising_scalars([p_cur[i, 0] for i in range(4)], [p_cur[i, 1] for i in range(4)], ws)
    # A homography exists and is unique iff no three of the four points are collinear (or
    # coincident) in either image. Check the four triangle areas in the normalized
    # coordinates (RMS radius sqrt(2), so a good quad has areas of order 1); cheaper and
    # sharper than a condition number. Degenerate inputs are swapped for a square first, so
    # that neither the value nor the gradient is NaN (the result code says "bad"); each side
    # on its own, so that a reference shared by a batch stays unbatched. The barrier: the
    # predicate once per frame (XLA would recompute the areas into every entry it selects).
    ref_swap = (_min_triangle_area(ref[3], ref[4]) < tol) | ref_bad
    cur_swap = barrier((_min_triangle_area(cur[3], cur[4]) < tol) | cur_bad)

    def safe(x, y, swap):
        return (
            [jnp.where(swap, a, b) for a, b in zip(_SQUARE[0], x)],
            [jnp.where(swap, a, b) for a, b in zip(_SQUARE[1], y)],
        )

    # the projective-basis construction in closed form (two 3x3 adjugates) instead of
    # solving the 8x8 system
    B_cur = _projective_basis(*safe(cur[3], cur[4], cur_swap))
    B_ref = _projective_basis(*safe(ref[3], ref[4], ref_swap))
    G_hat = smm(B_cur, sadjugate(B_ref))
    size = jnp.sqrt(total([g * g for row in G_hat for g in row]))
    G_hat = [[g / size for g in row] for row in G_hat]  # its scale is arbitrary: unit norm
    # points collinear in one image only: a singular G (a predicate: no gradient)
    Gs = [[jax.lax.stop_gradient(g) for g in row] for row in G_hat]
    norm2 = total([g * g for row in Gs for g in row])
    singular = ~(jnp.abs(sdot(Gs[0], scross(Gs[1], Gs[2]))) > tol * norm2 * jnp.sqrt(norm2))
    degenerate = ref_swap | cur_swap | singular
    return _undo_normalisation(G_hat, ref[:3], cur[:3]), degenerate


def _dlt(p_ref, p_cur, visible=None):
    """Normalized DLT. Returns `(G_n, result)`; `G_n` is finite whatever the input.

    `visible` (n,) bool, optional: only these points enter (the others' current pixels may
    be anything, NaN included: features that dropped out of view)."""
    dtype = jnp.result_type(p_ref, p_cur)
    n = p_ref.shape[0]
    w = None
    if visible is not None:
        w = visible.astype(dtype)
        p_cur = jnp.where(visible[:, None], p_cur, 0.0)
    # each side made finite on its own, so that a reference shared by a batch of current
    # frames is normalised once, not per frame; materialised (a barrier) once per frame
    ref_bad = ~sall(jnp.isfinite(p_ref))
    cur_bad = ~sall(jnp.isfinite(p_cur))
    p_ref = jnp.where(ref_bad, jnp.zeros_like(p_ref), p_ref)
    p_cur, cur_bad = barrier((jnp.where(cur_bad, jnp.zeros_like(p_cur), p_cur), cur_bad))
    nonfinite = ref_bad | cur_bad
    tol = _rcond_tol(dtype)
    if n == 4:
        G, degenerate = _four_point(p_ref, p_cur, w, ref_bad, cur_bad, tol)
        # four points, one of them out of view: no homography
        n_visible_ok = jnp.array(True) if visible is None else sall(visible)
    else:
        c_ref, s_ref, q_ref = _normalising_transform(p_ref, w)
        c_cur, s_cur, q_cur = _normalising_transform(p_cur, w)
        M, b = _design(q_ref, q_cur)
        if w is not None:
            ww = jnp.concatenate([w, w])
            M, b = M * ww[:, None], b * ww
        # Over-determined: degeneracy from the conditioning of the normalized design (a
        # predicate only: no gradient flows through the singular values). Least squares by
        # QR: unlike an SVD or eigh of M^T M, its derivative exists when singular values
        # repeat (a noise-free symmetric target, for instance).
        sv = jnp.linalg.svd(jax.lax.stop_gradient(M), compute_uv=False)
        degenerate = ~(sv[-1] > tol * sv[0])
        M_dummy = jnp.concatenate([jnp.eye(8, dtype=dtype), jnp.zeros((2 * n - 8, 8), dtype)])
        M_safe = jnp.where(degenerate | nonfinite, M_dummy, M)
        Q, Rq = jnp.linalg.qr(M_safe)
        h = jsl.solve_triangular(Rq, Q.T @ b, lower=False)
        G_hat = jnp.concatenate([h, jnp.ones((1,), dtype)]).reshape(3, 3)
        # Points collinear in one image only can still give a solvable system, but its
        # solution is a singular G: no homography maps them.
        G_hat_ng = jax.lax.stop_gradient(G_hat)
        norm2 = ssum(G_hat_ng**2)
        degenerate = degenerate | ~(jnp.abs(det3(G_hat_ng)) > tol * norm2 * jnp.sqrt(norm2))
        n_visible_ok = jnp.array(True)
        G = _undo_normalisation(
            [[G_hat[i, j] for j in range(3)] for i in range(3)],
            (c_ref[0], c_ref[1], s_ref),
            (c_cur[0], c_cur[1], s_cur),
        )

    bad = barrier(degenerate | nonfinite | ~n_visible_ok)  # once per frame
    G = [[jnp.where(bad, float(i == j), G[i][j]) for j in range(3)] for i in range(3)]
    g33 = G[2][2]
    # g33 = 0: the image origin maps to infinity. Compared with the other terms of the
    # third row at the data's own scale (w_i = g31 u_i + g32 v_i + g33), not with |G|, whose
    # translation entries grow with the pixel coordinates (version 1 called a pure
    # translation of pixels near 4e5 "g33 = 0" in float32).
    extent = smax(jnp.abs(p_ref), 0)
    row = jnp.abs(G[2][0]) * extent[0] + jnp.abs(G[2][1]) * extent[1] + jnp.abs(g33)
    g33_zero = ~(jnp.abs(g33) > 100.0 * jnp.finfo(dtype).eps * row)
    g33_safe = jnp.where(g33_zero, 1.0, g33)
    G_n = [[G[i][j] / g33_safe for j in range(3)] for i in range(3)]
    G_n[2][2] = jnp.ones_like(g33)  # exactly 1, not 1 - ulp
    G_n = jnp.stack([jnp.stack(r) for r in G_n])

    result = RESULTS.where(
        nonfinite,
        RESULTS.nonfinite_pixels,
        RESULTS.where(
            bad,
            RESULTS.degenerate_points,
            RESULTS.where(g33_zero, RESULTS.g33_zero, RESULTS.successful),
        ),
    )
    # materialised once per frame: XLA's CPU fusions would otherwise recompute the whole
    # fit into every entry of every consumer
    return barrier(G_n), result


def _check_pair(p_ref, p_cur):
    p_ref = check_points(p_ref, "p_ref")
    p_cur = check_points(p_cur, "p_cur")
    if p_ref.shape != p_cur.shape:
        raise ValueError(
            "`p_ref` and `p_cur` must hold the same points: got shapes "
            f"{tuple(p_ref.shape)} and {tuple(p_cur.shape)}."
        )
    dtype = jnp.result_type(p_ref, p_cur)
    return p_ref.astype(dtype), p_cur.astype(dtype)


@final
class Homography(eqx.Module):
    """What `find_homography` returns.

    **Fields:**

    - `G`: the normalized projective homography $G_n = G / g_{33}$ of eq. (17), with
        `p_cur ~ G p_ref` and `G[2, 2] == 1`; all NaN when `result` is not successful.
    - `result`: a `RESULTS` item (always `successful` when the call was made with
        `throw=True`, since a failure raises): `nonfinite_pixels`, `degenerate_points` or
        `g33_zero` otherwise.
    """

    G: Float[Array, "3 3"]
    result: RESULTS


def find_homography(
    p_ref: Float[ArrayLike, "n 2"], p_cur: Float[ArrayLike, "n 2"], *, throw: bool = True
) -> Homography:
    """The normalized projective homography $G_n$ with $p_i \\sim G_n p_i^*$ (eq. (17)).

    A normalized (Hartley) DLT: both point sets are moved to their centroid and scaled to an
    RMS distance of $\\sqrt 2$, the linear system of eq. (17) with $g_{33} = 1$ is solved
    (exactly for 4 points, in the least-squares sense for more), and the normalisation is
    undone.

    Convention: `p_cur ~ G p_ref`, and `G[2, 2] == 1`, as `cv2.findHomography(p_ref, p_cur, 0)`
    returns for exact correspondences.

    Differentiable: `jax.grad` of `G` with respect to `p_ref` and `p_cur` is finite, a
    failed frame's included (degenerate inputs are swapped for a square before the fit, so
    a failed frame of a `vmap` batch gives a zero gradient, not NaN).

    **Arguments:**

    - `p_ref`: reference pixels $p_i^*$, shape (n, 2), n >= 4.
    - `p_cur`: current pixels $p_i$, shape (n, 2).
    - `throw`: if `True` (default), collinear or coincident points, non-finite pixels or a
        vanishing $g_{33}$ raise at run time; with `False` the failure is reported in
        `result` (and `G` is all NaN), so that one degenerate frame of a `jax.vmap` batch
        leaves the others intact.

    **Returns:** a `Homography` with `G` ($G_n$, shape (3, 3)) and `result`.
    """
    p_ref, p_cur = _check_pair(p_ref, p_cur)
    if not isinstance(throw, bool):
        raise ValueError(f"`throw` must be a bool; got {throw!r}.")
    return _find_homography(p_ref, p_cur, throw)


@eqx.filter_jit  # one program per shape and `throw` outside `jit`; its error_if raised as
# equinox's runtime error
def _find_homography(p_ref, p_cur, throw: bool):
    G_n, result = _dlt(p_ref, p_cur)
    G_n = jnp.where(result == RESULTS.successful, G_n, jnp.nan)  # never a finite placeholder
    return raise_or_keep(result, Homography(G=G_n, result=result), throw)


def alpha_g33(G_n: Float[ArrayLike, "3 3"], p_ref: Float[ArrayLike, "n 2"]) -> Float[Array, " n"]:
    """The products $\\alpha_i g_{33}$ of eq. (17), from its third row.

    $p_i = \\alpha_i g_{33} G_n p_i^*$ and $p_i$ has third entry 1, so
    $\\alpha_i g_{33} = 1 / (G_n p_i^*)_3$.

    **Arguments:**

    - `G_n`: the normalized projective homography.
    - `p_ref`: reference pixels $p_i^*$, shape (n, 2).

    **Returns:** $\\alpha_i g_{33}$ for each point, shape (n,). A point whose image lies at
    infinity gets `inf`; `euclidean_reconstruction` reports it as behind the camera. No
    error path: NaN in `G_n` or in a pixel gives NaN for the points it reaches (NaN in,
    NaN out).
    """
    G_n = as_float(G_n)
    check_shape(G_n, (3, 3), "G_n")
    p_ref = check_points(p_ref, "p_ref", min_points=1)
    w = mv(to_homogeneous(p_ref), G_n[2])
    return 1.0 / w


def euclidean_homography(
    G: Float[ArrayLike, "3 3"], A: Float[ArrayLike, "3 3"]
) -> Float[Array, "3 3"]:
    """The Euclidean homography $H = A^{-1} G A$ from the projective one (eq. (16)).

    Convention: the scale of `G` carries over: with $G_n = G/g_{33}$ this returns
    $H / g_{33}$.

    No error path: an unusable `A` (non-finite, or a zero focal length) gives an all-NaN
    `H`, and a NaN or inf entry of `G` gives NaN or inf in the entries it reaches (NaN in,
    NaN out), never a finite value.
    """
    G = as_float(G)
    A = as_float(A)
    check_shape(G, (3, 3), "G")
    check_shape(A, (3, 3), "A")
    ok = intrinsics_ok(A)
    A = jnp.where(ok, A, jnp.eye(3, dtype=A.dtype))  # no inf, no NaN gradient
    return jnp.where(ok, mm(inv3(A), mm(G, A)), jnp.nan)


def projective_homography(
    H: Float[ArrayLike, "3 3"], A: Float[ArrayLike, "3 3"]
) -> Float[Array, "3 3"]:
    """The projective homography $G = A H A^{-1}$ of eq. (16).

    No error path, as `euclidean_homography`: an unusable `A` gives an all-NaN `G`; NaN in
    `H` gives NaN out.
    """
    H = as_float(H)
    A = as_float(A)
    check_shape(H, (3, 3), "H")
    check_shape(A, (3, 3), "A")
    ok = intrinsics_ok(A)
    A = jnp.where(ok, A, jnp.eye(3, dtype=A.dtype))
    return jnp.where(ok, mm(mm(A, H), inv3(A)), jnp.nan)
