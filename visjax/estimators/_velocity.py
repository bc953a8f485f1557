"""The fixed-camera 6-DoF velocity estimator of Chitrakaran et al., sections 4 and 5.

Source: Chitrakaran, Dawson, Dixon, Chen, *Identification of a moving object's velocity with a
fixed camera*. Signals: the error $e = [e_v, e_\\omega]$ (eqs. (18)-(20), (24), (28)), the
Jacobian-like matrix $J$ with $\\dot e = J v$ (eq. (33)), the continuous estimator
(eqs. (39)-(40)) and the velocity $\\hat v = J^{-1}\\hat\\kappa$ (Theorem 2).

Convention: feature 1 of the paper is row 0 of every pixel array. $v = [v_e, \\omega_e]$ is
the object's linear velocity (of the origin of its frame $\\mathcal F$) and angular velocity,
both expressed in the camera frame $\\mathcal I$.

Everything that depends on one sample only (the reconstruction, $e$, $J$, $J^{-1}$) is in
`velocity_measurements`, vmapped over all samples before the time loop; the estimator's
time loop then costs a few dozen flops per step.
"""

from typing import final

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from .._results import RESULTS, raise_or_keep
from .._small import (
    barrier,
    det3,
    from_rows,
    mm,
    mv,
    rows,
    sadjugate,
    sall,
    sdot,
    smax,
    smm,
    sskew,
    stranspose,
)
from .._util import (
    as_float,
    check_points,
    check_shape,
    chunked_map,
    median_interval,
    positive_finite,
)
from ..geometry import (
    L_omega,
    L_omega_inv,
    euclidean_reconstruction,
    pixel_to_normalized,
    so3_log,
    to_homogeneous,
)
from ._base import (
    AbstractEstimator,
    Innovation,
    Stream,
    innovation,
    reject_mask,
    rejected_samples,
)

CHATTER_FRACTION = 1e-2
"""The chattering bound of `VelocityEstimator`'s sign gain $\\rho$: the chatter that the
sign term causes in the velocity estimate under Euler steps, $\\frac{\\pi}{2}\\rho_i
\\sqrt{h/(k_i + 1)}$, may reach this fraction of the fastest rate the samples carry,
$\\sigma_i/\\Delta t$ (`VelocityEstimator.max_chatter_dt`)."""

GROWTH_RADIANS = 10.0
"""`VelocityEstimator.valid`: the estimate $\\hat e$ has left the signal it tracks when
$|e_i - \\hat e_i|$ exceeds this many radians of view, $10\\,\\sigma_i$ (ten focal lengths
of pixels, ten e-folds of depth, ten radians: more than a whole turn, so that the wrap of
$u\\theta$ at $\\pi$ is not taken for divergence)."""


def _view_scale(y: "VelocityMeasurement") -> Float[Array, "6"]:
    """The scale $\\sigma$ of each entry of $e$ in its own unit: one radian of view.

    $\\sigma = [f_x, f_y, 1, 1, 1, 1]$: a bearing of one radian is $f_x$, $f_y$ pixels on
    $e_v$'s image coordinates (eqs. (18)-(19)), one e-fold of depth on $-\\ln\\alpha_1$
    (eq. (20)) and one radian on $u\\theta$ (eq. (28)). The focal lengths are read from the
    sample's $J$ (eq. (33)): its top-left block is $\\frac{\\alpha_1}{z_1^*} A_e L_v$, so
    $J_{11}/J_{33} = f_x$ and $J_{22}/J_{33} = f_y$ ($A_e$ of eq. (22), $L_v$ of eq. (23)).
    """
    J = y.J
    unit = J[..., 2, 2]
    f = jnp.stack([jnp.abs(J[..., 0, 0] / unit), jnp.abs(J[..., 1, 1] / unit)], axis=-1)
    return jnp.concatenate([f, jnp.ones(f.shape[:-1] + (4,), f.dtype)], axis=-1)


@final
class VelocityMeasurement(eqx.Module):
    """One sample of what the velocity estimator reads.

    **Fields:** `e` (6,): $e = [e_v, e_\\omega]$; `J` (6, 6): eq. (33); `J_inv` (6, 6): its
    inverse, in closed form from the block structure; `R` (3, 3): the object's orientation
    $R = \\bar R R^*$ in the camera frame (eq. (8)), for velocities in the object frame
    (Remark 6); `result`: why the frame could not be measured (then `e`, `J`, `J_inv`, `R`
    are NaN, never a finite placeholder).
    """

    e: Float[Array, "*batch 6"]
    J: Float[Array, "*batch 6 6"]
    J_inv: Float[Array, "*batch 6 6"]
    R: Float[Array, "*batch 3 3"]
    result: RESULTS


def error_signal(
    p1_cur: Float[ArrayLike, "2"],
    p1_ref: Float[ArrayLike, "2"],
    alpha1: Float[ArrayLike, ""],
    R_bar: Float[ArrayLike, "3 3"],
) -> Float[Array, "6"]:
    """The error $e = [e_v, e_\\omega]$ of Chitrakaran et al.

    $e_v = p_e - p_e^* = [u_1 - u_1^*, v_1 - v_1^*, -\\ln\\alpha_1]$ (eqs. (18)-(20), the third
    entry being $\\ln z_1 - \\ln z_1^* = -\\ln\\alpha_1$), and $e_\\omega = u\\theta$ of
    $\\bar R$ (eqs. (24), (28)).
    """
    p1_cur, p1_ref, alpha1, R_bar = (as_float(x) for x in (p1_cur, p1_ref, alpha1, R_bar))
    e_v = jnp.concatenate([p1_cur - p1_ref, -jnp.log(alpha1)[None]])
    return jnp.concatenate([e_v, so3_log(R_bar).omega])


def kinematics_jacobian(
    A: Float[ArrayLike, "3 3"],
    m1: Float[ArrayLike, "2"],
    alpha1: Float[ArrayLike, ""],
    z1_star: Float[ArrayLike, ""],
    R: Float[ArrayLike, "3 3"],
    s1: Float[ArrayLike, "3"],
    e_omega: Float[ArrayLike, "3"],
) -> tuple[Float[Array, "6 6"], Float[Array, "6 6"]]:
    """The Jacobian-like matrix $J$ of eq. (33) and its inverse.

    $J = \\begin{bmatrix} \\frac{\\alpha_1}{z_1^*} A_e L_v &
    -\\frac{\\alpha_1}{z_1^*} A_e L_v R [s_1]_\\times R^T \\\\ 0 & L_\\omega \\end{bmatrix}$, with
    $A_e$ of eq. (22), $L_v$ of eq. (23) and $L_\\omega$ of eq. (27). Writing the top-left block
    $B$, $J^{-1} = \\begin{bmatrix} B^{-1} & R[s_1]_\\times R^T L_\\omega^{-1} \\\\ 0 &
    L_\\omega^{-1}\\end{bmatrix}$.

    **Arguments:** `A` the intrinsics; `m1` the current normalized coordinates of feature 1;
    `alpha1` its depth ratio; `z1_star` its reference depth; `R` the current rotation of the
    object, $R = \\bar R R^*$ (eq. (8)); `s1` feature 1 in the object frame; `e_omega`
    $= u\\theta$ of $\\bar R$.

    **Returns:** `(J, J_inv)`.
    """
    A, m1, alpha1, z1_star, R, s1, e_omega = (
        as_float(x) for x in (A, m1, alpha1, z1_star, R, s1, e_omega)
    )
    Lw, Lw_inv = rows(L_omega(e_omega)), rows(L_omega_inv(e_omega))  # eq. (27), its inverse
    J, J_inv = _jacobian_rows(rows(A), rows(m1), alpha1, z1_star, rows(R), rows(s1), Lw, Lw_inv)
    return from_rows(J, A.dtype), from_rows(J_inv, A.dtype)


