"""Bundle adjustment with known platform poses: the batch baseline of the uncalibrated
structure problem of Nath, Dawson and Tatlicioglu, *Euclidean position estimation of static
features using a moving uncalibrated camera*.

The paper's adaptive laws (eqs. (37)-(45)) update the camera and structure parameters
online, one sample at a time. The batch answer to the same problem fits everything at once:
the intrinsics $A$ of eq. (4) (five entries: focal terms, skew term, principal point), the
mounting $R_c$ (a rotation vector) and $x_c$, and every unknown feature's world position
$\\omega_{si}$, to the pixels of all frames (or of a sliding window of past frames), by
Levenberg-Marquardt (`optimistix.least_squares`). The model is the paper's eqs. (2)-(5): a
world point $\\omega$ is at $\\bar m = R_c^T(R_b^T(\\omega - x_b) - x_c)$ in the camera frame
and at the pixel $p = A\\bar m / \\bar m_z$; the residuals are pixels, measured minus
predicted, of the known features (`omega_c` given) and of the unknown ones, zero where a
feature was not seen. Not in the paper: a baseline to compare its estimator against.
With a calibrated camera (`intrinsics="known"`) $A$ is held and only the mounting and the
features are fitted. `tests/baselines/test_vs_gtsam.py` checks both against GTSAM's
Levenberg-Marquardt on the same factor graph.
"""

from typing import final

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jax.flatten_util import ravel_pytree
from jaxtyping import Array, ArrayLike, Float, Int

from .._results import RESULTS, all_finite, first_failure, raise_or_keep
from .._util import as_float, check_shape
from ..estimators import Solution, StaticPointsEstimator, StaticPointsOutput, Stream
from ..geometry import so3_exp, so3_log
from ._ekf import AbstractEKFModel, baseline_solution, extended_kalman_filter
from ._losses import as_loss, covariance


@final
class BundleDiagnostics(eqx.Module):
    """Per fit (one for all frames, one per fit time for a sliding window): `rms_px` the
    RMS pixel residual over the seen features at the solution, `steps` the
    Levenberg-Marquardt steps taken, `fit_ts` the time of the last frame in the fit;
    `omega_s_std` (F, n, 3) the standard deviation of each unknown feature's coordinates
    and `cov` (F, p, p) the covariance of all the unknowns (`covariance`: in the order
    intrinsics relative to $A_{11}$ (when fitted), features, mounting rotation vector,
    mounting offset), from the fit's residuals (rescaled by the loss); `rejected` the
    observations left out by `reject_px`."""

    rms_px: Float[Array, " F"]
    steps: Int[Array, " F"]
    fit_ts: Float[Array, " F"]
    omega_s_std: Float[Array, "F n 3"]
    cov: Float[Array, "F p p"]
    rejected: Int[Array, " F"]


def _A_from(a):
    """$A$ of eq. (4) from its five free entries $[A_{11}, A_{12}, A_{13}, A_{22}, A_{23}]$."""
    z, o = jnp.zeros_like(a[0]), jnp.ones_like(a[0])
    return jnp.stack(
        [jnp.stack([a[0], a[1], a[2]]), jnp.stack([z, a[3], a[4]]), jnp.stack([z, z, o])]
    )


def _camera_point(R_b, x_b, R_c, x_c, w):
    """Eq. (5): the world point `w` in the camera frame, $R_c^T(R_b^T(w - x_b) - x_c)$."""
    return R_c.T @ (R_b.T @ (w - x_b) - x_c)


def _unpack(y, scale, a_known):
    """The camera and features of the unknowns `y`; the intrinsics are `a_known` (relative
    to `scale`, like `y["a"]`) where they are not among the unknowns (`intrinsics="known"`)."""
    a = (y["a"] if "a" in y else a_known) * scale
    return _A_from(a), so3_exp(y["r_c"]), y["x_c"], y["omega_s"]


def _residuals(y, args):
    """Pixel residuals (measured - predicted) of every frame and feature, masked."""
    R_b, x_b, p_s, p_c, vis_s, vis_c, omega_c, frame_mask, scale, a_known = args
    A, R_c, x_c, omega_s = _unpack(y, scale, a_known)

    def frame(R, x, ps, pc, vs, vc, keep):
        def pixel(w, p, seen):
            m = _camera_point(R, x, R_c, x_c, w)
            q = A @ m
            r = p[:2] - q[:2] / q[2]
            return jnp.where(seen & keep, r, 0.0)

        rs = jax.vmap(pixel)(omega_s, ps, vs)
        rc = jax.vmap(pixel)(omega_c, pc, vc)
        return jnp.concatenate([rs, rc])

    return jax.vmap(frame)(R_b, x_b, p_s, p_c, vis_s, vis_c, frame_mask)


