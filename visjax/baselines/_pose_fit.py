"""Batch and filter baselines of the velocity problem of Chitrakaran, Dawson, Dixon and Chen,
*Identification of a moving object's velocity with a fixed camera*: the object's pose in
every frame, then its velocity as the derivative of a local least-squares fit of the pose
trajectory (centred: a smoother using all frames around $t$; causal: frames up to $t$),
and an extended Kalman filter with a constant-acceleration model. Not in the paper: the
answers a researcher would otherwise compute from the same pixels.

The pose: the features' coordinates $s_i$ in the object frame follow from the reference
image, $n^*$ and $z_1^*$ (eqs. (3)-(5): $\\bar m_i^* = d^* A^{-1}p_i^* / (n^{*T}A^{-1}p_i^*)$
with $d^* = z_1^* n^{*T}A^{-1}p_1^*$, and $s_i = R^{*T}(\\bar m_i^* - x_f^*)$ with
$x_f^* = \\bar m_1^* - R^* s_1$); in frame $t$ a feature is at $\\bar m_i = x_f + R s_i$
(eq. (5)) and its pixel at $p_i = A\\bar m_i / z_i$ (eq. (15)). The homography gives
$R = \\bar R R^*$ (eq. (8)) and $x_f = d^*\\bar x_h + \\bar R x_f^*$ (eqs. (12)-(13)); a
Gauss-Newton fit of the reprojection error (`optimistix.least_squares`; started this close,
it converges in a few steps where Levenberg-Marquardt's damping stalled on some frames)
refines them.
The velocity is $[v_e, \\omega_e]$ in the camera frame, $v_e = \\dot x_f$ and
$[\\omega_e]_\\times = \\dot R R^T$, the quantity of the paper's eqs. (29)-(31).
"""

import math
from typing import final

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, ArrayLike, Float

from .._results import RESULTS, all_finite, raise_or_keep
from .._small import spd_solve
from .._util import as_float, check_shape, median_interval, solver_tolerance
from ..estimators import FixedCamera, Solution, VelocityOutput
from ..geometry import euclidean_reconstruction, so3_exp, so3_log
from ._ekf import AbstractEKFModel, baseline_solution, extended_kalman_filter
from ._losses import as_loss, covariance


@final
class FramePoses(eqx.Module):
    """The object's pose per frame: `R` (N, 3, 3), `x_f` (N, 3) in the camera frame,
    `rms_px` the reprojection RMS per frame, `result` per frame (a failed frame is NaN),
    and `cov` (N, 6, 6) the covariance of the pose (`covariance`: the rotation as the
    rotation vector $\\phi$ of $R = e^{[\\phi]_\\times}R_0$ about the homography's estimate
    $R_0$, then $x_f$) from the frame's own residuals; NaN without refinement or with
    fewer than four features seen."""

    R: Float[Array, "*N 3 3"]
    x_f: Float[Array, "*N 3"]
    rms_px: Float[Array, "*N"]
    result: RESULTS
    cov: Float[Array, "*N 6 6"]


@final
class SmootherDiagnostics(eqx.Module):
    """The diagnostics of `velocity_smoother`: `poses`, the `FramePoses` the fit used, and
    `cov` (N, 6, 6), the covariance of each frame's $\\hat v = [v_e, \\omega_e]$ (camera
    frame) propagated from the poses' covariances: the velocity is a linear combination
    $\\sum_j c_j y_j$ of the window's poses, so
    $\\operatorname{cov}(\\hat v_k) = \\sum_j c_j^2 C_j$ with $C_j$ frame $j$'s pose
    covariance (`FramePoses.cov`, $\\hat\\sigma^2(J^TJ)^{-1}$ of the module docstring of
    `_losses.py`) reordered to $[x_f, \\phi]$; first order in the rotations' errors,
    frames independent. It is the spread from the pixel noise only, not the fit's bias (a
    motion faster than its bandwidth). NaN where the velocity is, or where the poses have
    no covariance (`refine=False`, fewer than four features seen)."""

    poses: FramePoses
    cov: Float[Array, "*N 6 6"]