def _jacobian_rows(A, m1, alpha1, z1_star, R, s1, Lw, Lw_inv):
    """`kinematics_jacobian` on scalars (rows of scalars in, rows of scalars out: under
    `vmap` each entry is one elementwise operation over the batch, fused by XLA into few
    loops; on (3, 3) arrays the same products were ~2x slower per frame)."""
    # A_e of eq. (22): A without its principal point
    Ae = [[A[0][0], A[0][1], 0.0], [A[1][0], A[1][1], 0.0], list(A[2])]
    Lv = [[1.0, 0.0, -m1[0]], [0.0, 1.0, -m1[1]], [0.0, 0.0, 1.0]]  # eq. (23)
    k = alpha1 / z1_star
    B = [[k * x for x in r] for r in smm(Ae, Lv)]
    Rs = smm(smm(R, sskew(s1)), stranspose(R))  # R [s1]_x R^T
    zeros = [0.0, 0.0, 0.0]
    BRs = smm(B, Rs)
    J = [B[i] + [-x for x in BRs[i]] for i in range(3)] + [zeros + Lw[i] for i in range(3)]
    Lv_inv = [[1.0, 0.0, m1[0]], [0.0, 1.0, m1[1]], [0.0, 0.0, 1.0]]
    Ae_adj = sadjugate(Ae)
    k_inv = (z1_star / alpha1) / sdot(Ae_adj[0], [r[0] for r in Ae])  # over det(A_e)
    B_inv = [[k_inv * x for x in r] for r in smm(Lv_inv, Ae_adj)]
    RsLw = smm(Rs, Lw_inv)
    J_inv = [B_inv[i] + RsLw[i] for i in range(3)] + [zeros + Lw_inv[i] for i in range(3)]
    return J, J_inv


@final
class FixedCamera(eqx.Module):
    """The constants of a fixed camera watching a planar object (Chitrakaran et al.,
    sections 2-5), which travel together through every function that takes them.

    **Fields:** `p_ref` (n, 2) the reference image's pixels, feature 1 first; `A` (3, 3) the
    intrinsic matrix; `R_star` (3, 3) the known reference orientation of the object; `s1`
    (3,) feature 1 in the object frame; `n_star` (3,) the plane normal in the reference
    camera frame (`plane_normal_from_frames`); `z1_star` () feature 1's reference depth
    (`depth_from_known_length`, `depth_from_feature_length`); `result` whether they were
    recovered (`fixed_camera(throw=False)`: `RESULTS.depth_recovery_failed` when $z_1^*$
    could not be). `fixed_camera` measures `n_star` and `z1_star` from the frames; all are
    arrays (a new value never recompiles,
    and gradients flow through them).
    """

    p_ref: Float[Array, "n 2"] = eqx.field(converter=as_float)
    A: Float[Array, "3 3"] = eqx.field(converter=as_float)
    R_star: Float[Array, "3 3"] = eqx.field(converter=as_float)
    s1: Float[Array, "3"] = eqx.field(converter=as_float)
    n_star: Float[Array, "3"] = eqx.field(converter=as_float)
    z1_star: Float[Array, ""] = eqx.field(converter=as_float)
    result: RESULTS = eqx.field(default_factory=lambda: RESULTS.successful)

    def __check_init__(self):
        if self.p_ref.ndim != 2 or self.p_ref.shape[-1] != 2 or self.p_ref.shape[0] < 4:
            raise ValueError(f"`p_ref` must have shape (n >= 4, 2); got {tuple(self.p_ref.shape)}.")
        for name, shape in (("A", (3, 3)), ("R_star", (3, 3)), ("s1", (3,)), ("n_star", (3,)),
                            ("z1_star", ())):  # fmt: skip
            check_shape(getattr(self, name), shape, name)


def velocity_measurements(
    camera: FixedCamera,
    p_cur: Float[ArrayLike, "n 2"],
    *,
    visible: Bool[ArrayLike, " n"] | None = None,
    throw: bool = True,
) -> VelocityMeasurement:
    """$e$, $J$ and $J^{-1}$ of one frame (Chitrakaran et al., sections 3-5). Vmap it over frames.

    The reconstruction uses the known-normal path (smooth at the reference pose, where the
    paper's simulation starts); $R = \\bar R R^*$ (eq. (8)).

    **Arguments:** `camera` the fixed camera's constants (`FixedCamera`: the reference
    pixels, $A$, $R^*$, $s_1$, $n^*$, $z_1^*$); `p_cur` the current pixels, feature 1 first;
    `visible`: optional (n,) booleans, the features seen in this frame (the homography is
    fitted to these; of more than four features at least four must be seen; feature 1 may
    be among the missing: its pixel then follows from the homography,
    $p_1 \\sim G_n p_1^*$, eq. (17)); `throw` as in `euclidean_reconstruction`.

    **Returns:** a `VelocityMeasurement`; with `throw=False` its `result` says whether the
    frame was measured (a failed frame is all NaN).
    """
    p_ref, A, R_star, s1 = camera.p_ref, camera.A, camera.R_star, camera.s1
    z1_star, n_star = camera.z1_star, camera.n_star
    rec = euclidean_reconstruction(p_ref, p_cur, A, n_star=n_star, visible=visible, throw=False)
    p_cur = as_float(p_cur)
    if visible is not None:
        # feature 1 out of view: its pixel from the homography of the others (eq. (17))
        g = mv(rec.G_n, to_homogeneous(p_ref[0]))
        p1 = jnp.where(visible[0], p_cur[0], g[:2] / g[2])
        p_cur = p_cur.at[0].set(p1)
    # a decomposition that returned no rotation (nearly coincident points far from the
    # image, which the DLT's degeneracy test did not name) is a failed frame: so3_log's own
    # test, R^T R = I and det R = 1 within 10 sqrt(eps)
    tol = 10.0 * float(jnp.finfo(A.dtype).eps) ** 0.5
    R_off = smax(jnp.abs(mm(rec.R_bar.T, rec.R_bar) - jnp.eye(3, dtype=A.dtype)))
    rotation = R_off + jnp.abs(det3(rec.R_bar) - 1.0) <= tol
    rec_result = RESULTS.where(
        (rec.result == RESULTS.successful) & ~rotation, RESULTS.no_physical_solution, rec.result
    )
    # a failed frame is reported by its result (and NaN-filled below), never by so3_log
    R_bar = jnp.where(rec_result == RESULTS.successful, rec.R_bar, jnp.eye(3, dtype=A.dtype))
    e = error_signal(p_cur[0], p_ref[0], rec.alpha[0], R_bar)
    m1 = pixel_to_normalized(p_cur[0], A)
    R = mm(R_bar, R_star)  # eq. (8)
    e_w = e[3:]
    J, J_inv = _jacobian_rows(
        rows(A), rows(m1), rec.alpha[0], as_float(z1_star), rows(R), rows(s1),
        rows(L_omega(e_w)), rows(L_omega_inv(e_w)),
    )  # fmt: skip
    # J's finiteness from its entries (the zero blocks are literals), the arrays stacked
    # once and NaN-filled in the same pass
    entries = [x for r in J + J_inv for x in r if not isinstance(x, float)]
    ok = jnp.isfinite(entries[0])
    for x in entries[1:]:
        ok = ok & jnp.isfinite(x)
    result = RESULTS.where(
        rec_result != RESULTS.successful,
        rec_result,
        RESULTS.where(ok, RESULTS.successful, RESULTS.singular_jacobian),
    )
    # the reference depth is a constant of the scene: not finite or not positive (a depth
    # recovery that failed, with throw=False) is a bad parameter, not a bad frame
    z1_ok = jnp.isfinite(z1_star) & (z1_star > 0.0)
    result = RESULTS.where(z1_ok, result, RESULTS.invalid_intrinsics)
    result = RESULTS.where(camera.result == RESULTS.successful, result, camera.result)
    # once per frame (a barrier: XLA would recompute it into each of the 90 entries below)
    bad = barrier(result != RESULTS.successful)
    J, J_inv = (from_rows(M, A.dtype) for M in (J, J_inv))
    e, J, J_inv, R = (jnp.where(bad, jnp.nan, x) for x in (e, J, J_inv, R))
    out = VelocityMeasurement(e=e, J=J, J_inv=J_inv, R=R, result=result)
    return raise_or_keep(result, out, throw)


