"""Homography from point correspondences with outliers: a batched RANSAC followed by an
iteratively reweighted refinement.

Sources: Fischler and Bolles, "Random sample consensus: a paradigm for model fitting with
applications to image analysis and automated cartography" (the hypothesise-and-verify
loop); Hartley and Zisserman, "Multiple View Geometry in Computer Vision" (the normalised
DLT, and its algebraic residual divided by the third homogeneous coordinate as the
geometric one); Huber, "Robust estimation of a location parameter" (the weights of the
refinement).

Convention: `H` maps `src` to `dst`, $[u', v', 1]^T \\sim H [u, v, 1]^T$, with
`H[2, 2] == 1`, the direction and scale of `cv2.findHomography(src, dst, ...)` and of
`find_homography(p_ref=src, p_cur=dst).G`. Errors are forward transfer errors in the
pixels of `dst`, $e_i = \\| \\mathrm{dst}_i - \\pi(H\\, \\mathrm{src}_i) \\|$ (OpenCV's
`ransacReprojThreshold` is the same quantity).
"""

from typing import final

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
from jaxtyping import Array, ArrayLike, Bool, Float, PRNGKeyArray, Real

from .._results import RESULTS, raise_or_keep
from .._small import det3
from .._util import as_float, check_points, covariance
from ._homography import (
    _design,
    _four_point,
    _normalising_transform,
    _rcond_tol,
    _undo_normalisation,
)

# The refinement's fixed number of reweighted least-squares steps after the first DLT. Each
# step shrinks the change by about 10x; on 200 scenes of 100 points with 0 to 40% outliers
# the last of 5 moved the image corners by < 2e-5 px (the noise moves them by ~0.4 px).
_REFINE_STEPS = 5
# The Huber scale as a fraction of the inlier threshold: residuals below threshold / 2 get
# full weight (least squares), those between it and the threshold a weight k / e.
_HUBER_FRACTION = 0.5


@final
class RobustHomography(eqx.Module):
    """What `find_homography_robust` returns.

    **Fields:**

    - `H`: the homography mapping `src` to `dst`, with `H[2, 2] == 1`; all NaN when
        `result` is not successful.
    - `inliers`: which correspondences `H` transfers to within the threshold (and in front:
        with the sign of the other inliers' third homogeneous coordinate), shape (n,); all
        `False` when `result` is not successful.
    - `result`: a `RESULTS` item (always `successful` when the call was made with
        `throw=True`, since a failure raises).
    - `cov`: the covariance of the eight free entries of `H` (row by row, $h_{33} = 1$
        fixed), $\\hat\\sigma^2 (J^TJ)^{-1}$ of the inliers' transfer errors at `H` ($J$
        their Jacobian in the eight entries, $\\hat\\sigma^2$ their sum of squares over
        $2m - 8$ for $m$ inliers); shape (8, 8), NaN when `result` is not successful.
    """

    H: Float[Array, "3 3"]
    inliers: Bool[Array, " n"]
    result: RESULTS
    cov: Float[Array, "8 8"]