def object_features(camera: FixedCamera):
    """The features in the object frame, (n, 3), and $x_f^*$ from the fixed camera's
    reference image and constants (module docstring; Chitrakaran et al., eqs. (3)-(5))."""
    p_ref, A, R_star, s1 = camera.p_ref, camera.A, camera.R_star, camera.s1
    n_star, z1_star = camera.n_star, camera.z1_star
    q = jnp.linalg.solve(A, jnp.concatenate([p_ref, jnp.ones_like(p_ref[:, :1])], 1).T).T
    d_star = z1_star * (n_star @ q[0])
    m_star = d_star * q / (q @ n_star)[:, None]
    x_f_star = m_star[0] - R_star @ s1
    return (m_star - x_f_star[None]) @ R_star, x_f_star


def _pixels(A, R, x_f, s):
    m = x_f[None] + s @ R.T
    q = m @ A.T
    return q[:, :2] / q[:, 2:]


def _check(pixels, camera):
    pixels = as_float(pixels)
    if pixels.ndim != 3 or pixels.shape[-1] != 2 or pixels.shape[1] < 4:
        raise ValueError(f"`pixels` must have shape (N, n >= 4, 2); got {tuple(pixels.shape)}.")
    if not isinstance(camera, FixedCamera):
        raise TypeError(
            f"`camera` must be a FixedCamera (see `estimators.fixed_camera`); "
            f"got {type(camera).__name__}."
        )
    check_shape(camera.p_ref, pixels.shape[1:], "camera.p_ref")
    c = camera
    return pixels, c.p_ref, c.A, c.R_star, c.s1, c.n_star, c.z1_star


def frame_poses(
    pixels: Float[ArrayLike, "N n 2"],
    camera: FixedCamera,
    *,
    refine: bool = True,
    max_steps: int = 1000,
    loss=None,
) -> FramePoses:
    """The object's pose in every frame from the homography (Chitrakaran et al., eqs.
    (8)-(17), the known-normal path), refined by Gauss-Newton on the reprojection
    error in pixels (rotation as a rotation vector about the homography's estimate); a NaN
    pixel is a feature not seen in that frame (at least four must be). Vmapped over
    frames; a frame that cannot be measured has its `result` and NaN pose. `loss`: `None`
    (least squares) or a robust `Loss` on each feature's pixel residual (`huber(k)`,
    `cauchy(k)`, `k` in pixels): an outlier feature then weighs less; the fit is then
    iteratively reweighted least squares from the homography's pose, refined by
    Gauss-Newton on the rescaled residuals (`_losses.py`) from there. The covariance of
    each pose (`FramePoses.cov`) is $\\hat\\sigma^2(J^TJ)^{-1}$ of the (rescaled) residuals."""
    pixels, p_ref, A, R_star, s1, n_star, z1_star = _check(pixels, camera)
    loss = as_loss(loss)
    s, x_f_star = object_features(camera)
    d_star = z1_star * (n_star @ jnp.linalg.solve(A, jnp.append(p_ref[0], 1.0)))
    tol = solver_tolerance(1e-9, A.dtype)  # float64: 1e-9; float32: 1000 eps
    solver = optx.GaussNewton(rtol=tol, atol=tol)

    def one(p):
        # NaN: a feature not seen; inf: a bad measurement (the frame's result says so)
        seen = ~jnp.any(jnp.isnan(p), axis=-1)
        bad_pixel = jnp.any(jnp.isinf(p))
        p = jnp.where(jnp.isinf(p), jnp.nan, p)
        rec = euclidean_reconstruction(p_ref, p, A, n_star=n_star, visible=seen, throw=False)
        ok = rec.result == RESULTS.successful
        R_bar = jnp.where(ok, rec.R_bar, jnp.eye(3, dtype=A.dtype))
        R0 = R_bar @ R_star  # eq. (8)
        x0 = d_star * jnp.where(ok, rec.x_h, 0.0) + R_bar @ x_f_star  # eqs. (12)-(13)
        p_clean = jnp.where(seen[:, None], p, 0.0)

        def residuals(y, _):
            r = _pixels(A, so3_exp(y[0]) @ R0, y[1], s) - p_clean
            return jnp.where(seen[:, None], r, 0.0)

        def robust(y, _):
            return loss(residuals(y, None))

        def reweighted(y, _):
            # each block weighted by psi(s)/s at the current residuals, held fixed in the
            # step: Gauss-Newton on these is iteratively reweighted least squares
            r = residuals(y, None)
            return jnp.sqrt(jax.lax.stop_gradient(_irls_weight(loss, r)))[:, None] * r

        y0 = (jnp.zeros(3, A.dtype), x0)
        if refine:
            code = RESULTS.successful
            if loss.kind != "squared":
                sol = optx.least_squares(reweighted, solver, y0, max_steps=max_steps, throw=False)
                y0, code = sol.value, RESULTS.promote(sol.result)
            # (least squares; or, from the reweighted fit's answer, the M-estimate itself:
            # its derivatives with respect to the pixels are those of the loss)
            sol = optx.least_squares(robust, solver, y0, max_steps=max_steps, throw=False)
            y = sol.value
            code = RESULTS.where(code == RESULTS.successful, RESULTS.promote(sol.result), code)
            cov, _ = covariance(robust, y, None, 2 * jnp.sum(seen))
        else:
            y, code = y0, RESULTS.successful
            cov = jnp.full((6, 6), jnp.nan, A.dtype)
        R, x_f = so3_exp(y[0]) @ R0, y[1]
        r = residuals(y, None)
        rms = jnp.sqrt(jnp.sum(r**2) / (2.0 * jnp.maximum(jnp.sum(seen), 1).astype(r.dtype)))
        result = RESULTS.where(ok, code, rec.result)
        result = RESULTS.where(bad_pixel, RESULTS.nonfinite_measurement, result)
        result = RESULTS.where(
            (result == RESULTS.successful) & ~all_finite((R, x_f)), RESULTS.nonfinite_output, result
        )
        result = RESULTS.where(
            (result == RESULTS.successful) & ~loss.checks(), RESULTS.invalid_settings, result
        )
        bad = result != RESULTS.successful
        R, x_f, rms, cov = (jnp.where(bad, jnp.nan, v) for v in (R, x_f, rms, cov))
        return FramePoses(R=R, x_f=x_f, rms_px=rms, result=result, cov=cov)

    return jax.vmap(one)(pixels)