def _depths(y, args):
    R_b, x_b, _, _, vis_s, vis_c, omega_c, frame_mask, scale, a_known = args
    _, R_c, x_c, omega_s = _unpack(y, scale, a_known)
    ws = jnp.concatenate([omega_s, omega_c])
    seen = jnp.concatenate([vis_s, vis_c], axis=1) & frame_mask[:, None]
    z = jax.vmap(lambda R, x: jax.vmap(lambda w: _camera_point(R, x, R_c, x_c, w)[2])(ws))(R_b, x_b)
    return jnp.where(seen, z, jnp.inf)


def _initial(estimator, y0):
    """The estimator's own initial estimate (its output at the first sample)."""
    state = estimator.init(y0)
    out = estimator.output(jnp.zeros(()), state, y0)
    return out


def _check(estimator, stream, omega_c):
    """The arguments shared by the baselines, checked before tracing."""
    if not isinstance(estimator, StaticPointsEstimator):
        raise ValueError(
            f"`estimator` must be an StaticPointsEstimator; got {type(estimator).__name__}."
        )
    if not isinstance(stream, Stream):
        raise ValueError(f"`stream` must be a visjax Stream; got {type(stream).__name__}.")
    omega_c = as_float(omega_c)
    check_shape(omega_c, (jnp.shape(stream.ys.p_c)[1], 3), "omega_c")
    return omega_c


def _fit(y_init, args, solver, max_steps, loss):
    def robust(y, a):
        return loss(_residuals(y, a))  # each feature's pixel pair a block

    sol = optx.least_squares(robust, solver, y_init, args, max_steps=max_steps, throw=False)
    r = _residuals(sol.value, args)
    R_b, x_b, _, _, vis_s, vis_c, _, frame_mask, _, _ = args
    seen = jnp.concatenate([vis_s, vis_c], axis=1) & frame_mask[:, None]
    count = jnp.maximum(jnp.sum(seen), 1).astype(r.dtype)
    rms = jnp.sqrt(jnp.sum(r**2) / (2.0 * count))
    cov, _ = covariance(robust, sol.value, args, 2 * jnp.sum(seen))
    _, unravel = ravel_pytree(sol.value)
    std = unravel(jnp.sqrt(jnp.maximum(jnp.diag(cov), 0.0)))["omega_s"]
    in_front = jnp.all(_depths(sol.value, args) > 0.0)
    result = RESULTS.promote(sol.result)
    result = RESULTS.where(
        result != RESULTS.successful,
        result,
        RESULTS.where(
            ~all_finite(sol.value),
            RESULTS.nonfinite_state,
            RESULTS.where(in_front, RESULTS.successful, RESULTS.behind_camera),
        ),
    )
    result = RESULTS.where(
        (result == RESULTS.successful) & ~loss.checks(), RESULTS.invalid_settings, result
    )
    return sol.value, result, rms, sol.stats["num_steps"], std, cov