def find_homography_robust(
    key: PRNGKeyArray,
    src: Float[ArrayLike, "n 2"],
    dst: Float[ArrayLike, "n 2"],
    *,
    iterations: int = 500,
    threshold_px: int | float | Real[ArrayLike, ""] = 3.0,
    throw: bool = True,
) -> RobustHomography:
    """The homography of n >= 4 point correspondences of a plane, some of them outliers.

    Two stages, both of fixed size (so that it runs under `jax.jit` and `jax.vmap` over
    frames, and the same key gives the same answer):

    1. RANSAC (Fischler and Bolles): `iterations` minimal samples of 4 distinct
        correspondences drawn from `key` (uniformly, without replacement within a sample),
        each fitted exactly by the four-point construction of `find_homography`, all of
        them at once (`vmap` over the hypotheses). A sample is rejected when three of its
        points are collinear in either image (`find_homography`'s test), or when its
        homography puts its own points on both sides of the line at infinity: the
        products $\\alpha_i g_{33} = 1 / (G p_i^*)_3$ of true correspondences all have one
        sign (Chitrakaran et al., eq. (17), with $\\alpha_i = z_i^*/z_i > 0$). Each
        hypothesis is scored by its inliers, the correspondences with forward transfer
        error $e_i$ < `threshold_px` and third coordinate of that sign; the best has the
        most inliers, ties broken by the smallest sum of their $e_i^2$, then by the lowest
        index.
    2. Refinement: the normalised DLT (Hartley and Zisserman) on the best hypothesis'
        inliers, then 5 steps of iteratively reweighted least squares. Each step
        re-estimates the inlier set from the current $H$ (as in stage 1) and solves the
        normalised DLT with the rows of correspondence $i$ weighted by
        $\\sqrt{w_i} / |(H\\, \\mathrm{src}_i)_3|$: the division turns the DLT's algebraic
        residual into the transfer error $e_i$ (Hartley and Zisserman), and $w_i$ is
        Huber's weight on it, $w_i = \\min(1, k / e_i)$ with scale $k$ =
        `threshold_px` / 2, zero for the outliers. The last step's inliers are returned.

    Convention: `dst ~ H src`, `H[2, 2] == 1`, as `cv2.findHomography(src, dst, method)`.

    Differentiable: `jax.grad` of `H` with respect to `src` and `dst` flows through the
    refinement (the DLT solves and the weights); the inlier sets are piecewise constant,
    and the RANSAC stage carries no gradient.

    **Arguments:**

    - `key`: a PRNG key (`jax.random.key(seed)`); the samples are a function of it alone.
    - `src`: pixels in the first image, shape (n, 2), n >= 4.
    - `dst`: the corresponding pixels in the second image, shape (n, 2).
    - `iterations`: the number of RANSAC hypotheses (static: it sets the shapes). 500
        draws an all-inlier sample with probability 0.99 up to about 69% outliers,
        $1 - (1 - (1 - \\epsilon)^4)^{500} \\geq 0.99$.
    - `threshold_px`: the inlier threshold on the forward transfer error, in pixels of
        `dst` (OpenCV's `ransacReprojThreshold`); may be traced (a traced threshold that is
        not positive finds no inliers: `too_few_inliers`).
    - `throw`: if `True` (default), a failure raises at run time (non-finite pixels, no
        hypothesis that is not degenerate, fewer than 4 inliers or inliers that do not fix
        a homography, a vanishing $h_{33}$); with `False` it is reported in `result`.

    **Returns:** a `RobustHomography` with `H`, `inliers` and `result`. As any RANSAC, it
    succeeds whenever some sample of 4 fits: with no plane among the correspondences the
    inliers are those 4 and few more, so check `inliers.sum()` against what the scene
    should give.
    """
    src = check_points(src, "src")
    dst = check_points(dst, "dst")
    if src.shape != dst.shape:
        raise ValueError(
            "`src` and `dst` must hold the same correspondences: got shapes "
            f"{tuple(src.shape)} and {tuple(dst.shape)}."
        )
    dtype = jnp.result_type(src, dst)
    src, dst = src.astype(dtype), dst.astype(dtype)
    key = jnp.asarray(key)
    typed = jnp.issubdtype(key.dtype, jax.dtypes.prng_key)
    if (typed and key.shape != ()) or (not typed and (key.shape != (2,) or key.dtype != "uint32")):
        raise ValueError(
            "`key` must be one PRNG key (`jax.random.key(seed)`, or a raw uint32 key of "
            f"shape (2,)); got {key.dtype} of shape {tuple(key.shape)}. For a batch of "
            "frames, `jax.vmap` the function."
        )
    if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 1:
        raise ValueError(f"`iterations` must be a positive int; got {iterations!r}.")
    threshold = as_float(threshold_px)
    if threshold.shape != ():
        raise ValueError(f"`threshold_px` must be a scalar; got shape {tuple(threshold.shape)}.")
    with jax.ensure_compile_time_eval():  # a concrete threshold is checked, also in jit
        positive = threshold > 0.0
    if not isinstance(positive, jax.core.Tracer) and not bool(positive):
        raise ValueError(f"`threshold_px` must be positive; got {float(threshold)}.")
    return _robust(key, src, dst, threshold.astype(dtype), iterations, throw)