def depth_from_known_length(
    p1_ref: Float[ArrayLike, "2"],
    p0_ref: Float[ArrayLike, "2"],
    A: Float[ArrayLike, "3 3"],
    n_star: Float[ArrayLike, "3"],
    R_star: Float[ArrayLike, "3 3"],
    s1: Float[ArrayLike, "3"],
    *,
    residual_tol: float = 1e-2,
) -> Float[Array, ""]:
    """The reference depth $z_1^*$ of feature 1 from the known vector $s_1$ (replaces eq. (56)).

    Eq. (56) of the paper, $x_f^* = [\\mathrm{diag}(\\bar\\gamma_1 - \\bar\\gamma_2) + \\bar R]^{-1}
    [\\mathrm{diag}(\\bar\\gamma_1 - \\bar\\gamma_2) R^* - R] s_1$, cannot be used as printed: with
    $\\bar\\gamma_{1,2}$ of eq. (57), $(\\bar\\gamma_2 - \\bar\\gamma_1)_j\\, \\bar m^*_{1j} =
    z_1^* (m_1/\\alpha_1 - (n^{*T} m_1^*)\\bar x_h)_j = (\\bar R \\bar m_1^*)_j$ by eqs. (7),
    (12), (13), so $\\bar m_1^* = x_f^* + R^* s_1$ is a null vector of the matrix it inverts
    (`tests/estimators/test_velocity.py` checks this numerically). The reason is physical:
    $s_1$ cancels from every image relation (eq. (7) holds for any object origin), so the
    images of feature 1 alone fix no scale.

    The paper's premise, "a single geometric length between two feature points on the object
    be known", does fix it once the object origin is a point whose image is known: then
    $R^* s_1 = \\bar m_1^* - x_f^*$ with both points on the plane, $z_i^* = d^* / (n^{*T}
    m_i^*)$ (eq. (4)), so $R^* s_1 = d^* w$ with $w = m_1^*/(n^{*T}m_1^*) - m_0^*/(n^{*T}
    m_0^*)$. This returns the least-squares $d^* = w^T R^* s_1 / w^T w$ and
    $z_1^* = d^*/(n^{*T} m_1^*)$ (eq. (58), third row). Noise-free it is exact.

    **Arguments:**

    - `p1_ref`: reference pixel of feature 1.
    - `p0_ref`: reference pixel of the object-frame origin (for a parallelogram of
        features centred on the origin, `diagonal_intersection` of the four).
    - `A`, `n_star`, `R_star`, `s1`: intrinsics, plane normal, reference orientation,
        feature 1 in the object frame.

    - `residual_tol`: the largest relative residual $\\|R^* s_1 - d^* w\\| / \\|s_1\\|$ accepted
        (noise-free it is 0; 0.1 px of noise on the reference pixels leaves about 1e-4 with
        the true $n^*$, but a normal measured from a few seconds of noisy frames can be a
        degree or two off, which leaves a few 1e-2: then give the known length between two
        features, `depth_from_feature_length`). Above it the premise does not hold and the
        function raises instead of returning a wrong $z_1^*$. (`fixed_camera(throw=False)`
        returns the failure as the camera's `result` instead.)

    **Returns:** $z_1^*$ (a runtime error if it is not positive or the residual is too
    large).
    """
    z1, premise = _depth_from_known_length(p1_ref, p0_ref, A, n_star, R_star, s1, residual_tol)
    z1 = eqx.error_if(
        z1,
        ~premise,
        "depth recovery: R* s1 = d* w does not hold (relative residual above `residual_tol`):"
        " `p0_ref` is not the image of the object origin on the feature plane (for"
        " `diagonal_intersection`, the features must be a parallelogram centred on it), or"
        " n* is too coarse (from noisy frames: give `known_length` instead).",
    )
    return eqx.error_if(z1, ~(z1 > 0.0), "depth recovery gave z1* <= 0: check s1, R*, n*.")


def _depth_from_known_length(p1_ref, p0_ref, A, n_star, R_star, s1, residual_tol):
    """`depth_from_known_length`'s $z_1^*$ and whether its premise holds."""
    p1_ref, p0_ref, A, n_star, R_star, s1 = (
        as_float(x) for x in (p1_ref, p0_ref, A, n_star, R_star, s1)
    )
    check_shape(p1_ref, (2,), "p1_ref")
    check_shape(p0_ref, (2,), "p0_ref")
    check_shape(n_star, (3,), "n_star")
    check_shape(R_star, (3, 3), "R_star")
    check_shape(s1, (3,), "s1")
    m1 = to_homogeneous(pixel_to_normalized(p1_ref, A))
    m0 = to_homogeneous(pixel_to_normalized(p0_ref, A))
    n = n_star / jnp.linalg.norm(n_star)
    w = m1 / (n @ m1) - m0 / (n @ m0)
    Rs1 = R_star @ s1
    d_star = (w @ Rs1) / (w @ w)
    z1 = d_star / (n @ m1)
    # R* s1 = d* w is three equations for one unknown: their residual says whether the
    # premise holds (the origin's pixel is the image of the object origin, on the plane)
    residual = jnp.linalg.norm(Rs1 - d_star * w) / jnp.linalg.norm(Rs1)
    return z1, residual <= residual_tol


