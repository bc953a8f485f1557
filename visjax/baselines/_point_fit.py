"""Batch and filter baselines of the moving-point problem of Jang's thesis (a point seen by
a moving camera whose velocity is measured; the unknown input observer of eq. (3.5)):
triangulation of the point over a sliding window of past frames from the known camera
motion, and an extended Kalman filter with an inverse-depth state. Not in the thesis: the
answers one would otherwise compute from the same measurements.

Camera motion. The camera's measured velocity $u = [v_c, \\omega]$ (camera basis) is held
between its samples, as the observer holds it. A point with coordinates $P$ in a fixed
frame moves in the camera frame as $\\dot m = -v_c - \\omega\\times m$ (eq. (2.11) with
$v_p = 0$), so the camera's pose $(R, c)$ in that frame obeys $\\dot R = R[\\omega]_\\times$,
$\\dot c = R v_c$, $m = R^T(P - c)$; over an interval $\\delta$ with a held twist it moves by
$R_\\delta = e^{[\\omega\\delta]_\\times}$, $c_\\delta = J_l(\\omega\\delta)\\,v_c\\delta$
($J_l$ the left Jacobian of SO(3)): exact.

Triangulation. Over the frames $j$ of a window ending at frame $k$, the poses relative to
frame $k$ follow from the held twists; the point in frame $k$'s coordinates is modelled as
a polynomial in $\\tau = t_j - t_k$ of degree `order` (0: a static point; 1, 2: a moving
point, as in the batch reconstructions of moving points the thesis cites in its
introduction: Avidan and Shashua, "Trajectory triangulation: 3D reconstruction of moving
points from a monocular image sequence" (its ref. [1]; a point on a line at constant
speed), and Park, Shiratori, Matthews and Sheikh, "3D reconstruction of a moving point
from a series of 2D projections" (its ref. [6]; a trajectory in a basis of time
functions)), and each normalised measurement $y_j$ gives the two linear
equations $(y_{j,r} e_3 - e_r)^T m_j = 0$, $r = 1, 2$ (the collinearity of $[y_j, 1]$ and
$m_j$, eq. (3.1)). The least-squares solution is exact for noise-free data whose point
follows the model; the estimate at $t_k$ is $m_k = P(0)$, and $[X/Z, Y/Z, 1/Z]$ of it.

Robust linear fit. With a robust `loss` and no refinement, the linear solution is the start
of a fixed number of iteratively reweighted least-squares steps (Huber, *Robust
Statistics*; Hartley and Zisserman, *Multiple View Geometry*, app. A6.8): at the current
estimate each frame's pair of equations is divided by the frame's predicted depth of the
point, $z_j = e_3^T m_j$ (so that its residual is the reprojection residual in normalised
coordinates, exactly at the estimate the depth is taken from and to first order near it:
the depth reweighting of the "iterative linear" triangulation methods of Hartley and
Sturm, "Triangulation", CVIU 68(2), 1997) and weighted by the M-estimator's weight
$\\psi(s_j)/s_j = \\rho'(s_j)/s_j$ at the norm $s_j$ of that residual pair (`Loss.irls_weight`),
and the weighted normal equations are solved again. An outlier frame's weight falls as
its residual grows (Cauchy: as $k^2/s_j^2$), where least squares lets it pull the point
as much as its residual is large.

Refinement. The algebraic residuals above weigh each frame by the point's depth, so under
pixel noise the linear solution is not the maximum-likelihood one. For a static point
(`order=0`) `refine=True` takes it as the start of a Levenberg-Marquardt minimisation of
the reprojection residuals in normalised coordinates, $r_j = y_j - \\pi(R_{kj}^T(P -
c_{kj}))$ with $\\pi(m) = [m_1/m_3, m_2/m_3]$ ($R_{kj} = R_k^TR_j$, $c_{kj} = R_k^T(c_j -
c_k)$: frame $j$'s pose in frame $k$), the cost $\\frac12\\sum_j\\|r_j\\|^2$ that
`triangulation_residuals` evaluates: the maximum-likelihood point under isotropic
Gaussian pixel noise and equal focal lengths (the classical two-step triangulation, a
linear start refined by nonlinear least squares: Hartley and Zisserman, *Multiple View
Geometry in Computer Vision*, 2nd ed., sections 12.2 and 12.3).
"""

from typing import final

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, ArrayLike, Float