def _samples(key, n, iterations):
    """`iterations` rows of 4 distinct indices in [0, n), each row uniform over the ordered
    4-tuples: the k-th index is drawn from the n - k not yet taken, by counting up past the
    taken ones in increasing order."""
    # one 32-bit draw per index, reduced modulo the range: a bias below n / 2^32
    bits = jax.random.bits(key, (iterations, 4), jnp.uint32)
    r = (bits % jnp.array([[n, n - 1, n - 2, n - 3]], jnp.uint32)).astype(jnp.int32)

    def skip(x, taken_sorted):
        for t in taken_sorted:
            x = jnp.where(x >= t, x + 1, x)
        return x

    i0 = r[:, 0]
    i1 = skip(r[:, 1], [i0])
    lo, hi = jnp.minimum(i0, i1), jnp.maximum(i0, i1)
    i2 = skip(r[:, 2], [lo, hi])
    a, c = jnp.minimum(lo, i2), jnp.maximum(hi, i2)
    b = i0 + i1 + i2 - a - c
    i3 = skip(r[:, 3], [a, b, c])
    return jnp.stack([i0, i1, i2, i3], axis=1)


def _fit4(s4, d4, tol):
    """The four-point homography of one sample (any scale, its sign making $(G s_1)_3 > 0$)
    and whether the sample is usable: no three points collinear in either image
    (`find_homography`'s test), and all four points in front, $(G s_i)_3 > 0$."""
    G, degenerate = _four_point(s4, d4, None, False, False, tol)
    G = jnp.stack([jnp.stack(r) for r in G])
    w = G[2, 0] * s4[:, 0] + G[2, 1] * s4[:, 1] + G[2, 2]
    G = jnp.where(w[0] < 0.0, -G, G)
    oriented = jnp.all(w > 0.0) | jnp.all(w < 0.0)
    return G, ~degenerate & oriented


def _transfer(G, src, dst):
    """Squared forward transfer errors $e_i^2$ (inf where a point maps to infinity) and the
    third homogeneous coordinates $(G\\, \\mathrm{src}_i)_3$."""
    u, v = src[:, 0], src[:, 1]
    x = G[0, 0] * u + G[0, 1] * v + G[0, 2]
    y = G[1, 0] * u + G[1, 1] * v + G[1, 2]
    w = G[2, 0] * u + G[2, 1] * v + G[2, 2]
    finite = w != 0.0
    w_safe = jnp.where(finite, w, 1.0)
    e2 = (x / w_safe - dst[:, 0]) ** 2 + (y / w_safe - dst[:, 1]) ** 2
    return jnp.where(finite, e2, jnp.inf), w


def _inliers(G, src, dst, t2, sign=None):
    """Inliers of `G` (transfer error below the threshold, third coordinate of the sign of
    the majority) with their squared errors and third coordinates."""
    e2, w = _transfer(G, src, dst)
    close = e2 < t2
    if sign is None:
        sign = jnp.where(jnp.sum(jnp.where(close, w, 0.0)) < 0.0, -1.0, 1.0).astype(w.dtype)
    return close & (sign * w > 0.0), e2, sign * w