def _irls_weight(loss, r):
    """`Loss.irls_weight`, $\\psi(s)/s$, of the residual blocks `r` (n, 2), $s$ their norms:
    a Gauss-Newton step on the blocks weighted by its square root, the weights held fixed,
    is a step of iteratively reweighted least squares on $\\sum_i \\rho(s_i)$ (its gradient
    is the loss' own; Hartley and Zisserman, "Multiple View Geometry", app. A6.8).
    Gauss-Newton on the rescaled blocks instead (the module docstring of `_losses.py`) all
    but loses an outlier's radial direction from the Jacobian under the Cauchy loss, and
    its steps can run off (measured: a frame of a track 20 px off at 0.5 px of noise ended
    non-finite; from the reweighted fit's answer it converges in two or three steps)."""
    s2 = jnp.sum(r * r, axis=-1)
    return loss.irls_weight(jnp.where(s2 > 0, jnp.sqrt(jnp.where(s2 > 0, s2, 1.0)), 0.0))


def reprojection_residuals(
    R: Float[ArrayLike, "3 3"],
    x_f: Float[ArrayLike, "3"],
    pixels: Float[ArrayLike, "n 2"],
    A: Float[ArrayLike, "3 3"],
    s: Float[ArrayLike, "n 3"],
) -> Float[Array, "n 2"]:
    """The residuals that `frame_poses` minimises in one frame: the features `s` (object
    frame, `object_features`) at the pose `(R, x_f)` projected by `A` (Chitrakaran et al.,
    eqs. (5), (15)), minus the measured `pixels`; zero for a NaN (unseen) pixel."""
    R, x_f, pixels, A, s = (as_float(v) for v in (R, x_f, pixels, A, s))
    seen = jnp.all(jnp.isfinite(pixels), axis=-1)
    r = _pixels(A, R, x_f, s) - jnp.where(seen[:, None], pixels, 0.0)
    return jnp.where(seen[:, None], r, 0.0)