from .._results import RESULTS, all_finite, raise_or_keep
from ..estimators import MovingPointOutput, Solution, Stream
from ..geometry import skew, so3_exp
from ..kinematics import perspective_dynamics
from ._ekf import AbstractEKFModel, baseline_solution, extended_kalman_filter
from ._losses import as_loss, covariance


def _left_jacobian(phi):
    """$J_l(\\phi) = I + \\frac{1 - \\cos\\theta}{\\theta^2}[\\phi]_\\times + \\frac{\\theta -
    \\sin\\theta}{\\theta^3}[\\phi]_\\times^2$, its series below 1e-4 rad (NaN-free in value
    and gradient)."""
    t2 = phi @ phi
    small = t2 < 1e-8
    t2s = jnp.where(small, 1.0, t2)
    t = jnp.sqrt(t2s)
    a = jnp.where(small, 0.5 - t2 / 24.0, (1.0 - jnp.cos(t)) / t2s)
    b = jnp.where(small, 1.0 / 6.0 - t2 / 120.0, (t - jnp.sin(t)) / (t2s * t))
    K = skew(phi)
    return jnp.eye(3, dtype=phi.dtype) + a * K + b * K @ K


def camera_poses(ts: Float[ArrayLike, " N"], u: Float[ArrayLike, "N 6"]):
    """The camera's pose at each sample in the frame of the first, from its measured
    velocities held between samples (module docstring): `(R, c)`, (N, 3, 3) and (N, 3), with
    $m = R^T(P - c)$ for a point at $P$."""
    ts, u = jnp.asarray(ts), jnp.asarray(u)
    dts = jnp.diff(ts)

    def step(pose, k):
        R, c = pose
        phi = u[k, 3:] * dts[k]
        R_d, c_d = so3_exp(phi), _left_jacobian(phi) @ (u[k, :3] * dts[k])
        new = (R @ R_d, c + R @ c_d)
        return new, new

    first = (jnp.eye(3, dtype=u.dtype), jnp.zeros(3, u.dtype))
    _, (R, c) = jax.lax.scan(step, first, jnp.arange(ts.shape[0] - 1))
    return jnp.concatenate([first[0][None], R]), jnp.concatenate([first[1][None], c])


def _reprojection(P, R_kj, c_kj, y, use):
    """The reprojection residuals of a static point `P` (frame k's coordinates) in the
    frames of a window: $y_j - \\pi(R_{kj}^T(P - c_{kj}))$ (module docstring), zero where
    `use` is false (the depth there replaced by 1, so value and gradient stay finite)."""
    m = jnp.einsum("nji,nj->ni", R_kj, P[None] - c_kj)  # R_kj^T (P - c_kj)
    z = jnp.where(use, m[:, 2], 1.0)
    return jnp.where(use[:, None], y - m[:, :2] / z[:, None], 0.0)


def _window_poses(R, c, k, idx):
    """The poses of the frames `idx` in frame `k`'s coordinates: $R_{kj} = R_k^TR_j$,
    $c_{kj} = R_k^T(c_j - c_k)$."""
    R_kj = jnp.einsum("ji,njk->nik", R[k], R[idx])  # R_k^T R_j
    c_kj = (c[idx] - c[k][None]) @ R[k]  # R_k^T (c_j - c_k)
    return R_kj, c_kj


def _check_stream(stream):
    if not isinstance(stream, Stream):
        raise ValueError(f"`stream` must be a visjax Stream; got {type(stream).__name__}.")
    y, u = stream.ys.y, stream.ys.u
    n = jnp.shape(stream.ts)[0]
    if jnp.shape(y) != (n, 2) or jnp.shape(u) != (n, 6):
        raise ValueError(
            f"the stream must carry `y` ({n}, 2) and `u` ({n}, 6); got {jnp.shape(y)} and "
            f"{jnp.shape(u)}."
        )
    return y, u


def _output(m):
    x_hat = jnp.stack([m[0] / m[2], m[1] / m[2], 1.0 / m[2]])
    return MovingPointOutput(x_hat=x_hat, position=m)


@final
class TriangulationDiagnostics(eqx.Module):
    """Per frame (window): `codes` its `RESULTS` code and `cov` (N, 3, 3) the covariance of
    its point (the current camera frame's coordinates)."""

    codes: RESULTS
    cov: Float[Array, "N 3 3"]