def bundle_adjustment(
    estimator: StaticPointsEstimator,
    stream: Stream,
    omega_c: Float[ArrayLike, "m 3"],
    *,
    window: int | None = None,
    every: int = 1,
    intrinsics: str = "fit",
    loss=None,
    reject_px: float | None = None,
    max_steps: int = 256,
    rtol: float = 1e-9,
    atol: float = 1e-9,
    throw: bool = True,
) -> Solution:
    """Bundle adjustment of the camera and the unknown features, from the same stream and
    the same initial guesses as `StaticPointsEstimator` (module docstring).

    **Arguments:**

    - `estimator`: the adaptive estimator whose initial estimate starts the fit (its
        output at the first sample: intrinsics, mounting and features, e.g. from
        `StaticPointsEstimator.from_nominal`). Its gains are not used.
    - `stream`: the estimator's stream (`static_points_stream`): platform poses, pixels of the
        unknown and known features, visibility.
    - `omega_c` (m, 3): the known features' world positions (as given to
        `static_points_stream`).
    - `window`: `None` (default): one fit over all frames; the estimate is the same at
        every sample time (it uses the future: an offline answer). An int `W`: the online
        variant, a fit at every `every`-th sample over the last `W` frames up to it
        (fewer at the start), warm-started from the previous fit; the estimate at time
        $t$ uses only frames up to $t$ and is held between fits.
    - `intrinsics`: `"fit"` (default): the five intrinsics of eq. (4) are unknowns (the
        uncalibrated camera of the paper). `"known"`: a calibrated camera; the intrinsics
        are held at the estimator's initial ones (its output's `A` at the first sample)
        and only the mounting and the unknown features are fitted; every output's `A` is
        that matrix.
    - `loss`: `None` (least squares) or a robust `Loss` on each observation's pixel pair
        (`huber(k)`, `cauchy(k)`, `k` in pixels): the fit is then the M-estimate, and an
        outlier observation (a false match, a feature sliding along an edge) weighs in
        less than quadratically.
    - `reject_px` (one fit over all frames only): after the fit, the observations whose
        pixel residual exceeds it are left out and the fit is repeated by least squares
        from that solution (with a robust `loss` first: a robust fit, then the efficient
        least-squares fit of the observations it accepts).
    - `max_steps`, `rtol`, `atol`: of the Levenberg-Marquardt solver (its cost is
        $\\frac12\\sum r^2$ over the pixel residuals $r$).
    - `throw`: raise on failure (default), else report it in `Solution.result`.

    **Returns:** a `Solution` with `ts = stream.ts`, `outputs` an `StaticPointsOutput` per
    sample, `diagnostics` a `BundleDiagnostics` per fit, `result` (the solver's code
    promoted into `RESULTS`, `nonfinite_state` for a non-finite solution, `behind_camera`
    for a solution that puts a seen feature behind a camera) and `failed_sample` (the last
    sample of the first failed fit, -1 if none; after it the estimate is frozen at the last
    good fit). Works under `jit`, `vmap` (per-problem result codes with `throw=False`)
    and `grad` (the implicit function theorem at the solution).
    """
    omega_c = _check(estimator, stream, omega_c)
    ys = stream.ys
    n_frames = jnp.shape(stream.ts)[0]
    if window is not None and not (isinstance(window, int) and window >= 1):
        raise ValueError(f"`window` must be None or a positive int; got {window!r}.")
    if not (isinstance(every, int) and every >= 1):
        raise ValueError(f"`every` must be a positive int; got {every!r}.")
    if intrinsics not in ("fit", "known"):
        raise ValueError(f'`intrinsics` must be "fit" or "known"; got {intrinsics!r}.')
    loss = as_loss(loss)
    if reject_px is not None:
        if window is not None:
            raise ValueError("`reject_px` applies to the one fit over all frames (`window=None`).")
        if not (isinstance(reject_px, (int, float)) and reject_px > 0):
            raise ValueError(f"`reject_px` must be a positive number of pixels; got {reject_px!r}.")

    y0 = jax.tree_util.tree_map(lambda x: x[0], ys)
    init = _initial(estimator, y0)
    a0 = jnp.stack([init.A[0, 0], init.A[0, 1], init.A[0, 2], init.A[1, 1], init.A[1, 2]])
    # unknowns of order one: the intrinsics relative to the nominal focal length
    scale = jnp.abs(init.A[0, 0])
    y_init = {"r_c": so3_log(init.R_c).omega, "x_c": init.x_c, "omega_s": init.omega_s}
    if intrinsics == "fit":
        y_init["a"] = a0 / scale
    a_known = a0 / scale  # the intrinsics where they are not fitted
    present = jnp.ones(n_frames, bool) if stream.present is None else jnp.asarray(stream.present)
    # seen: the stream's flags (NaN pixels are already unseen); an infinite pixel that is
    # marked seen is a bad measurement
    vis_s, vis_c = ys.visible_s > 0, ys.visible_c > 0
    data = (ys.R_b, ys.x_b, ys.p_s, ys.p_c, vis_s, vis_c, present)
    # a non-finite pose or pixel that is marked seen is a bad measurement, not a miss
    bad = ~(
        all_finite((ys.R_b, ys.x_b))
        & jnp.all(jnp.where(vis_s[..., None], jnp.isfinite(ys.p_s), True))
        & jnp.all(jnp.where(vis_c[..., None], jnp.isfinite(ys.p_c), True))
    )
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol)

    def to_output(y):
        A, R_c, x_c, omega_s = _unpack(y, scale, a_known)
        return StaticPointsOutput(omega_s=omega_s, A=A, R_c=R_c, x_c=x_c)

    def clean(x):
        if not jnp.issubdtype(x.dtype, jnp.floating):
            return x
        return jnp.where(jnp.isfinite(x), x, jnp.zeros((), x.dtype))

    if window is None:
        R_b, x_b, p_s, p_c, vs, vc, keep = data
        clean_data = (clean(R_b), clean(x_b), clean(p_s), clean(p_c), vs, vc)
        args = (*clean_data, omega_c, keep, scale, a_known)
        y, result, rms, steps, std, cov = _fit(y_init, args, solver, max_steps, loss)
        rejected = jnp.zeros((), int)
        if reject_px is not None:
            # leave out the observations the robust fit puts further than `reject_px`,
            # then least squares on the rest from the robust solution
            far = jnp.linalg.norm(_residuals(y, args), axis=-1) > reject_px
            n_s = vs.shape[1]
            args = (*clean_data[:4], vs & ~far[:, :n_s], vc & ~far[:, n_s:], *args[6:])
            y2, result2, rms, steps2, std, cov = _fit(y, args, solver, max_steps, as_loss(None))
            result = RESULTS.where(result == RESULTS.successful, result2, result)
            y, steps = y2, steps + steps2
            rejected = jnp.sum(far & jnp.concatenate([vs, vc], axis=1))
        result = RESULTS.where(bad, RESULTS.nonfinite_measurement, result)
        out = to_output(y)
        outputs = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (n_frames,) + x.shape), out)
        failed = jnp.where(result == RESULTS.successful, -1, n_frames - 1)
        diagnostics = BundleDiagnostics(
            rms_px=rms[None], steps=steps[None], fit_ts=stream.ts[-1:], omega_s_std=std[None],
            cov=cov[None], rejected=rejected[None],
        )  # fmt: skip
    else:
        W = min(window, n_frames)

        def pad(x):  # W - 1 empty frames before the first: every window has W frames
            return jnp.concatenate([jnp.zeros((W - 1,) + x.shape[1:], x.dtype), x])

        R_b, x_b, p_s, p_c, vs, vc, keep = (pad(clean(x)) for x in data)
        R_b = R_b.at[: W - 1].set(jnp.eye(3, dtype=R_b.dtype))
        ends = jnp.arange(0, n_frames, every)
        frame_ok = jax.vmap(
            lambda k: (
                all_finite((ys.R_b[k], ys.x_b[k]))
                & jnp.all(jnp.where(vis_s[k][:, None], jnp.isfinite(ys.p_s[k]), True))
                & jnp.all(jnp.where(vis_c[k][:, None], jnp.isfinite(ys.p_c[k]), True))
            )
        )(jnp.arange(n_frames))
        seen_bad = jnp.cumsum(~frame_ok) > 0  # a bad frame at or before k

        def body(carry, k):
            y_prev, result, failed = carry
            sl = lambda x: jax.lax.dynamic_slice_in_dim(x, k, W)  # noqa: E731
            window_data = (sl(R_b), sl(x_b), sl(p_s), sl(p_c), sl(vs), sl(vc))
            args = (*window_data, omega_c, sl(keep), scale, a_known)
            y, code, rms, steps, std, cov = _fit(y_prev, args, solver, max_steps, loss)
            code = RESULTS.where(seen_bad[k], RESULTS.nonfinite_measurement, code)
            result, failed = first_failure(result, failed, code, k)
            keep_y = failed < 0
            y_next = jax.tree_util.tree_map(lambda a, b: jnp.where(keep_y, a, b), y, y_prev)
            return (y_next, result, failed), (y_next, rms, steps, std, cov)

        init_carry = (y_init, RESULTS.successful, jnp.array(-1))
        (_, result, failed), (y_fits, rms, steps, std, cov) = jax.lax.scan(body, init_carry, ends)
        # the estimate at sample j: the last fit at or before j
        which = jnp.arange(n_frames) // every
        outputs = jax.vmap(to_output)(jax.tree_util.tree_map(lambda x: x[which], y_fits))
        diagnostics = BundleDiagnostics(
            rms_px=rms, steps=steps, fit_ts=stream.ts[ends], omega_s_std=std, cov=cov,
            rejected=jnp.zeros(ends.shape, int),
        )  # fmt: skip
    outputs = raise_or_keep(result, outputs, throw)
    return baseline_solution(stream.ts, outputs, result, failed, diagnostics)