def depth_from_feature_length(
    p_ref: Float[ArrayLike, "n 2"],
    A: Float[ArrayLike, "3 3"],
    n_star: Float[ArrayLike, "3"],
    known_length: tuple,
) -> Float[Array, ""]:
    """The reference depth $z_1^*$ of feature 1 from one known length between two features.

    The paper's premise (section 5, before eq. (56)): "a single geometric length between two
    feature points on the object be known". With the plane normal $n^*$ known and every
    feature on the plane at distance $d^*$ (eq. (4): $n^{*T}\\bar m_i^* = d^*$), feature
    $i$ is at $\\bar m_i^* = d^*\\, m_i^* / (n^{*T} m_i^*)$ in the reference camera frame, so
    the known distance $L = \\|\\bar m_i^* - \\bar m_j^*\\|$ gives

    $d^* = L / \\| m_i^*/(n^{*T} m_i^*) - m_j^*/(n^{*T} m_j^*) \\|$ and
    $z_1^* = d^* / (n^{*T} m_1^*)$ (the third entry of $\\bar m_1^*$, eq. (58)).

    Exact for any coplanar feature set (no parallelogram, no object origin needed).

    **Arguments:**

    - `p_ref`: the reference pixels of the features, feature 1 first, shape (n, 2).
    - `A`: the intrinsic matrix; `n_star`: the plane normal in the reference camera frame
        (`plane_normal_from_frames`, or known).
    - `known_length`: `(i, j, L)`: two feature indices (Python ints, 0 is feature 1) and
        their distance in metres (an array: gradients flow through it).

    **Returns:** $z_1^*$ (the sign of `n_star` does not matter: it is taken with
    $n^{*T} m_1^* > 0$, eq. (4)); a runtime error if the two features coincide in the
    image, or if the depth is not positive (a feature on the other side of the camera, or
    $L \\le 0$). (`fixed_camera(throw=False)` returns a failure as the camera's `result`.)
    """
    z1, gap_ok = _depth_from_feature_length(p_ref, A, n_star, known_length)
    z1 = eqx.error_if(
        z1,
        ~gap_ok,
        "depth_from_feature_length: the two features of the known length coincide.",
    )
    return eqx.error_if(z1, ~(z1 > 0.0), "depth_from_feature_length: z1* <= 0 (check n*, L > 0).")


def _depth_from_feature_length(p_ref, A, n_star, known_length):
    """`depth_from_feature_length`'s $z_1^*$ and whether the two features are apart."""
    p_ref = check_points(p_ref, "p_ref", min_points=2)
    A, n_star = as_float(A), as_float(n_star)
    check_shape(n_star, (3,), "n_star")
    try:
        i, j, length = known_length
    except (TypeError, ValueError):
        raise ValueError(f"`known_length` must be (i, j, L); got {known_length!r}.") from None
    n = p_ref.shape[0]
    if not all(isinstance(k, int) and 0 <= k < n for k in (i, j)) or i == j:
        raise ValueError(
            f"`known_length` must name two different features among the {n}; got ({i}, {j})."
        )
    length = as_float(length)
    check_shape(length, (), "known_length[2]")
    m = to_homogeneous(pixel_to_normalized(p_ref, A))
    u = n_star / jnp.linalg.norm(n_star)
    u = jnp.where(u @ m[0] < 0.0, -u, u)  # the sign of eq. (4): d* = n*^T m_bar* > 0
    scaled = m / (m @ u)[:, None]  # m_k / (n^T m_k): the features at d* = 1
    gap = jnp.linalg.norm(scaled[i] - scaled[j])
    gap_ok = gap > 0.0
    return (length / jnp.where(gap_ok, gap, 1.0)) / (u @ m[0]), gap_ok


def diagonal_intersection(p: Float[ArrayLike, "4 2"]) -> Float[Array, "2"]:
    """The image of the intersection of the diagonals 1-3 and 2-4 of four plane points.

    Lines and their intersections are preserved by perspective projection, so this is the
    pixel of the diagonals' intersection on the plane (the object origin in the section-6
    scenario of visjax, where the features are a square centred on it).
    """
    p = check_points(p, "p")
    if p.shape[0] != 4:
        raise ValueError(f"`p` must hold exactly 4 points; got {p.shape[0]}.")
    h = to_homogeneous(p)
    x = jnp.cross(jnp.cross(h[0], h[2]), jnp.cross(h[1], h[3]))
    return x[:2] / x[2]


def plane_normal_from_frames(
    p_ref: Float[ArrayLike, "n 2"],
    p_frames: Float[ArrayLike, "N n 2"],
    A: Float[ArrayLike, "3 3"],
    n_prior: Float[ArrayLike, "3"] | None = None,
    *,
    visible: Bool[ArrayLike, "N n"] | None = None,
) -> Float[Array, "3"]:
    """The constant plane normal $n^*$ from a sequence of frames.

    Each frame is decomposed with the general method (eq. (12)); near the reference pose the
    normal is ill-determined (it is undefined at $H = I$), so the normals are averaged with
    weights $\\|\\bar x_h\\|^2$. Frames whose reconstruction fails get weight 0.
    `visible` (N, n), optional: the features seen in each frame (`euclidean_reconstruction`).
    """
    p_frames = as_float(p_frames)
    if p_frames.ndim != 3:
        raise ValueError(f"`p_frames` must have shape (N, n, 2); got {tuple(p_frames.shape)}.")
    if visible is not None:
        visible = jnp.asarray(visible)
        if visible.shape != p_frames.shape[:2]:
            raise ValueError(
                f"`visible` must have shape {tuple(p_frames.shape[:2])}; got {visible.shape}."
            )
    return _normal_from_frames(p_ref, p_frames, A, n_prior, visible)


@eqx.filter_jit
def _normal_from_frames(p_ref, p_frames, A, n_prior, visible):
    def weighted(args):
        pc, v = args
        rec = euclidean_reconstruction(p_ref, pc, A, n_prior, visible=v, throw=False)
        w = jnp.where(rec.result == RESULTS.successful, jnp.sum(rec.x_h**2), 0.0)
        return w, w * rec.n_star

    # 256 frames at a time: the reconstructions of a long run never exist all at once
    w, wn = chunked_map(weighted, (p_frames, visible), 256)
    n = jnp.sum(wn, axis=0)
    n = eqx.error_if(
        n, ~(jnp.sum(w) > 0.0), "No frame moves away from the reference pose: n* is unobservable."
    )
    return n / jnp.linalg.norm(n)