def triangulate_point(
    stream: Stream,
    *,
    window: int,
    order: int = 0,
    rcond: float = 1e-9,
    min_baseline: float | ArrayLike = 0.0,
    refine: bool = False,
    loss=None,
    irls_steps: int = 10,
    max_steps: int = 64,
    rtol: float = 1e-8,
    atol: float = 1e-10,
    throw: bool = True,
) -> Solution:
    """Triangulate the point at every frame from the last `window` frames (fewer at the
    start) and the camera velocities between them (module docstring).

    **Arguments:** `stream` the observer's stream (`moving_point_stream`: normalised
    coordinates `y` and camera velocities `u`; a NaN frame is skipped); `window` the frames
    per fit (static); `order` the degree of the point's trajectory over the window (0: a
    static point); `rcond` the smallest accepted ratio of the smallest to the largest
    eigenvalue of the normal equations (scaled to unit columns): below it the window does
    not determine the point (no camera translation, too few frames), `RESULTS.singular`;
    `min_baseline` (in the units of the camera velocities times seconds; default 0: no
    test): the warm-up lasts until a window whose camera centres reach `min_baseline` from
    the current one determines the point (the triangulation angle is about the baseline
    over the distance: with pixel noise $\\sigma$ and focal $f$, a window whose angle is
    under a few $\\sigma/f$ gives a depth of either sign, so a lucky early window of a few
    frames would end the warm-up and the next one fail; the point's own estimate is no
    guide to its distance there, so the caller states the baseline, from a depth guess);
    `refine` (static point only, `order=0`): start a Levenberg-Marquardt minimisation of
    the reprojection residuals (module docstring; the cost of `triangulation_residuals`)
    from each window's linear solution, and return its minimiser, the maximum-likelihood
    point under isotropic pixel noise; `max_steps`, `rtol`, `atol` those of its solver
    (`optimistix.LevenbergMarquardt`; the residuals are normalised coordinates, the
    unknowns in the units of the camera velocities), unused without `refine`; `loss`:
    `None` (least squares) or a robust `Loss` on each frame's reprojection residual pair
    (`huber(k)`, `cauchy(k)`, `k` in normalised coordinates: the pixel scale over the
    focal length): with `refine`, the refinement's cost; without it, the linear fit's, by
    `irls_steps` (static) iteratively reweighted least-squares steps from the linear
    solution (module docstring; the squared loss: the linear solution itself, unweighted);
    `throw` as for the estimators.

    **Returns:** a `Solution` with `ts`, `outputs` a `MovingPointOutput` per frame (position in the
    current camera frame, in the units of the camera velocities; NaN during the warm-up,
    before the first window that determines a point in front of the camera), `result`
    (the first failure after the warm-up: a singular window, a refinement that failed (the
    solver's code promoted into `RESULTS`), a point behind the camera (the refined point
    with `refine`), a non-finite measurement), `failed_sample`, and as `diagnostics` a
    `TriangulationDiagnostics`: every window's code and the covariance of its point
    (`covariance`: of the refined point from the reprojection residuals; without
    `refine`, of the linear solution from the linear system's residuals, which are the
    reprojection residuals scaled by each frame's depth; with a robust loss, from those of
    the last reweighted system, the reweighted residuals at its solution: an approximation
    that ignores the weights' own spread, measured to under-predict the spread over noise
    seeds of a Cauchy fit at twice the pixel noise by about a sixth). Causal: the
    estimate at $t$ uses frames up to $t$ only. Works under `jit`, `vmap` and `grad` (with
    `refine`, by the implicit function theorem at each window's minimum; through the
    reweighted steps, by differentiating them).
    """
    y, u = _check_stream(stream)
    if not (isinstance(window, int) and window >= 2):
        raise ValueError(f"`window` must be an int of at least 2; got {window!r}.")
    if order not in (0, 1, 2):
        raise ValueError(f"`order` must be 0, 1 or 2; got {order!r}.")
    if refine and order != 0:
        raise ValueError(
            "`refine=True` minimises the reprojection error of a static point: it needs "
            f"`order=0`; got `order={order!r}`."
        )
    if not (isinstance(max_steps, int) and max_steps >= 1):
        raise ValueError(f"`max_steps` must be a positive int; got {max_steps!r}.")
    if not (isinstance(irls_steps, int) and irls_steps >= 1):
        raise ValueError(f"`irls_steps` must be a positive int; got {irls_steps!r}.")
    loss = as_loss(loss)
    # the linear fit is reweighted only for a robust loss without refinement: with the
    # squared loss it is the unweighted solution, exactly
    reweight = loss.kind != "squared" and not refine
    ts = jnp.asarray(stream.ts)
    n = ts.shape[0]
    seen = jnp.all(jnp.isfinite(y), axis=1)
    if stream.present is not None:
        seen = seen & jnp.asarray(stream.present)
    bad_input = jnp.any(jnp.isinf(y), axis=1) | ~jnp.all(jnp.isfinite(u), axis=1)
    y_clean = jnp.where(seen[:, None], y, 0.0)
    R, c = camera_poses(ts, jnp.where(jnp.isfinite(u), u, 0.0))
    offsets = jnp.arange(-(window - 1), 1)
    n_par = 3 * (order + 1)
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol)

    def fit(k):
        idx = k + offsets
        use = (idx >= 0) & seen[jnp.clip(idx, 0, n - 1)]
        idx = jnp.clip(idx, 0, n - 1)
        R_kj, c_kj = _window_poses(R, c, k, idx)
        tau = ts[idx] - ts[k]
        span = jnp.maximum(jnp.max(jnp.where(use, -tau, 0.0)), jnp.finfo(ts.dtype).tiny)
        powers = jnp.stack([(tau / span) ** i for i in range(order + 1)], axis=1)

        def rows(yj, Rj, cj, pw):
            e = jnp.stack(
                [yj[0] * jnp.eye(3)[2] - jnp.eye(3)[0], yj[1] * jnp.eye(3)[2] - jnp.eye(3)[1]]
            )  # (2, 3)
            a = e @ Rj.T  # the rows acting on P
            return jnp.kron(pw[None, :], a), a @ cj  # (2, n_par), (2,)

        M_all, b_all = jax.vmap(rows)(y_clean[idx], R_kj, c_kj, powers)  # (W, 2, p), (W, 2)
        w0 = use.astype(ts.dtype)

        def is_determined(Gs):
            ev = jnp.linalg.eigvalsh(Gs)
            return ev[0] > rcond * ev[-1]

        def system(w, safe=False):
            """The equations with each frame's pair scaled by `w` (W,), their normal
            matrix scaled to unit diagonal, whether it determines the unknowns, and its
            solution (`safe`: of the identity in its place where it does not, finite in
            value and gradient; the window's code says it failed anyway)."""
            M = (M_all * w[:, None, None]).reshape(-1, n_par)
            b = (b_all * w[:, None]).reshape(-1)
            G = M.T @ M
            d = jnp.sqrt(jnp.maximum(jnp.diag(G), jnp.finfo(ts.dtype).tiny))
            Gs = G / jnp.outer(d, d)
            ok = is_determined(Gs)
            if safe:
                Gs = jnp.where(ok, Gs, jnp.eye(n_par, dtype=Gs.dtype))
            return M, b, ok, jnp.linalg.solve(Gs, (M.T @ b) / d) / d

        if reweight:

            def weights(a_):
                # each frame's predicted depth of the point, z_j = e_3^T R_kj^T (P(tau_j)
                # - c_kj), and its algebraic residual pair over it: the reprojection
                # residual in normalised coordinates (module docstring)
                P_j = powers @ a_.reshape(order + 1, 3)  # (W, 3)
                z = jnp.einsum("ji,ji->j", R_kj[:, :, 2], P_j - c_kj)
                z_abs = jnp.where(use, jnp.abs(z), 0.0)
                z_max = jnp.max(z_abs)
                z_eff = jnp.maximum(z_abs, 1e-9 * jnp.where(z_max > 0.0, z_max, 1.0))
                r = (jnp.einsum("jrp,p->jr", M_all, a_) - b_all) / z_eff[:, None]
                s2 = jnp.where(use, jnp.sum(r * r, axis=1), 0.0)
                s_j = jnp.where(s2 > 0.0, jnp.sqrt(jnp.where(s2 > 0.0, s2, 1.0)), 0.0)
                return w0 * jnp.sqrt(loss.irls_weight(s_j)) / z_eff

            def step(_, carry):
                a_, _w = carry
                w = weights(a_)
                return system(w, safe=True)[3], w

            _, _, determined, a = system(w0, safe=True)
            a, w = jax.lax.fori_loop(0, irls_steps, step, (a, w0))
            M, b, ok, _ = system(w)
            determined = determined & ok
        else:
            M, b, determined, a = system(w0)
        m = a[:3]  # P(0): the point at t_k in frame k
        refined = RESULTS.successful
        count = 2 * jnp.sum(use)
        # the linear solution's covariance (all three unknowns when order > 0: the point's
        # block is the first 3 x 3), from the (last reweighted) system's residuals
        cov_lin, _ = covariance(lambda a_, _: M @ a_ - b, a, None, count)
        cov = cov_lin[:3, :3]
        if refine:
            # from the linear solution where it is a point in front of the camera (else
            # from one on the optical axis: the window's code says it failed anyway)
            start = determined & (m[2] > 0.0) & all_finite(m)
            m0 = jnp.where(start, m, jnp.array([0.0, 0.0, 1.0], m.dtype))
            data = (R_kj, c_kj, y_clean[idx], use)

            def robust(P, d):
                return loss(_reprojection(P, *d))

            sol = optx.least_squares(robust, solver, m0, data, max_steps=max_steps, throw=False)
            m, refined = sol.value, RESULTS.promote(sol.result)
            cov, _ = covariance(robust, m, data, count)
        # the window's baseline: its farthest camera centre from the current one (a
        # comparison: no gradient flows through it)
        wide = jnp.max(jnp.where(use, jnp.linalg.norm(c_kj, axis=1), 0.0)) >= min_baseline
        ok = determined & (refined == RESULTS.successful) & (m[2] > 0.0) & all_finite(m)
        code = RESULTS.where(
            ~determined,
            RESULTS.singular,
            RESULTS.where(
                refined != RESULTS.successful,
                refined,
                RESULTS.where(all_finite(m), RESULTS.behind_camera, RESULTS.nonfinite_output),
            ),
        )
        code = RESULTS.where(ok, RESULTS.successful, code)
        code = RESULTS.where(bad_input[k], RESULTS.nonfinite_measurement, code)
        code = RESULTS.where(~loss.checks(), RESULTS.invalid_settings, code)
        return _output(m), code, cov, wide

    outputs, codes, covs, wide = jax.vmap(fit)(jnp.arange(n))
    # warm-up: until a window first gives a point (enough frames and camera translation
    # to determine it, in front of the camera) the estimate is NaN and that is not a
    # failure; after it, a window that does not (the camera stopped translating) is one,
    # and a non-finite measurement always is
    # (a window wide enough: `min_baseline`)
    started = jnp.cumsum((codes == RESULTS.successful) & wide) > 0
    failed_mask = (codes != RESULTS.successful) & (
        started | (codes == RESULTS.nonfinite_measurement)
    )
    first = jnp.argmax(failed_mask)
    any_failed = jnp.any(failed_mask)
    result = RESULTS.where(
        any_failed, jax.tree_util.tree_map(lambda x: x[first], codes), RESULTS.successful
    )
    failed = jnp.where(any_failed, first, -1)
    outputs = jax.tree_util.tree_map(
        lambda v: jnp.where(started.reshape((-1,) + (1,) * (v.ndim - 1)), v, jnp.nan), outputs
    )
    outputs = raise_or_keep(result, outputs, throw)
    diagnostics = TriangulationDiagnostics(codes=codes, cov=covs)
    return baseline_solution(ts, outputs, result, failed, diagnostics)