def bundle_adjustment_residuals(
    A: Float[ArrayLike, "3 3"],
    R_c: Float[ArrayLike, "3 3"],
    x_c: Float[ArrayLike, "3"],
    omega_s: Float[ArrayLike, "n 3"],
    stream: Stream,
    omega_c: Float[ArrayLike, "m 3"],
) -> Float[Array, "N n+m 2"]:
    """The pixel residuals that `bundle_adjustment` minimises, at a given camera and
    features (measured minus predicted, eqs. (2)-(5) of Nath et al.; zero for a feature not
    seen). Differentiable in every argument, the pixels of the stream included."""
    A, R_c, x_c, omega_s, omega_c = (as_float(x) for x in (A, R_c, x_c, omega_s, omega_c))
    ys = stream.ys
    vis_s = (ys.visible_s > 0) & jnp.all(jnp.isfinite(ys.p_s), axis=-1)
    vis_c = (ys.visible_c > 0) & jnp.all(jnp.isfinite(ys.p_c), axis=-1)
    n_frames = jnp.shape(stream.ts)[0]
    scale = jnp.ones((), A.dtype)
    a = jnp.stack([A[0, 0], A[0, 1], A[0, 2], A[1, 1], A[1, 2]])
    y = {"a": a, "r_c": so3_log(R_c).omega, "x_c": x_c, "omega_s": omega_s}
    keep = jnp.ones(n_frames, bool)
    args = (ys.R_b, ys.x_b, ys.p_s, ys.p_c, vis_s, vis_c, omega_c, keep, scale, a)
    return _residuals(y, args)