@final
class VelocityState(eqx.Module):
    """The state of eqs. (39)-(40): $\\hat e$ and $\\eta = \\int_{t_0}^t (K + I_6)\\tilde e +
    \\rho\\,\\mathrm{sgn}(\\tilde e)\\,d\\tau$."""

    e_hat: Float[Array, "6"]
    eta: Float[Array, "6"]


@final
class VelocityOutput(eqx.Module):
    """The estimated velocity $\\hat v = J^{-1}\\hat\\kappa$ (Theorem 2): `v_hat` $=
    [\\hat v_e, \\hat\\omega_e]$ expressed in the camera frame $\\mathcal I$, and `v_object`
    the same velocity expressed in the object frame $\\mathcal F$, $[R^T\\hat v_e,
    R^T\\hat\\omega_e]$ with $R = \\bar R R^*$ (Remark 6)."""

    v_hat: Float[Array, "6"]
    v_object: Float[Array, "6"]


@final
class VelocityDiagnostics(eqx.Module):
    """$\\tilde e = e - \\hat e$ (eq. (36)) and $\\hat\\kappa$ (eq. (40))."""

    e_tilde: Float[Array, "6"]
    kappa_hat: Float[Array, "6"]


@final
class VelocityEstimator(AbstractEstimator):
    """The continuous sign-based velocity estimator of Chitrakaran et al., eqs. (39)-(40).

    State: $(\\hat e, \\eta)$ with $\\eta = \\int_{t_0}^t (K + I_6)\\tilde e + \\rho\\,
    \\mathrm{sgn}(\\tilde e)\\, d\\tau$, $\\tilde e = e - \\hat e$ (eq. (36)). Then
    $\\hat\\kappa = \\eta + (K + I_6)\\tilde e$ (eq. (40)), $\\dot{\\hat e} = \\hat\\kappa$
    (eq. (39)), and $\\hat v = J^{-1}\\hat\\kappa$ (Theorem 2). Initial state (the paper does
    not fix it): $\\hat e(t_0) = e(t_0)$, $\\eta(t_0) = 0$.

    The right-hand side is discontinuous: run it with fixed steps (the default Euler at the
    sample rate is the paper's 1 kHz discretisation), never an adaptive controller.

    Euler stability of `K`: per degree of freedom the linear part of the error dynamics is
    $\\dot{\\tilde e} = -(k + 1)\\tilde e - \\eta$, $\\dot\\eta = (k + 1)\\tilde e$, with
    characteristic polynomial $\\lambda^2 + (k + 1)\\lambda + (k + 1)$; Euler steps are stable
    for $h < \\min_\\lambda -2\\,\\mathrm{Re}\\lambda / |\\lambda|^2$ (`max_stable_dt`): 6.7 ms
    for the gains of eq. (63), so one step per 33 ms camera frame diverges.

    Chattering of `rho` (`max_chatter_dt`): per degree of freedom, with $a = k + 1$, Euler
    steps $h$ of eqs. (39)-(40) are $\\eta_{n+1} = \\eta_n + h(a\\tilde e_n + \\rho\\,
    \\mathrm{sgn}\\,\\tilde e_n)$, $\\hat e_{n+1} = \\hat e_n + h\\hat\\kappa_n$. Near
    $\\tilde e = 0$ the velocity error of the integral, $w = \\dot e - \\eta$, obeys
    $\\dot w \\approx -\\rho\\,\\mathrm{sgn}\\,\\tilde e$, and $\\tilde e$ follows it with the
    time constant $1/a$, $\\dot{\\tilde e} = w - a\\tilde e$: a relay loop $\\rho/(s(s + a))$.
    In continuous time it slides to $\\tilde e = 0$ (Theorem 1); sampled every $h$ the sign
    switches a step late, and the loop settles on a limit cycle instead. Its frequency,
    where the phase reaches $-\\pi$ ($\\arctan(\\omega/a) + \\omega h = \\pi/2$), is
    $\\omega \\approx \\sqrt{a/h}$ for $ah \\ll 1$; a square wave $\\pm\\rho$ integrated over
    half its period makes the chatter of $\\hat\\kappa$ (the velocity estimate, eq. (40))
    $A_\\kappa \\approx \\frac{\\pi}{2}\\rho\\sqrt{h/a}$, and that of $\\tilde e$
    $\\frac{4}{\\pi}\\rho h/a$ (on a simulated degree of freedom, $\\dot e = 0.2\\cos t$, the
    largest $|\\hat\\kappa - \\dot e|$ is 0.9 to 1.2 $A_\\kappa$ for the gains of eq. (63) at
    1 and 10 kHz; the noise-free errors of section 6 are this chatter: $A_\\kappa = 0.012$
    rad/s on $\\omega$, measured up to 0.015). The chatter grows with $\\rho$ and
    $\\sqrt h$; it must stay below `CHATTER_FRACTION` (1%) of the fastest rate the samples
    carry, one radian of view per mean sample interval $\\Delta t$, $V_i = \\sigma_i/\\Delta t$
    ($\\sigma$ = $[f_x, f_y, 1, 1, 1, 1]$: pixels, e-folds of depth, radians; `_view_scale`):
    $\\frac{\\pi}{2}\\rho_i\\sqrt{h/a_i} \\le 0.01\\,V_i$, i.e.
    $h \\le a_i\\,(0.02\\,V_i/(\\pi\\rho_i))^2$. The gains of eq. (63) chatter at 1/285
    of this bound at 1 kHz (the depth entry binds; the bound is 81 s), and at 1/4.7 of it
    on 30 Hz frames held under 3.3 ms steps (the bound is 73 ms, K's 6.7 ms); the bound
    does not depend on the pixel noise. $\\rho = 10^9$ needs steps of $6.5 \\cdot
    10^{-16}$ s at 1 kHz: refused (a `ValueError` naming `rho`, its bound and the step, or
    `RESULTS.chattering_step` under `jit`), and `integration_step`, which keeps below
    every bound, would take $3 \\cdot 10^{15}$ steps per second of data, refused before
    anything is allocated (`MAX_STEPS`).

    Divergence (`valid`): besides the absolute `bound`, the state has left its valid set
    when the estimate leaves the signal it tracks, $|\\tilde e_i| > 10\\,\\sigma_i$
    (`GROWTH_RADIANS`: ten radians of view; $\\tilde e \\to 0$ by Theorem 1). An Euler step
    past `K`'s bound makes $\\tilde e$ grow geometrically, and a large `rho` makes it chatter
    by $\\frac{4}{\\pi}\\rho h/a$ ($8 \\cdot 10^4$ rad on $\\omega$ for $\\rho = 10^9$ at 1 kHz,
    while $\\eta$, of order $\\rho h = 10^6$, stays below `bound`); the run then stops with
    `RESULTS.diverged` and the sample (with a solver that the step bounds do not cover, or
    a `state0` far from the signal). Section 6 (3 s at 1 kHz) reaches $1.3 \\cdot 10^{-5}$ of
    it noise-free, 0.08 with 1 px of pixel noise and 0.13 with 3 px (on the rotation about
    the plane's axes, which the noise disturbs most).

    **Fields:** `K`, `rho`: the diagonals of the positive definite diagonal gains (shape
    (6,)); `bound`: the state is also valid only while every entry of $\\hat e$ and $\\eta$
    stays below it in magnitude (pixels, pixels/s: default 1e8). Measurements are
    `VelocityMeasurement`s.
    """

    K: Float[Array, "6"] = eqx.field(converter=as_float)
    rho: Float[Array, "6"] = eqx.field(converter=as_float)
    bound: Float[Array, ""] = eqx.field(converter=as_float, default=1e8)

    def __check_init__(self):
        for name in ("K", "rho"):
            g = getattr(self, name)
            if jnp.shape(g) != (6,):
                raise ValueError(
                    f"`{name}` must be the diagonal of a 6x6 gain, shape (6,); got {jnp.shape(g)}."
                )
        if jnp.shape(self.bound) != ():
            raise ValueError(f"`bound` must be a scalar; got shape {jnp.shape(self.bound)}.")

    def checks(self):
        return (
            (positive_finite(self.K), "`K` must be positive definite and finite (eq. (40))."),
            (positive_finite(self.rho), "`rho` must be positive definite and finite (eq. (40))."),
            (self.bound > 0, "`bound` must be positive."),
        )

    def max_stable_dt(self, y=None):
        """The Euler stability bound of `K` (the linear part of eqs. (39)-(40))."""
        a = self.K + 1.0
        fast = 0.5 * (a + jnp.sqrt(jnp.maximum(a * a - 4.0 * a, 0.0)))
        # real roots (a >= 4): 2 / |lambda_fast|; complex roots: -2 Re(l) / |l|^2 = 1
        per_dof = jnp.where(a >= 4.0, 2.0 / fast, 1.0)
        return jnp.min(per_dof)

    def max_chatter_dt(
        self, y: VelocityMeasurement, sample_dt: Float[ArrayLike, ""]
    ) -> Float[Array, ""]:
        """The chattering bound of `rho`: the largest Euler step whose chatter of the velocity
        estimate, $\\frac{\\pi}{2}\\rho_i\\sqrt{h/(k_i + 1)}$, stays below `CHATTER_FRACTION`
        of $\\sigma_i / \\Delta t$ on every degree of freedom (see the class; eqs. (39)-(40)),
        for a sample `y` (its $J$ gives $\\sigma$) and the mean sample interval `sample_dt`."""
        fastest = _view_scale(y) / sample_dt  # one radian of view per sample interval
        amp = 2.0 * CHATTER_FRACTION * fastest / (jnp.pi * self.rho)
        return jnp.min((self.K + 1.0) * amp * amp)

    def step_bounds(self, y: VelocityMeasurement, sample_dt):
        """`K`'s Euler stability bound (`max_stable_dt`, `RESULTS.unstable_step`) and `rho`'s
        chattering bound (`max_chatter_dt`, `RESULTS.chattering_step`)."""
        return (
            (
                self.max_stable_dt(y),
                "the Euler stability bound of `K` (`max_stable_dt`)",
                "the run would diverge",
                RESULTS.unstable_step,
            ),
            (
                self.max_chatter_dt(y, sample_dt),
                "the chattering bound of `rho` (`max_chatter_dt`)",
                "the sign term's chatter in the velocity estimate, (pi/2) rho sqrt(dt / (K + "
                f"1)), would exceed {CHATTER_FRACTION:g} of the fastest rate the samples "
                "carry (one radian of view per sample interval) on some degree of freedom "
                "(is `rho` far larger than intended?)",
                RESULTS.chattering_step,
            ),
        )

    def init(self, y0: VelocityMeasurement) -> VelocityState:
        return VelocityState(e_hat=y0.e, eta=jnp.zeros_like(y0.e))

    def _kappa(self, state: VelocityState, y: VelocityMeasurement):
        e_tilde = y.e - state.e_hat  # eq. (36)
        return state.eta + (self.K + 1.0) * e_tilde, e_tilde  # eq. (40)

    def vector_field(self, t, state: VelocityState, y: VelocityMeasurement) -> VelocityState:
        kappa, e_tilde = self._kappa(state, y)
        d_eta = (self.K + 1.0) * e_tilde + self.rho * jnp.sign(e_tilde)  # integrand of (40)
        return VelocityState(e_hat=kappa, eta=d_eta)  # eq. (39)

    def output(self, t, state: VelocityState, y: VelocityMeasurement) -> VelocityOutput:
        kappa, _ = self._kappa(state, y)
        # (unrolled products: a per-step 6x6 `dot` is a kernel call of its own on a CPU)
        v_hat = mv(y.J_inv, kappa)  # Theorem 2: v_hat = J^{-1} kappa_hat
        # Remark 6: the same velocity in the object frame, with R = R_bar R* (eq. (8))
        v_object = jnp.concatenate([mv(y.R.T, v_hat[:3]), mv(y.R.T, v_hat[3:])])
        return VelocityOutput(v_hat=v_hat, v_object=v_object)

    def diagnostics(self, t, state: VelocityState, y: VelocityMeasurement):
        kappa, e_tilde = self._kappa(state, y)
        return VelocityDiagnostics(e_tilde=e_tilde, kappa_hat=kappa)

    def valid(self, state: VelocityState, y: VelocityMeasurement | None = None):
        """Every entry of the state below `bound`, and (given the held sample `y`) the
        estimate within `GROWTH_RADIANS` radians of view of the signal it tracks,
        $|e_i - \\hat e_i| \\le 10\\,\\sigma_i$ (a NaN is neither)."""
        # elementwise, fused with the step
        ok = sall(jnp.abs(state.e_hat) < self.bound) & sall(jnp.abs(state.eta) < self.bound)
        if y is None:
            return ok
        e_tilde = y.e - state.e_hat  # eq. (36)
        return ok & sall(jnp.abs(e_tilde) <= GROWTH_RADIANS * _view_scale(y))