def _derivative_weights(taus, degree):
    """The weights $c_j$ with $\\sum_j c_j f(\\tau_j) = \\hat f'(0)$ of the least-squares
    polynomial of `degree` through the samples at `taus` (NumPy, for the bandwidth)."""
    V = np.vander(taus, degree + 1, increasing=True)
    return np.linalg.pinv(V)[1]


def fit_bandwidth_hz(half_width: int, dt: float, *, degree: int = 2, causal: bool = False):
    """The -3 dB bandwidth of the local least-squares differentiator of `velocity_smoother`
    (centred over `2 half_width + 1` samples, or causal over as many past ones) at sample
    interval `dt`: the lowest frequency where its gain falls to $1/\\sqrt 2$ of the ideal
    differentiator's, $|\\sum_j c_j e^{i 2\\pi f \\tau_j}| = 2\\pi f/\\sqrt 2$."""
    j = np.arange(-2 * half_width, 1) if causal else np.arange(-half_width, half_width + 1)
    c = _derivative_weights(j * dt, degree)
    span = (j[-1] - j[0]) * dt
    f = np.geomspace(1e-3 / span, 0.5 / dt, 2000)
    gain = np.abs(np.exp(2j * np.pi * np.outer(f, j * dt)) @ c) / (2 * np.pi * f)
    below = np.nonzero(gain < 1 / math.sqrt(2))[0]
    return float(f[below[0]]) if below.size else 0.5 / dt


def half_width_for_bandwidth(bandwidth_hz: float, dt: float, *, degree=2, causal=False) -> int:
    """The smallest half-width whose bandwidth (`fit_bandwidth_hz`) is at most
    `bandwidth_hz` (at least `degree`)."""
    if not (bandwidth_hz > 0 and dt > 0):
        raise ValueError(
            f"`bandwidth_hz` and the sample interval must be positive; got "
            f"{bandwidth_hz!r}, {dt!r}."
        )
    lo = max(1, degree)
    if fit_bandwidth_hz(lo, dt, degree=degree, causal=causal) <= bandwidth_hz:
        return lo
    hi = 2 * lo
    while fit_bandwidth_hz(hi, dt, degree=degree, causal=causal) > bandwidth_hz:
        lo, hi = hi, 2 * hi  # the bandwidth falls as the window grows
        if hi > 100_000:
            raise ValueError(f"`bandwidth_hz` = {bandwidth_hz!r} needs a window over 1e5 samples.")
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if fit_bandwidth_hz(mid, dt, degree=degree, causal=causal) <= bandwidth_hz:
            hi = mid
        else:
            lo = mid
    return hi


def _window_offsets(half_width, causal):
    return jnp.arange(-2 * half_width, 1) if causal else jnp.arange(-half_width, half_width + 1)


def _derivative_rows(ok, ts, half_width, degree, causal):
    """Per frame $k$: the frames of its window (`idx` (N, W), clipped to the run), which of
    them the fit uses (`use`), and the weights $c_j$ (N, W) of the fit's slope at $t_k$,
    $\\hat y'(t_k) = \\sum_j c_j y_j$ (zero for a frame not used); NaN weights where frame
    $k$ itself was not measured."""
    n = ts.shape[0]
    offsets = _window_offsets(half_width, causal)

    def at(k):
        idx = k + offsets
        inside = (idx >= 0) & (idx < n)
        idx = jnp.clip(idx, 0, n - 1)
        use = inside & ok[idx]
        tau = jnp.where(use, ts[idx] - ts[k], 0.0)
        scale = jnp.maximum(jnp.max(jnp.abs(tau)), jnp.finfo(ts.dtype).tiny)
        V = jnp.stack([(tau / scale) ** d for d in range(degree + 1)], axis=1)
        w = use.astype(ts.dtype)
        count = jnp.sum(use)
        # fewer frames than degree + 1 (the start of a causal fit): the degree drops to
        # count - 1; one frame gives a zero slope (no motion seen yet)
        unused = (jnp.arange(degree + 1) >= count).astype(ts.dtype)
        Vw = V * w[:, None]
        G = Vw.T @ V + jnp.diag(unused)
        # the slope at tau = 0 is row 1 of G^-1 (V w)^T, i.e. (V w) G^-1 e_1 (G symmetric):
        # one small solve, elementwise (`spd_solve`), not a batched LAPACK call per frame
        e1 = (jnp.arange(degree + 1) == 1).astype(ts.dtype)
        c = Vw @ spd_solve(G, e1) / scale  # d/dt at tau = 0
        c = jnp.where(use, c, 0.0)
        return idx, use, jnp.where((count >= 1) & ok[k], c, jnp.nan)

    return jax.vmap(at)(jnp.arange(n))