class _CameraFeaturesModel(AbstractEKFModel):
    """State: the five intrinsics (relative to `scale`), $R_c$ as a rotation vector, $x_c$,
    the unknown features (n, 3), all constant (random walk of small variance); input:
    the platform pose $(R_b, x_b)$; measurement: the pixels of the unknown and the known
    features (eqs. (2)-(5))."""

    omega_c: Array
    scale: Array
    q: Array  # (dim,) process noise variance per second of each state entry
    r_px: Array
    n: int = eqx.field(static=True)

    def transition(self, x, u, dt):
        return x

    def process_noise(self, x, u, dt):
        return jnp.diag(self.q * dt)

    def measure(self, x, u):
        R_b, x_b = u
        A = _A_from(x[:5] * self.scale)
        R_c, x_c = so3_exp(x[5:8]), x[8:11]
        ws = jnp.concatenate([x[11:].reshape(self.n, 3), self.omega_c])

        def pixel(w):
            q = A @ _camera_point(R_b, x_b, R_c, x_c, w)
            return q[:2] / q[2]

        return jax.vmap(pixel)(ws).reshape(-1)

    def measurement_noise(self, x, u):
        m = 2 * (self.n + self.omega_c.shape[0])
        return self.r_px**2 * jnp.eye(m, dtype=x.dtype)

    def valid(self, x, u):
        R_b, x_b = u
        R_c, x_c = so3_exp(x[5:8]), x[8:11]
        ws = x[11:].reshape(self.n, 3)
        z = jax.vmap(lambda w: _camera_point(R_b, x_b, R_c, x_c, w)[2])(ws)
        return jnp.all(z > 0.0)