@final
class FrameMeasure(eqx.Module):
    """`velocity_measurements` of one frame with the fixed camera's constants: the `measure`
    of a `velocity_stream`, applied by `run` in chunks fused with the time loop.

    **Fields:** `camera` (`FixedCamera`); `dropouts` (static): a NaN pixel is a feature out
    of view. Calling it on a frame's pixels (n, 2) returns its `VelocityMeasurement` (never
    raises: a failed frame is all NaN with its `result`).
    """

    camera: FixedCamera
    dropouts: bool = eqx.field(default=False, static=True)

    def __call__(self, pixels: Float[Array, "n 2"]) -> VelocityMeasurement:
        visible = jnp.all(jnp.isfinite(pixels), axis=-1) if self.dropouts else None
        return velocity_measurements(self.camera, pixels, visible=visible, throw=False)


@eqx.filter_jit
def _frame_results(measure, pixels, batch_size):
    """The result code of every frame, `batch_size` frames at a time (nothing else kept)."""
    return chunked_map(lambda pc: measure(pc).result, pixels, batch_size)


def _check_frames(pixels, ts=None):
    pixels = as_float(pixels)
    if pixels.ndim != 3 or pixels.shape[-1] != 2:
        raise ValueError(f"`pixels` must have shape (N, n, 2); got {tuple(pixels.shape)}.")
    if ts is not None and as_float(ts).shape != pixels.shape[:1]:
        raise ValueError(
            f"`ts` must have one time per frame, shape ({pixels.shape[0]},); "
            f"got {as_float(ts).shape}."
        )
    return pixels