def _weighted_dlt(src, dst, weight, tol):
    """The normalised DLT with row weights `weight` (>= 0; the points of weight 0 take no
    part, also not in the normalisation). Returns `(G, degenerate)`, `G` finite with
    $\\hat g_{33} = 1$ in the normalised coordinates."""
    dtype = src.dtype
    n = src.shape[0]
    used = (weight > 0.0).astype(dtype)
    c_ref, s_ref, q_ref = _normalising_transform(src, used)
    c_cur, s_cur, q_cur = _normalising_transform(dst, used)
    M, b = _design(q_ref, q_cur)
    ww = jnp.concatenate([weight, weight])
    M, b = M * ww[:, None], b * ww
    # Degeneracy from the conditioning of the weighted, normalised design (a predicate: no
    # gradient), by the eigenvalues of its 8 x 8 Gram matrix (a quarter of the time of the
    # design's SVD under `vmap`): sigma_min / sigma_max > tol, as `find_homography`, but
    # never finer than 10 sqrt(eps), the eigenvalues' own accuracy (eps lambda_max).
    M_ng = jax.lax.stop_gradient(M)
    lam = jnp.linalg.eigvalsh(M_ng.T @ M_ng)
    eps = float(jnp.finfo(dtype).eps)
    degenerate = ~(lam[0] > max(tol**2, 100.0 * eps) * lam[-1])
    M_dummy = jnp.concatenate([jnp.eye(8, dtype=dtype), jnp.zeros((2 * n - 8, 8), dtype)])
    M_safe = jnp.where(degenerate, M_dummy, M)
    Q, Rq = jnp.linalg.qr(M_safe)
    h = jsl.solve_triangular(Rq, Q.T @ b, lower=False)
    G_hat = jnp.concatenate([h, jnp.ones((1,), dtype)]).reshape(3, 3)
    # a solvable system can still give a singular G (inliers collinear in one image only)
    G_ng = jax.lax.stop_gradient(G_hat)
    norm2 = jnp.sum(G_ng**2)
    degenerate = degenerate | ~(jnp.abs(det3(G_ng)) > tol * norm2 * jnp.sqrt(norm2))
    G = _undo_normalisation(
        [[G_hat[i, j] for j in range(3)] for i in range(3)],
        (c_ref[0], c_ref[1], s_ref),
        (c_cur[0], c_cur[1], s_cur),
    )
    G = jnp.stack([jnp.stack(r) for r in G])
    return jnp.where(degenerate, jnp.eye(3, dtype=dtype), G), degenerate


def _best_hypothesis(G_h, valid, src, dst, t2):
    """The index of the hypothesis with the most inliers (ties: the smallest sum of their
    squared errors, then the lowest index) among the valid ones, and whether there is one.

    The score is the count minus the inliers' summed $e_i^2 / (n t^2)$, a tie-breaker in
    [0, 1); a hypothesis that is not valid scores -1."""
    n = src.shape[0]
    scale = 1.0 / (n * jnp.where(t2 > 0.0, t2, 1.0))

    def errors(G):
        e2, w = _transfer(G, src, dst)
        inlier = (e2 < t2) & (w > 0.0)
        return inlier.astype(jnp.int32), jnp.where(inlier, e2, 0.0)

    # one reduction of two operands (the count and the summed squared error): XLA's CPU
    # backend fuses it with the errors it reduces, where a plain sum goes to a library call
    # that needs the (hypotheses x points) array stored first (3x slower under `vmap`)
    inlier, e2 = jax.vmap(errors)(G_h)
    count, spread = jax.lax.reduce(
        (inlier, e2),
        (jnp.zeros((), jnp.int32), jnp.zeros((), e2.dtype)),
        lambda a, b: (a[0] + b[0], a[1] + b[1]),
        (1,),
    )
    scores = count.astype(e2.dtype) - spread * scale
    scores = jnp.where(valid, scores, -1.0)
    best = jnp.argmax(scores)  # the first on ties
    return best, valid[best]