def triangulation_residuals(
    position: Float[ArrayLike, "3"], stream: Stream, k: int, window: int
) -> Float[Array, "W 2"]:
    """The reprojection residuals (normalised coordinates, measured minus predicted) of a
    static point at `position` (frame `k`'s coordinates) over the `window` frames up to
    `k`: the loss a static-point triangulation minimises. Differentiable in the position
    and in the stream's measurements."""
    y, u = _check_stream(stream)
    R, c = camera_poses(stream.ts, u)
    idx = jnp.arange(k - window + 1, k + 1)
    R_kj, c_kj = _window_poses(R, c, k, idx)
    use = jnp.ones(idx.shape, bool)
    return _reprojection(jnp.asarray(position), R_kj, c_kj, y[idx], use)


class _InverseDepth(AbstractEKFModel):
    """State $[x_1, x_2, x_3, v_{px}, v_{py}, v_{pz}]$: the observer's own coordinates
    (eq. (3.1)) and the point's velocity (camera basis, a random walk); prediction by a
    fourth-order Runge-Kutta step of eq. (2.11) under the held camera velocity; measurement
    $y = [x_1, x_2]$."""

    q_velocity: Array
    r_norm: Array

    def transition(self, x, u, dt):
        def f(z):
            return jnp.concatenate([perspective_dynamics(z[:3], u, z[3:]), jnp.zeros(3, z.dtype)])

        k1 = f(x)
        k2 = f(x + 0.5 * dt * k1)
        k3 = f(x + 0.5 * dt * k2)
        k4 = f(x + dt * k3)
        return x + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)

    def process_noise(self, x, u, dt):
        q = jnp.concatenate([jnp.zeros(3, x.dtype), jnp.full(3, self.q_velocity)])
        return jnp.diag(q * dt)

    def measure(self, x, u):
        return x[:2]

    def measurement_noise(self, x, u):
        return self.r_norm**2 * jnp.eye(2, dtype=x.dtype)

    def valid(self, x, u):
        return x[2] > 0.0