def _dropped(dropped: str) -> bool:
    """`dropped="hold"` (a NaN pixel is a feature out of view) or `"stop"` (a failure)."""
    if dropped not in ("stop", "hold"):
        raise ValueError(f'`dropped` must be "stop" or "hold"; got {dropped!r}.')
    return dropped == "hold"


def fixed_camera(
    pixels: Float[ArrayLike, "N n 2"],
    A: Float[ArrayLike, "3 3"],
    R_star: Float[ArrayLike, "3 3"],
    s1: Float[ArrayLike, "3"],
    *,
    reference_pixels: Float[ArrayLike, "n 2"] | None = None,
    n_star: Float[ArrayLike, "3"] | None = None,
    z1_star: Float[ArrayLike, ""] | None = None,
    n_prior: Float[ArrayLike, "3"] | None = None,
    known_length: tuple | None = None,
    origin_pixel: Float[ArrayLike, "2"] | None = None,
    dropped: str = "stop",
    throw: bool = True,
) -> FixedCamera:
    """The fixed camera's constants (`FixedCamera`), the unknown ones measured once from the
    frames (Chitrakaran et al., sections 3-5).

    The reference image (the pose $R^*$ describes) is frame 0, or `reference_pixels` when
    given (an image taken before the run, or any other frame). The plane normal by
    `plane_normal_from_frames` (unless `n_star` is given; `n_prior` picks between the two
    decompositions), then $z_1^*$ (unless `z1_star` is given): by
    `depth_from_feature_length` when `known_length = (i, j, L)` names two features and their
    distance (the paper's premise; any coplanar set), else by `depth_from_known_length`
    with the origin's pixel (default: `diagonal_intersection` of the four reference
    features).

    With `dropped="hold"` a NaN pixel is a feature out of view (the reference pixels must
    all be finite), as in `velocity_stream`. A depth recovery that fails (its premise
    broken, or a plane normal too coarse from a few seconds of noisy frames: give
    `known_length` then) raises with
    `throw=True`; with `throw=False` the camera's `result` is
    `RESULTS.depth_recovery_failed`, every frame of a `velocity_stream` on it has that
    result, and `run` stops at the first sample.
    """
    pixels = _check_frames(pixels)
    dropouts = _dropped(dropped)
    if reference_pixels is None:
        p_ref = pixels[0]
    else:
        p_ref = check_points(reference_pixels, "reference_pixels")
        if p_ref.shape != pixels.shape[1:]:
            raise ValueError(
                f"`reference_pixels` must have the frames' shape {tuple(pixels.shape[1:])};"
                f" got {tuple(p_ref.shape)}."
            )
    visible = None
    if dropouts:
        visible = jnp.all(jnp.isfinite(pixels), axis=-1)
        # (checked when the pixels are concrete; under jit a non-finite reference fails
        # the first frame instead, which must be measured)
        if not isinstance(p_ref, jax.core.Tracer) and not jnp.all(jnp.isfinite(p_ref)):
            raise ValueError(
                'with `dropped="hold"` the reference image must show every feature: '
                "a reference pixel is not finite."
            )
    if n_star is None:
        n_star = plane_normal_from_frames(p_ref, pixels, A, n_prior, visible=visible)
    result = RESULTS.successful
    if z1_star is None and known_length is not None:
        if throw:
            z1_star = depth_from_feature_length(p_ref, A, n_star, known_length)
        else:
            z1_star, ok = _depth_from_feature_length(p_ref, A, n_star, known_length)
            ok = ok & (z1_star > 0.0)
            result = RESULTS.where(ok, result, RESULTS.depth_recovery_failed)
    if z1_star is None:
        if origin_pixel is None:
            origin_pixel = diagonal_intersection(p_ref)
        if throw:
            z1_star = depth_from_known_length(p_ref[0], origin_pixel, A, n_star, R_star, s1)
        else:
            z1_star, ok = _depth_from_known_length(
                p_ref[0], origin_pixel, A, n_star, R_star, s1, 1e-2
            )
            ok = ok & (z1_star > 0.0)
            result = RESULTS.where(ok, result, RESULTS.depth_recovery_failed)
    return FixedCamera(
        p_ref=p_ref, A=A, R_star=R_star, s1=s1, n_star=n_star, z1_star=z1_star, result=result
    )


SETTLE_FRAMES = 10
"""`velocity_stream`'s default `settle`: the consecutive frames a new set of visible
features must be seen in before the estimator's error signal is computed from it."""


def consistent_frames(
    visible: Bool[ArrayLike, "N n"], measurable: Bool[ArrayLike, " N"], settle: int
) -> Bool[Array, " N"]:
    """The frames to use so that the features behind each used frame's measurement are
    those of the used frame before it (`velocity_stream(dropped="hold")`): a frame is used
    when it is `measurable` and sees the features in use; the features in use become a
    frame's own once the same features have been seen in `settle` consecutive frames.
    The first frame's features are in use from the start."""
    visible = jnp.asarray(visible, bool)
    measurable = jnp.asarray(measurable, bool)
    settle = int(settle)
    if settle < 1:
        raise ValueError(f"`settle` must be a positive number of frames; got {settle}.")

    def step(carry, frame):
        current, last, count = carry
        vis, ok = frame
        count = jnp.where(jnp.all(vis == last), count + 1, 1)
        switch = ok & (count >= settle)
        use = ok & (jnp.all(vis == current) | switch)
        return (jnp.where(switch, vis, current), vis, count), use

    start = (visible[0], visible[0], jnp.asarray(0))
    _, used = jax.lax.scan(step, start, (visible, measurable))
    return used