def _velocity_outputs(poses, ts, half_width, degree, causal):
    ok = poses.result == RESULTS.successful
    idx, use, c = _derivative_rows(ok, ts, half_width, degree, causal)

    def at(k, idx, use, c):
        R_k = jnp.where(ok[k], poses.R[k], jnp.eye(3, dtype=ts.dtype))
        R_j = jnp.where(use[:, None, None], poses.R[idx], jnp.eye(3, dtype=ts.dtype))
        rot = jax.vmap(lambda R: so3_log(R @ R_k.T).omega)(R_j)  # exp(rot) R_k = R_j
        pos = jnp.where(use[:, None], poses.x_f[idx], 0.0)
        v = c @ jnp.concatenate([pos, rot], 1)
        R = poses.R[k]
        return VelocityOutput(v_hat=v, v_object=jnp.concatenate([R.T @ v[:3], R.T @ v[3:]]))

    return jax.vmap(at)(jnp.arange(ts.shape[0]), idx, use, c)


def velocity_covariance(
    poses: FramePoses,
    ts: Float[ArrayLike, " N"],
    half_widths: tuple[int, ...],
    *,
    degree: int = 2,
    causal: bool = False,
) -> Float[Array, "N 6 6"]:
    """The covariance (N, 6, 6) of the velocity $[v_e, \\omega_e]$ that `velocity_smoother`
    fits to the frames' poses (`frame_poses`), component $i$ from a local polynomial fit of
    degree `degree` and half-width `half_widths[i]` samples (six of them; one width for
    all six is `velocity_smoother`'s own covariance, `SmootherDiagnostics.cov`; the
    velocity problem gives each degree of freedom its own bandwidth). First order in each
    frame's pose covariance (`FramePoses.cov`), frames independent; NaN where a window
    holds a failed frame. Pure JAX (`jit`, `vmap`, `grad`; `half_widths`, `degree` and
    `causal` static).

    **Raises:** `ValueError` for `half_widths` that are not six positive ints."""
    half_widths = tuple(half_widths)
    if len(half_widths) != 6 or not all(
        isinstance(m, int | np.integer) and m >= 1 for m in half_widths
    ):
        raise ValueError(f"`half_widths` must be six positive ints; got {half_widths!r}.")
    if not isinstance(degree, int) or degree < 1:
        raise ValueError(f"`degree` must be a positive int; got {degree!r}.")
    return _velocity_covariance(
        poses, as_float(ts), tuple(int(m) for m in half_widths), degree, bool(causal)
    )