def static_points_ekf(
    estimator: StaticPointsEstimator,
    stream: Stream,
    omega_c: Float[ArrayLike, "m 3"],
    *,
    r_px: float | ArrayLike = 0.5,
    sigma_focal: float | ArrayLike = 0.1,
    sigma_principal_px: float | ArrayLike = 30.0,
    sigma_rotation: float | ArrayLike = 0.1,
    sigma_offset: float | ArrayLike = 0.05,
    sigma_feature: float | ArrayLike = 0.1,
    q_rate: float | ArrayLike = 1e-12,
    gate: float | ArrayLike | None = None,
    throw: bool = True,
) -> Solution:
    """An extended Kalman filter over the camera parameters and the unknown features, the
    filter one would otherwise write for the problem of Nath et al. (not in the paper).

    State: the intrinsics of eq. (4) ($A_{11}, A_{12}, A_{13}, A_{22}, A_{23}$, divided
    by the initial $A_{11}$), $R_c$ as a rotation vector, $x_c$, and every unknown
    feature's world position; all constant, so the prediction is the identity plus a tiny
    process noise `q_rate` x dt on every entry (numerical: it keeps the covariance from
    collapsing). Measurement: the pixels of all features at each sample (eqs. (2)-(5)),
    a missing feature (NaN) skipped; the platform pose $(R_b, x_b)$ is the known input.

    Noise settings (the documented rule): `r_px` = the pixel noise level (the measurement
    noise the user expects; default 0.5 px); the prior is the estimator's initial estimate
    (`estimator.init`: the same guesses as the adaptive laws) with standard deviations
    stated as the uncertainty of a nominal camera: `sigma_focal` relative on the focal
    and skew terms (10%), `sigma_principal_px` on the principal point (30 px),
    `sigma_rotation` on the mounting rotation (0.1 rad), `sigma_offset` on the mounting
    offset (5 cm), `sigma_feature` on each feature coordinate (10 cm). `gate`: the
    probability of the outlier gate on each feature's pixel pair (`ExtendedKalmanFilter`;
    `None`, the default: no gate).

    **Returns:** a `Solution` like `bundle_adjustment`'s: `outputs` an `StaticPointsOutput`
    per sample (the filtered estimate after that sample), `result` (`diverged`: a feature
    estimated behind the camera; `nonfinite_state`; `nonfinite_measurement`),
    `failed_sample`, `diagnostics` the filter's covariances (N, d, d).
    """
    omega_c = _check(estimator, stream, omega_c)
    ys = stream.ys
    n = jnp.shape(ys.p_s)[1]
    y0 = jax.tree_util.tree_map(lambda x: x[0], ys)
    init = _initial(estimator, y0)
    scale = jnp.abs(init.A[0, 0])
    a0 = jnp.stack([init.A[0, 0], init.A[0, 1], init.A[0, 2], init.A[1, 1], init.A[1, 2]])
    x0 = jnp.concatenate([a0 / scale, so3_log(init.R_c).omega, init.x_c, init.omega_s.reshape(-1)])
    dtype = x0.dtype
    sf, sp = jnp.asarray(sigma_focal, dtype), jnp.asarray(sigma_principal_px, dtype) / scale
    sr, so, sw = (jnp.asarray(s, dtype) for s in (sigma_rotation, sigma_offset, sigma_feature))
    sd = jnp.concatenate(
        [
            jnp.stack([sf, sf, sp, sf, sp]),
            jnp.full(3, sr),
            jnp.full(3, so),
            jnp.full(3 * n, sw),
        ]
    )
    model = _CameraFeaturesModel(
        omega_c=omega_c,
        scale=scale,
        q=jnp.full(x0.shape, jnp.asarray(q_rate, dtype)),
        r_px=jnp.asarray(r_px, dtype),
        n=n,
    )
    # measured pixels: NaN where not seen (the filter skips them)
    seen_s = ys.visible_s > 0
    seen_c = ys.visible_c > 0
    p_s = jnp.where(seen_s[..., None], ys.p_s[..., :2], jnp.nan)
    p_c = jnp.where(seen_c[..., None], ys.p_c[..., :2], jnp.nan)
    zs = jnp.concatenate([p_s, p_c], axis=1).reshape(p_s.shape[0], -1)
    sol = extended_kalman_filter(
        model,
        stream.ts,
        zs,
        (ys.R_b, ys.x_b),
        x0,
        jnp.diag(sd**2),
        present=stream.present,
        gate=gate,
        gate_size=2,
        throw=False,
    )
    # a non-finite pose is an input of the filter's samples: the runner stops there with
    # `nonfinite_measurement`
    result, failed = sol.result, sol.failed_sample

    def to_output(x):
        A = _A_from(x[:5] * scale)
        return StaticPointsOutput(
            omega_s=x[11:].reshape(n, 3), A=A, R_c=so3_exp(x[5:8]), x_c=x[8:11]
        )

    outputs = raise_or_keep(result, jax.vmap(to_output)(sol.outputs.x), throw)
    return baseline_solution(stream.ts, outputs, result, failed, sol.outputs.P)