@eqx.filter_jit  # one program per shape, `iterations` and `throw`; its error_if
def _robust(key, src, dst, threshold, iterations: int, throw: bool):
    dtype = src.dtype
    n = src.shape[0]
    tol = _rcond_tol(dtype)
    finite = jnp.all(jnp.isfinite(src)) & jnp.all(jnp.isfinite(dst))
    src = jnp.where(finite, src, jnp.zeros_like(src))
    dst = jnp.where(finite, dst, jnp.zeros_like(dst))
    t2 = threshold**2

    # Stage 1, RANSAC: no gradient (the hypotheses only choose a set of inliers)
    s_ng, d_ng = jax.lax.stop_gradient(src), jax.lax.stop_gradient(dst)
    idx = _samples(key, n, iterations)
    G_h, valid = jax.vmap(_fit4, (0, 0, None))(s_ng[idx], d_ng[idx], tol)
    best, found = _best_hypothesis(G_h, valid, s_ng, d_ng, t2)
    inliers, _, _ = _inliers(G_h[best], s_ng, d_ng, t2, sign=1.0)

    # Stage 2: the normalised DLT on the best hypothesis' inliers, then reweighted steps
    G, bad = _weighted_dlt(src, dst, inliers.astype(dtype), tol)
    k2 = (_HUBER_FRACTION * threshold) ** 2
    k2_safe = jnp.where(k2 > 0.0, k2, 1.0)
    for _ in range(_REFINE_STEPS):
        mask, e2, w_signed = _inliers(G, src, dst, t2)
        e2 = jnp.where(mask, e2, 0.0)  # finite: no 0 * inf in the outliers' gradient
        huber = jnp.where(e2 <= k2, 1.0, jnp.sqrt(k2_safe / jnp.maximum(e2, k2_safe)))
        # 1 / |(G src_i)_3|, relative to its mean over the inliers (a common factor: only
        # for the conditioning)
        w_safe = jnp.where(mask, w_signed, 1.0)
        count = jnp.maximum(jnp.sum(mask), 1).astype(dtype)
        mean_w = jnp.sum(jnp.where(mask, w_signed, 0.0)) / count
        mean_w = jnp.where(mean_w > 0.0, mean_w, 1.0)
        row = jnp.where(mask, jnp.sqrt(huber) * mean_w / w_safe, 0.0)
        G_new, step_bad = _weighted_dlt(src, dst, row, tol)
        # a step whose inliers no longer fix a homography keeps the previous estimate
        G = jnp.where(step_bad, G, G_new)
    inliers, _, _ = _inliers(G, src, dst, t2)
    few = jnp.sum(inliers) < 4

    # H / h33, with h33 compared with the rest of its row at the data's scale (as
    # `find_homography`)
    g33 = G[2, 2]
    extent = jnp.max(jnp.abs(src), axis=0)
    row = jnp.abs(G[2, 0]) * extent[0] + jnp.abs(G[2, 1]) * extent[1] + jnp.abs(g33)
    g33_zero = ~(jnp.abs(g33) > 100.0 * jnp.finfo(dtype).eps * row)
    H = G / jnp.where(g33_zero, 1.0, g33)
    H = H.at[2, 2].set(1.0)

    result = RESULTS.where(
        ~finite,
        RESULTS.nonfinite_pixels,
        RESULTS.where(
            ~found,
            RESULTS.degenerate_points,
            RESULTS.where(
                few,
                RESULTS.too_few_inliers,
                RESULTS.where(
                    bad,
                    RESULTS.degenerate_points,
                    RESULTS.where(g33_zero, RESULTS.g33_zero, RESULTS.successful),
                ),
            ),
        ),
    )
    ok = result == RESULTS.successful

    def transfer(h, _):  # the inliers' forward transfer errors, (n, 2), zero elsewhere
        Hh = jnp.concatenate([h, jnp.ones((1,), dtype)]).reshape(3, 3)
        q = src @ Hh[:, :2].T + Hh[None, :, 2]
        w = jnp.where(inliers, q[:, 2], 1.0)
        return jnp.where(inliers[:, None], q[:, :2] / w[:, None] - dst, 0.0)

    h_safe = jnp.where(ok, H, jnp.eye(3, dtype=dtype)).reshape(-1)[:8]
    cov, _ = covariance(transfer, h_safe, None, 2 * jnp.sum(inliers))
    out = RobustHomography(
        H=jnp.where(ok, H, jnp.nan),
        inliers=inliers & ok,
        result=result,
        cov=jnp.where(ok, cov, jnp.nan),
    )
    return raise_or_keep(result, out, throw)