def velocity_stream(
    ts: Float[ArrayLike, " N"],
    pixels: Float[ArrayLike, "N n 2"],
    camera: FixedCamera,
    *,
    dropped: str = "stop",
    reject: Bool[ArrayLike, " N"] | Bool[ArrayLike, "N n"] | None = None,
    truth=None,
    throw: bool = True,
    chunk: int = 256,
    settle: int = SETTLE_FRAMES,
) -> Stream:
    """The measurement `Stream` of the velocity estimator from raw pixel frames and the
    fixed camera's constants (`fixed_camera` measures them from the same frames).

    The run starts at the first frame of `pixels`, with $\\hat e(t_0) = e(t_0)$ (the
    reference image is `camera.p_ref`). The stream's `ys` are the pixels and its `measure`
    a `FrameMeasure` of the camera: $e$, $J$, $J^{-1}$ of each frame are computed by `run`
    in chunks of `chunk` steps fused with the time loop, so a run of any length needs
    memory for one chunk of prepared frames, not for the whole trajectory
    (`Stream.measured()` prepares them all, to look at them). The default suits `vmap` over
    many runs (about 16,000 frames per chunk call, batch x `chunk`, is fastest on a CPU);
    for one long trajectory `chunk=len(ts)` with `run(..., unroll=8)` runs twice as fast
    (~700 bytes per prepared frame).

    A missing sample is a NaN pixel. With `dropped="hold"` it is a feature out of view in
    that frame. The estimator's error signal $e$ must come from one set of features from
    frame to frame: the homographies of two different subsets of noisy features differ,
    and $e$ would jump by that difference between two frames, which the sign-based law
    reads as a velocity (Chitrakaran et al.'s estimator assumes a continuous $e$, eq.
    (36)). So a frame is used only when it sees the same features as the frame used before
    it; a frame that misses a feature the others see is held (marked absent in
    `Stream.present`: `run` holds the previous frame over it). A new set of features (one
    that left the view for good) is taken once it has been seen in `settle` consecutive
    frames: from then on the homography is fitted to the features seen (with more than
    four features, any four or more; feature 1 may be among the missing). A frame with
    too few features is held too; the first frame must be measurable.

    With `dropped="stop"` (default) a frame that cannot be measured (a NaN pixel,
    degenerate points) raises with `throw=True` (one pass over the frames for their result
    codes, `chunk` at a time), and with `throw=False` is all NaN:
    `run` stops there with `RESULTS.nonfinite_measurement` and its index.

    `reject`: the samples an outlier test rejected, held as missing ones. (N,) bool: whole
    frames, held over like a dropped frame (the first frame must be kept); (N, n): single
    features, out of view in those frames (as a NaN pixel with `dropped="hold"`, which a
    per-feature mask needs).

    `settle`: with `dropped="hold"`, the consecutive frames a new set of features must be
    seen in before it replaces the one in use (default `SETTLE_FRAMES`, 10: 10 ms at 1 kHz;
    1 uses every measurable frame with the features it sees).

    **Returns:** the `Stream` (its `measure.camera` is `camera`).
    """
    pixels = _check_frames(pixels, ts)
    dropouts = _dropped(dropped)
    reject = reject_mask(reject, pixels.shape[0], pixels.shape[1])
    if reject is not None and reject.ndim == 2:
        if not dropouts:
            raise ValueError(
                'a per-feature `reject` (N, n) needs `dropped="hold"` (a rejected feature is '
                "out of view in that frame); reject whole frames with a mask of shape (N,)."
            )
        pixels = jnp.where(reject[..., None], jnp.nan, pixels)
        reject = None
    ts = as_float(ts)
    if not isinstance(camera, FixedCamera):
        raise TypeError(
            f"`camera` must be a FixedCamera (see `fixed_camera`); got {type(camera).__name__}."
        )
    if camera.p_ref.shape != pixels.shape[1:]:
        raise ValueError(
            f"`camera.p_ref` must have the frames' shape {tuple(pixels.shape[1:])}; "
            f"got {tuple(camera.p_ref.shape)}."
        )
    measure = FrameMeasure(camera=camera, dropouts=dropouts)
    present = None
    if dropouts or throw:
        # one pass over the frames for their result codes only, `chunk` at a time
        results = _frame_results(measure, pixels, chunk)
        if dropouts:
            visible = jnp.all(jnp.isfinite(pixels), axis=-1)
            present = consistent_frames(visible, results == RESULTS.successful, settle)
            # the first frame starts the estimator: it must be measured
            if throw:
                present = eqx.error_if(
                    present, ~present[0], "velocity_stream: the first frame cannot be measured."
                )
        else:
            # the first frame that cannot be measured raises with its own message (the
            # check rides on the reference pixels, which every measurement reads: no copy
            # of the frames)
            bad = results != RESULTS.successful
            first = jax.tree_util.tree_map(lambda v: v[jnp.argmax(bad)], results)
            checked = first.error_if(camera.p_ref, jnp.any(bad))
            measure = eqx.tree_at(lambda m: m.camera.p_ref, measure, checked)
    stream = Stream(ts=ts, ys=pixels, truth=truth, present=present, measure=measure, chunk=chunk)
    return rejected_samples(stream, reject)


def velocity_innovation(
    stream: Stream,
    solution,
    estimator: "VelocityEstimator",
    *,
    t_start: float | Float[ArrayLike, ""] = -jnp.inf,
    t_end: float | Float[ArrayLike, ""] = jnp.inf,
    step: float | None = None,
    batch_size: int | None = None,
) -> Innovation:
    """The output error of Chitrakaran et al.'s estimator, $\\tilde e = e - \\hat e$ (eq.
    (36)), against the noise level its measurements imply (`Innovation`): a check of a run
    without the truth. Theorem 1 drives $\\tilde e$ to zero (eq. (35)); with noisy samples it
    settles at the noise of $e$, and sampled at the step $h$ the sign term keeps a limit
    cycle of amplitude $\\frac{4}{\\pi}\\rho_i h/(k_i + 1)$ (see `VelocityEstimator`), the
    estimator's own floor of $\\tilde e_i$. An output error far above both (`ratio`) is an
    estimator that lags its measurements or has lost them: its velocity, $J^{-1}\\hat\\kappa$,
    is not to be trusted.

    **Arguments:** `stream` (`velocity_stream`, the frames the run used); `solution`, the
    run's `Solution` saved with its diagnostics (`SaveAt(diagnostics=True)`: $\\tilde e$ at
    its saved times; each used frame takes the value saved at or before it); `estimator`
    (its gains give the floor); `step`, the run's integration step $h$ (default: the
    frames' median interval, `run`'s default); the samples counted are those used and
    inside `[t_start, t_end)`.

    Pure JAX (`jit`, `vmap`, `grad`); memory: the stream's prepared frames (`Stream.measured`,
    `batch_size` at a time)."""
    diagnostics = getattr(solution, "diagnostics", None)
    if not isinstance(diagnostics, VelocityDiagnostics):
        raise ValueError(
            "`solution` must be a velocity estimator's run saved with its diagnostics "
            "(`SaveAt(diagnostics=True)`)."
        )
    ts = solution.ts
    y = stream.measured(batch_size).ys
    t = stream.ts
    k = jnp.searchsorted(ts, t + 1e-9, side="right") - 1
    e_tilde = diagnostics.e_tilde[jnp.clip(k, 0, ts.shape[0] - 1)]
    used = (k >= 0) & (t >= t_start) & (t < t_end)
    if stream.present is not None:
        used = used & stream.present
    h = median_interval(t) if step is None else step
    floor = 4.0 / jnp.pi * estimator.rho * h / (estimator.K + 1.0)  # the sign term's chatter
    return innovation(y.e, e_tilde, used, floor)