def moving_point_ekf(
    stream: Stream,
    *,
    r_norm: Float[ArrayLike, ""],
    depth0: Float[ArrayLike, ""],
    sigma_depth0: Float[ArrayLike, ""],
    q_velocity: float | ArrayLike,
    sigma_velocity0: float | ArrayLike = 0.0,
    substeps: int = 1,
    gate: float | ArrayLike | None = None,
    throw: bool = True,
) -> Solution:
    """An extended Kalman filter of the point's inverse-depth coordinates and velocity (the
    filter one would otherwise write for the problem of Jang's thesis; not in the thesis).

    State: $x = [X/Z, Y/Z, 1/Z]$ (the UIO's coordinates, eq. (3.1)) and the point's own
    velocity $v_p$ (camera basis; the thesis' unknown input, here a random walk of
    intensity `q_velocity`, units^2/s^3); prediction: eq. (2.11) integrated by RK4 in
    `substeps` steps per sample interval under the held camera velocity; update: the
    measured $y$ (a NaN frame skipped). Noise settings (the documented rule): `r_norm` the
    pixel noise divided by the focal length; the prior from the first measurement and the
    same depth guess as the observer (`depth0`, with `sigma_depth0`), $v_p = 0$ with
    `sigma_velocity0` (0: a static point expected); `q_velocity` from the expected change of
    the point's velocity (its largest acceleration squared times the sample interval).
    `gate`: the probability of the outlier gate on each frame's measured $y$
    (`ExtendedKalmanFilter`; `None`, the default: no gate).

    **Returns:** a `Solution` with `outputs` a `MovingPointOutput` per frame (after its update),
    `result` (`diverged`: the inverse depth not positive; `nonfinite_measurement`;
    `nonfinite_state`), `failed_sample`, the covariances as `diagnostics`.
    """
    y, u = _check_stream(stream)
    ts = jnp.asarray(stream.ts)
    dtype = ts.dtype
    y0 = jnp.where(jnp.isfinite(y[0]), y[0], 0.0)
    x0 = jnp.concatenate([y0, jnp.array([1.0 / depth0], dtype), jnp.zeros(3, dtype)])
    sd = jnp.array([r_norm, r_norm, sigma_depth0 / depth0**2] + [sigma_velocity0] * 3, dtype)
    model = _InverseDepth(
        q_velocity=jnp.asarray(q_velocity, dtype), r_norm=jnp.asarray(r_norm, dtype)
    )
    sol = extended_kalman_filter(
        model,
        ts,
        y,
        u,
        x0,
        jnp.diag(sd**2) + 1e-18 * jnp.eye(6, dtype=dtype),
        present=stream.present,
        substeps=substeps,
        gate=gate,
        gate_size=2,
        throw=False,
    )
    # a non-finite camera velocity is an input of the filter's samples: the runner stops
    # there with `nonfinite_measurement`
    result, failed = sol.result, sol.failed_sample
    outputs = jax.vmap(lambda x: _output(jnp.stack([x[0], x[1], 1.0]) / x[2]))(sol.outputs.x)
    outputs = raise_or_keep(result, outputs, throw)
    return baseline_solution(ts, outputs, result, failed, sol.outputs.P)