def _velocity_covariance(poses, ts, half_widths, degree, causal):
    """The covariance (N, 6, 6) of the fitted velocity $[v_e, \\omega_e]$, component $i$ from
    the fit of half-width `half_widths[i]` (one per component; all equal for one fit).

    Each component is a linear combination of the window's poses, $\\hat v_{k,i} =
    \\sum_j c^{(i)}_j y_{j,i}$ with $y_j = [x_{f,j}, \\log(R_j R_k^T)]$. To first order in
    the rotations' errors ($R_j = e^{[\\delta\\phi_j]_\\times}\\bar R_j$, `FramePoses.cov`),
    $\\log(R_j R_k^T)$ moves by $\\delta\\phi_j - \\delta\\phi_k$ over a window short
    enough that the relative rotations are small, and $\\sum_j c_j = 0$ (the slope of a
    constant is zero) cancels $\\delta\\phi_k$; with independent frames,
    $\\operatorname{cov}(\\hat v_{k,i}, \\hat v_{k,l}) = \\sum_j c^{(i)}_j c^{(l)}_j
    C_{j,il}$, $C_j$ frame $j$'s pose covariance ($\\hat\\sigma^2(J^TJ)^{-1}$, the module
    docstring of `_losses.py`) reordered to $[x_f, \\phi]$. Computed by a scan over the
    window's offsets (memory O(N), not O(N x window))."""
    ok = poses.result == RESULTS.successful
    widest = max(half_widths)
    rows = {}
    for M in sorted(set(half_widths)):
        idx, use, c = _derivative_rows(ok, ts, M, degree, causal)
        # placed in the widest window: its offsets are the ends of the widest one's
        pad = 2 * (widest - M)
        before, after = (pad, 0) if causal else (pad // 2, pad // 2)
        rows[M] = jnp.pad(c, ((0, 0), (before, after)))
    n = ts.shape[0]
    idx = jnp.clip(jnp.arange(n)[:, None] + _window_offsets(widest, causal)[None], 0, n - 1)
    c = jnp.stack([rows[M] for M in half_widths], axis=-1)  # (N, W', 6)
    order = jnp.array([3, 4, 5, 0, 1, 2])  # [phi, x_f] -> [x_f, phi]
    C = poses.cov[:, order][:, :, order]

    def add(total, column):
        j, cj = column
        pair = cj[:, :, None] * cj[:, None, :]
        # a frame outside the fit has zero weight (and maybe a NaN covariance)
        return total + pair * jnp.where(pair != 0.0, C[j], 0.0), None

    total = jnp.zeros((n, 6, 6), ts.dtype)
    total, _ = jax.lax.scan(add, total, (idx.T, jnp.moveaxis(c, 1, 0)))
    return total  # NaN where frame k's velocity is (its weights are NaN)


def velocity_smoother(
    ts: Float[ArrayLike, " N"],
    pixels: Float[ArrayLike, "N n 2"],
    camera: FixedCamera,
    *,
    bandwidth_hz: float,
    causal: bool = False,
    degree: int = 2,
    sample_interval: float | None = None,
    poses: FramePoses | None = None,
    loss=None,
    throw: bool = True,
) -> Solution:
    """The velocity as the derivative of a local least-squares polynomial fit of the pose
    trajectory (`frame_poses`; module docstring).

    At each frame $t_k$: the position $x_f$ and the rotation vector $\\log(R_j R_k^T)$ of
    the frames $j$ in the window, fitted by a polynomial of `degree` in $t_j - t_k$; its
    slope at $t_k$ is $[v_e, \\omega_e]$ (camera frame) and $R_k^T$ of it the velocity in
    the object frame (Remark 6). `causal=False`: the window is centred (a smoother: it uses
    frames after $t_k$); `causal=True`: the window is the $2M + 1$ frames up to $t_k$ (the
    estimate at $t$ uses only frames up to $t$). The half-width $M$ is the smallest whose
    -3 dB bandwidth (`fit_bandwidth_hz`, at the median sample interval) is at most
    `bandwidth_hz`: state the observer's bandwidth here to compare at equal bandwidth.
    The window's size is static: under `jax.jit` give the nominal `sample_interval`
    (seconds; by default the median interval of `ts`, which must then be concrete).
    Exact (to rounding) for a pose whose position and rotation vector are polynomials of
    at most `degree` in time over each window, e.g. a constant twist. At the start of a
    causal fit, fewer than `degree + 1` frames lower the degree (one frame: zero velocity,
    no motion seen yet). `poses`: the `frame_poses` of these pixels, if already computed
    (e.g. for fits at several bandwidths). `loss`: the loss of each feature's pixel
    residual in the pose fits (`frame_poses`; `None`, least squares, or a robust `Loss`
    such as `cauchy(k)`, `k` in pixels, for tracks with outliers); give it to `frame_poses`
    instead when passing `poses`.

    **Returns:** a `Solution` with `ts`, `outputs` a `VelocityOutput` per frame,
    `diagnostics` a `SmootherDiagnostics` (the `FramePoses`, and the covariance of each
    frame's $\\hat v$ propagated from theirs), `result` the first failed frame's code (a
    frame that cannot be measured, or a window with too few measured frames; NaN there)
    and `failed_sample`.
    """
    ts = as_float(ts)
    check_shape(ts, (jnp.shape(pixels)[0],), "ts")
    if not (isinstance(degree, int) and degree >= 1):
        raise ValueError(f"`degree` must be a positive int; got {degree!r}.")
    if sample_interval is None:
        if isinstance(ts, jax.core.Tracer):
            raise ValueError("under jit, give `sample_interval` (the window size is static).")
        sample_interval = float(np.median(np.diff(np.asarray(ts))))
    dt = float(sample_interval)
    M = half_width_for_bandwidth(bandwidth_hz, dt, degree=degree, causal=causal)
    if poses is None:
        poses = frame_poses(pixels, camera, loss=loss)
    elif loss is not None:
        raise ValueError(
            "give `loss` to `frame_poses` when passing `poses` (the poses are already fitted)."
        )
    outputs = _velocity_outputs(poses, ts, M, degree, causal)
    cov = _velocity_covariance(poses, ts, (M,) * 6, degree, causal)
    good = jnp.all(jnp.isfinite(outputs.v_hat), axis=1)
    first = jnp.argmin(good)
    frame_result = _at(poses.result, first)
    code = RESULTS.where(frame_result != RESULTS.successful, frame_result, RESULTS.nonfinite_output)
    result = RESULTS.where(jnp.all(good), RESULTS.successful, code)
    failed = jnp.where(jnp.all(good), -1, first)
    outputs = raise_or_keep(result, outputs, throw)
    diagnostics = SmootherDiagnostics(poses=poses, cov=cov)
    return baseline_solution(ts, outputs, result, failed, diagnostics)


def _at(result, k):
    """The `RESULTS` item at index `k` of a batch of them."""
    return jax.tree_util.tree_map(lambda x: x[k], result)


class _ConstantAcceleration(AbstractEKFModel):
    """State (18,): $x_f$, $\\phi$ ($R = e^{[\\phi]_\\times} R_0$), $v_e$, $\\omega_e$, and the
    two accelerations; white jerk of densities `q_lin`, `q_ang`; measurement: the features'
    pixels (eqs. (5), (15))."""

    A: Array
    s: Array
    R0: Array
    q_lin: Array
    q_ang: Array
    r_px: Array

    def transition(self, x, u, dt):
        p, phi, v, w, a, al = (x[3 * i : 3 * i + 3] for i in range(6))
        turn = so3_exp(w * dt + 0.5 * al * dt**2) @ so3_exp(phi)
        return jnp.concatenate(
            [p + v * dt + 0.5 * a * dt**2, so3_log(turn).omega, v + a * dt, w + al * dt, a, al]
        )

    def process_noise(self, x, u, dt):
        block = jnp.array(
            [
                [dt**5 / 20, dt**4 / 8, dt**3 / 6],
                [dt**4 / 8, dt**3 / 3, dt**2 / 2],
                [dt**3 / 6, dt**2 / 2, dt],
            ]
        )
        eye = jnp.eye(3, dtype=x.dtype)
        Q_lin = jnp.kron(block, eye) * self.q_lin  # order: p, v, a
        Q_ang = jnp.kron(block, eye) * self.q_ang  # order: phi, w, al
        order_lin = jnp.array([0, 1, 2, 6, 7, 8, 12, 13, 14])
        order_ang = jnp.array([3, 4, 5, 9, 10, 11, 15, 16, 17])
        Q = jnp.zeros((18, 18), x.dtype)
        Q = Q.at[jnp.ix_(order_lin, order_lin)].set(Q_lin)
        return Q.at[jnp.ix_(order_ang, order_ang)].set(Q_ang)

    def measure(self, x, u):
        return _pixels(self.A, so3_exp(x[3:6]) @ self.R0, x[:3], self.s).reshape(-1)

    def measurement_noise(self, x, u):
        m = 2 * self.s.shape[0]
        return self.r_px**2 * jnp.eye(m, dtype=x.dtype)

    def valid(self, x, u):
        m = x[None, :3] + self.s @ (so3_exp(x[3:6]) @ self.R0).T
        return jnp.all(m[:, 2] > 0.0)


def velocity_ekf(
    ts: Float[ArrayLike, " N"],
    pixels: Float[ArrayLike, "N n 2"],
    camera: FixedCamera,
    *,
    r_px: Float[ArrayLike, ""] = 0.5,
    max_jerk: float | ArrayLike = 1.0,
    max_angular_jerk: float | ArrayLike = 1.0,
    sigma_velocity: float | ArrayLike = 1.0,
    gate: float | ArrayLike | None = None,
    throw: bool = True,
) -> Solution:
    """An extended Kalman filter of the object's pose and twist with a constant-acceleration
    model, updated with the features' pixels (the filter one would otherwise write for the
    problem of Chitrakaran et al.; not in the paper).

    State: $x_f$, $\\phi$ with $R = e^{[\\phi]_\\times}R_0$ ($R_0$ the first frame's pose),
    $v_e$, $\\omega_e$ (camera frame) and their derivatives; prediction at each sample
    interval, $R \\leftarrow e^{[\\omega\\delta + \\dot\\omega\\delta^2/2]_\\times} R$, driven by
    white jerk. Noise settings (the documented rule): `r_px` the pixel noise (default 0.5
    px); the jerk densities $q = j_{\\max}^2 T$ with $T$ the median sample interval and
    $j_{\\max}$ = `max_jerk` (m/s^3), `max_angular_jerk` (rad/s^3), the largest jerk
    expected (Bar-Shalom et al.'s rule: the acceleration changes by about $j_{\\max} T$
    per sample); prior: the first frame's pose (`frame_poses`) with 1 mm and 1 mrad,
    velocities and accelerations zero with `sigma_velocity` (per second for the
    accelerations). The features in the object frame come from the reference image as in
    `frame_poses`. `gate`: the probability of the outlier gate on each feature's pixel pair
    (`ExtendedKalmanFilter`; `None`, the default: no gate).

    **Returns:** a `Solution` with `outputs` a `VelocityOutput` per frame (after that
    frame's update), `result` (`nonfinite_measurement` for an infinite pixel,
    `diverged` for a pose behind the camera, `nonfinite_state`), `failed_sample`, and the
    covariances as `diagnostics`.
    """
    pixels, p_ref, A, R_star, s1, n_star, z1_star = _check(pixels, camera)
    ts = as_float(ts)
    check_shape(ts, (pixels.shape[0],), "ts")
    s, _ = object_features(camera)
    first = frame_poses(pixels[:1], camera)
    R0 = jnp.where(jnp.isfinite(first.R[0]), first.R[0], jnp.eye(3, dtype=A.dtype))
    x0 = jnp.concatenate(
        [jnp.where(jnp.isfinite(first.x_f[0]), first.x_f[0], 0.0), jnp.zeros(15, A.dtype)]
    )
    T = median_interval(ts)
    model = _ConstantAcceleration(
        A=A,
        s=s,
        R0=R0,
        q_lin=(max_jerk**2 * T).astype(A.dtype),
        q_ang=(max_angular_jerk**2 * T).astype(A.dtype),
        r_px=jnp.asarray(r_px, A.dtype),
    )
    sd = jnp.concatenate(
        [jnp.full(3, 1e-3), jnp.full(3, 1e-3), jnp.full(12, sigma_velocity)]
    ).astype(A.dtype)
    sol = extended_kalman_filter(
        model, ts, pixels.reshape(pixels.shape[0], -1), None, x0, jnp.diag(sd**2), gate=gate,
        gate_size=2, throw=False,
    )  # fmt: skip
    first_result = _at(first.result, 0)
    result = RESULTS.where(first_result != RESULTS.successful, first_result, sol.result)
    failed = jnp.where(first_result != RESULTS.successful, 0, sol.failed_sample)

    def to_output(x):
        R = so3_exp(x[3:6]) @ R0
        v = x[6:12]
        return VelocityOutput(v_hat=v, v_object=jnp.concatenate([R.T @ v[:3], R.T @ v[3:]]))

    outputs = raise_or_keep(result, jax.vmap(to_output)(sol.outputs.x), throw)
    return baseline_solution(ts, outputs, result, failed, sol.outputs.P)
