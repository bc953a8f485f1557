"""The `velocity` problem: the velocity of a moving planar object seen by a fixed camera
(Chitrakaran, Dawson, Dixon, Chen, *Identification of a moving object's velocity with a
fixed camera*), with the paper's estimator and its baselines."""

from typing import final

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float

from ..._results import RESULTS, first_failure
from ..._util import Frozen, Note, number_text
from ...baselines import (
    SmootherDiagnostics,
    cauchy,
    frame_poses,
    half_width_for_bandwidth,
    velocity_covariance,
    velocity_ekf,
    velocity_smoother,
)
from ...estimators import (
    AbstractAdjoint,
    DirectAdjoint,
    FixedCamera,
    SaveAt,
    VelocityEstimator,
    WindowRMS,
    fixed_camera,
    integration_step,
    lowpass,
    lowpass_delay,
    run,
    velocity_innovation,
    velocity_stream,
)
from ...io import VelocityData
from ...plots import plot_velocity
from ...sim import add_pixel_noise
from ...studies import (
    AbstractProblem,
    Parameter,
    as_default,
    held,
    noise_parameter,
    robust_parameters,
)
from ._scene import K_EQ63, RHO_EQ63, section6_scenario, window

# the robust settings (a stated choice, not tuned to any result; those of the static-points
# problem): the Cauchy loss, whose influence vanishes for large residuals, at 1 px
ROBUST_SCALE_PX = 1.0  # the Cauchy loss' scale of the fits' per-frame poses, px
ROBUST_GATE = 0.9999  # the robust EKF's gate on each feature's pixel pair


def velocity_observer_bandwidth_hz(K) -> list[float]:
    """The -3 dB bandwidth per degree of freedom of the linear part of the velocity
    estimator of Chitrakaran et al. (eqs. (39)-(40) without the sign term): from $e$ to
    $\\hat\\kappa$ per axis, $\\hat\\kappa = s\\,T(s)\\,e$ with
    $T(s) = (k+1)(s+1)/(s^2 + (k+1)s + (k+1))$; the frequency where $|T| = 1/\\sqrt2$.
    (The sign term $\\rho\\,\\mathrm{sgn}(\\tilde e)$ adds gain at small errors, so this is
    the bandwidth for errors large against $\\rho/(k+1)$.)"""
    out = []
    w = np.geomspace(1e-4, 1e6, 400_001)
    for k in np.asarray(K, float):
        s = 1j * w
        T = (k + 1) * (s + 1) / (s**2 + (k + 1) * s + (k + 1))
        out.append(float(w[np.nonzero(np.abs(T) < 1 / np.sqrt(2))[0][0]] / (2 * np.pi)))
    return out


AXES = ("v_x", "v_y", "v_z", "omega_x", "omega_y", "omega_z")
"""The six degrees of freedom of $v = [v_e^T, \\omega_e^T]^T$ (section 5.1), as the
tables name them."""
_UNITS6 = ("m/s",) * 3 + ("rad/s",) * 3


@final
class VelocityProblem(AbstractProblem):
    """The velocity of a moving planar object from a fixed camera's pixels (Chitrakaran et
    al.). Build it with `velocity_problem`.

    Methods: `estimator`, the sign-based estimator (eqs. (39)-(40)); `batch` and
    `batch_window`, the local least-squares fit of the pose trajectory (centred, all frames
    around $t$; causal) at the estimator's own bandwidth per degree of freedom
    (`velocity_observer_bandwidth_hz`); `ekf`, the constant-acceleration EKF
    (`baselines.velocity_ekf`). Each seed adds `noise_px` of Gaussian noise to the
    pixels; the homography, its decomposition and $J$ of every frame are recomputed from
    the noisy pixels, with $n^*$ and $z_1^*$ measured once from the noise-free pixels (the
    calibration before the run) and shared by every method.

    Parameters: `K` and `rho` (the gains of eq. (40), diagonal, 6 each; default eq. (63)
    or the data file's), and `K_scale`, `rho_scale`, multipliers of them (default 1); the
    baselines': `bandwidth_scale` (a multiplier of the fits' bandwidths, default 1: the
    estimator's own; a structural parameter), `ekf_jerk` (the EKF's largest expected jerk,
    its process noise) and, when `robust`, `robust_scale_px` and `ekf_gate_tail`
    (`studies.robust_parameters`).
    Metrics: `rms` (6,), the RMS error per degree of freedom over the paper's window (5-10
    s; the second half of a shorter run, and of a data file), and `rms_worst`, its largest
    component (m/s and rad/s mixed, as in the paper's Table I). Uncertainty
    (`uncertainty`): `rms_std` (6,), the RMS over the same window of the fits' predicted
    standard deviation of the velocity (`baselines.SmootherDiagnostics.cov`: the pixel
    noise's share of `rms`, not the fit's lag); NaN for the estimator and the EKF.

    `robust` (the command line's `--robust`): the baselines' robust settings for pixel
    tracks with outliers: the fits' per-frame poses minimise the Cauchy loss of each
    feature's pixel residual with the scale `ROBUST_SCALE_PX` (`frame_poses`), and the
    EKF gates each feature's pixel pair at the `ROBUST_GATE` quantile
    (`ExtendedKalmanFilter`). The estimator has no robust setting: it takes every sample
    it is given.
    """

    methods = ("estimator", "batch", "batch_window", "ekf")
    metric = "rms_worst"
    label = "worst-axis RMS over the window (m/s, rad/s)"
    trivial_label = "zero velocity"
    data_parameters = ("noise_px",)
    grid = "K_scale=1e-3:1e1:9,rho_scale=1e-3:1e1:9"
    columns = {
        "rms": tuple(f"rms_{a}" for a in AXES), "rms_std": tuple(f"rms_std_{a}" for a in AXES),
        "v_hat": AXES, "v_object": tuple(f"{a}_object" for a in AXES),
        "K": tuple(f"K_{a}" for a in AXES), "rho": tuple(f"rho_{a}" for a in AXES),
    }  # fmt: skip
    units = {
        "rms_worst": "m/s or rad/s (the worst axis)", "K": "1/s", "rho": "-",
        **{f"{p}{a}": u for a, u in zip(AXES, _UNITS6) for p in ("rms_", "rms_std_", "")},
        **{f"{a}_object": u for a, u in zip(AXES, _UNITS6)},
    }  # fmt: skip
    structural_parameters = ("bandwidth_scale",)
    own_parameters = {
        "estimator": ("K", "rho", "K_scale", "rho_scale"),
        "batch": ("bandwidth_scale", "robust_scale_px"),
        "batch_window": ("bandwidth_scale", "robust_scale_px"),
        "ekf": ("ekf_jerk", "ekf_gate_tail"),
    }

    ts: Float[ArrayLike, " n"]  # the sample times, s
    clean: Float[ArrayLike, "n m 2"]  # the noise-free pixels of the m features
    A: Float[ArrayLike, "3 3"]
    R_star: Float[ArrayLike, "3 3"]
    s1: Float[ArrayLike, " 3"]
    truth: Float[ArrayLike, "n 6"] | None  # the object's velocity; None for a file without it
    K: Float[ArrayLike, " 6"]
    rho: Float[ArrayLike, " 6"]
    n_star: Float[ArrayLike, " 3"]
    z1_star: Float[ArrayLike, ""]
    reference_pixels: Float[ArrayLike, "m 2"] | None
    noise_px: Float[ArrayLike, ""]  # a data parameter (`at`): a noise sweep is one `vmap`
    window: tuple = eqx.field(static=True)
    bandwidths: tuple = eqx.field(static=True)
    max_jerk: float = eqx.field(static=True)
    dropouts: bool = eqx.field(static=True)
    chunk: int = eqx.field(static=True)
    source: str = eqx.field(static=True)  # a `Note`: it does not key compilation
    interval: float = eqx.field(static=True, default=1e-3)  # the median sample interval, s
    dt: float | None = eqx.field(static=True, default=None)  # the estimator's step
    times: Frozen | None = eqx.field(static=True, default=None)  # `ts`, with a held step
    known_length: tuple | None = None  # (i, j) Python ints, the length an array (traced)
    constants: str = eqx.field(static=True, default="calibration")
    adjoint: AbstractAdjoint = DirectAdjoint()
    robust: bool = eqx.field(default=False, static=True)
    filter_hz: float | None = eqx.field(static=True, default=None)  # the estimate's low-pass
    bandwidth_scale: float = eqx.field(static=True, default=1.0)  # of the fits' bandwidths

    @property
    def title(self) -> str:
        noise = number_text(self.noise_px)
        robust = ", robust baselines" if self.robust else ""
        low = "" if self.filter_hz is None else f", low-passed at {self.filter_hz:g} Hz"
        return f"velocity (Chitrakaran et al.), {self.source}, {noise} px noise{robust}{low}"

    @property
    def scored(self) -> bool:
        return self.truth is not None

    def parameters(self) -> dict[str, Parameter]:
        return {
            "K": Parameter(as_default(self.K), "1/s", True, "gain K of eq. (40), diagonal"),
            "rho": Parameter(as_default(self.rho), "", True, "gain rho of eq. (40), diagonal"),
            # searched (`compare --tune`) over the default grid's range
            "K_scale": Parameter(1.0, "", True, "multiplier of K", span=(1e-3, 10.0)),
            "rho_scale": Parameter(1.0, "", True, "multiplier of rho", span=(1e-3, 10.0)),
            "noise_px": noise_parameter(self.noise_px),
            "bandwidth_scale": Parameter(
                float(self.bandwidth_scale),
                "",
                True,
                "multiplier of the fits' bandwidths",
                span=(0.25, 4.0),
            ),
            "ekf_jerk": Parameter(
                float(self.max_jerk),
                "m/s^3, rad/s^3",
                True,
                "the EKF's largest expected jerk",
                span=(float(self.max_jerk) / 100, float(self.max_jerk) * 100),
            ),
        } | (robust_parameters(ROBUST_SCALE_PX, ROBUST_GATE) if self.robust else {})

    def gains(self, params) -> dict:
        p = self.resolve(params)
        return {
            "K": (np.asarray(p["K"]) * np.asarray(p["K_scale"])).tolist(),
            "rho": (np.asarray(p["rho"]) * np.asarray(p["rho_scale"])).tolist(),
        }

    def inputs(self, key):

        return {"pixels": add_pixel_noise(key, self.clean, self.noise_px)}

    def _window(self):

        t0 = self.ts[0]
        a, b = self.window
        return WindowRMS(t0 + a, t0 + b + 1e-9, field="v_hat")

    def solve(self, method, params, inputs, *, outputs=False):

        pixels = inputs["pixels"]
        if method == "estimator":
            stream, est = self._estimator(params, pixels)
            low = self.filter_hz is not None  # scored from the saved, low-passed outputs
            reducer = None if self.truth is None or low else self._window()
            # a held step saves about once per sample interval (not every step)
            every = 1 if self.dt is None else max(1, round(self.interval / self.dt))
            sol = run(
                est,
                stream,
                dt=self.dt,
                saveat=SaveAt(every=every, outputs=outputs or low, diagnostics=outputs),
                reducer=reducer,
                adjoint=self.adjoint,
                throw=False,
            )
            return sol if not low else self._lowpassed(sol)
        if method in ("batch", "batch_window"):
            scale = params["robust_scale_px"] if self.robust else None
            return self._fit(pixels, causal=method == "batch_window", robust_scale=scale)
        if method == "ekf":
            return velocity_ekf(
                self.ts,
                pixels,
                self._camera(pixels),
                r_px=jnp.maximum(self.noise_px, 0.05),
                max_jerk=params["ekf_jerk"],
                max_angular_jerk=params["ekf_jerk"],
                gate=1.0 - params["ekf_gate_tail"] if self.robust else None,
                throw=False,
            )
        raise ValueError(f"{self.title}: unknown method {method!r}; choose {self.methods}.")

    def _lowpassed(self, sol):
        """The estimate (`v_hat` and `v_object`) through `estimators.lowpass` at
        `filter_hz` (causal, 2nd order; its delay `lowpass_delay(filter_hz)`)."""
        return eqx.tree_at(
            lambda s: (s.outputs.v_hat, s.outputs.v_object),
            sol,
            tuple(
                lowpass(sol.ts, x, self.filter_hz)
                for x in (sol.outputs.v_hat, sol.outputs.v_object)
            ),
        )

    def _estimator(self, params, pixels):
        """The estimator's stream of one draw's `pixels` and the estimator at `params`
        (resolved), as `solve` runs them."""

        ts = self.ts if self.times is None else self.times.array  # concrete for a held step
        stream = velocity_stream(
            ts, pixels, self._camera(pixels), dropped=self._dropped(), truth=self.truth,
            throw=False, chunk=self.chunk,
        )  # fmt: skip
        est = VelocityEstimator(
            K=params["K"] * params["K_scale"], rho=params["rho"] * params["rho_scale"]
        )
        return stream, est

    def _dropped(self):
        return "hold" if self.dropouts else "stop"

    def camera(self, inputs):
        """The fixed camera's constants every method of this draw (`inputs`) uses: the
        reference image is the draw's first frame unless the problem has its own; $n^*$
        and $z_1^*$ those of the calibration (`constants="calibration"`) or measured
        from the draw's own frames (`constants="per_draw"`, the paper's premise run on
        noisy images; a failed measurement fails every method of the draw)."""
        return self._camera(inputs["pixels"])

    def _camera(self, pixels):

        if self.constants == "per_draw":
            return fixed_camera(
                pixels, self.A, self.R_star, self.s1, reference_pixels=self.reference_pixels,
                known_length=self.known_length, dropped=self._dropped(), throw=False,
            )  # fmt: skip
        p_ref = pixels[0] if self.reference_pixels is None else self.reference_pixels
        return FixedCamera(p_ref, self.A, self.R_star, self.s1, self.n_star, self.z1_star)

    def _fit(self, pixels, causal, robust_scale=None):

        camera = self._camera(pixels)
        loss = None if robust_scale is None else cauchy(robust_scale)
        poses = frame_poses(pixels, camera, loss=loss)
        interval = self.interval
        bandwidths = self._fit_bandwidths()
        sols = {
            bw: velocity_smoother(
                self.ts,
                pixels,
                camera,
                bandwidth_hz=bw,
                causal=causal,
                sample_interval=interval,
                poses=poses,
                throw=False,
            )
            for bw in sorted(set(bandwidths))
        }
        # each degree of freedom from the fit at its own bandwidth
        v_hat, v_object = (
            jnp.stack([getattr(sols[bw].outputs, f)[:, i] for i, bw in enumerate(bandwidths)], 1)
            for f in ("v_hat", "v_object")
        )
        # their covariance, the fits' cross terms included
        widths = tuple(half_width_for_bandwidth(bw, interval, causal=causal) for bw in bandwidths)
        cov = velocity_covariance(poses, self.ts, widths, causal=causal)
        result, failed = RESULTS.successful, jnp.array(-1)
        for sol in sols.values():  # the first failure of any of the fits
            result, failed = first_failure(result, failed, sol.result, sol.failed_sample)
        first = sols[bandwidths[0]]
        return eqx.tree_at(
            lambda s: (
                s.outputs.v_hat,
                s.outputs.v_object,
                s.result,
                s.failed_sample,
                s.diagnostics,
            ),
            first,
            (v_hat, v_object, result, failed, SmootherDiagnostics(poses=poses, cov=cov)),
        )

    def _fit_bandwidths(self) -> tuple:
        """The fits' bandwidth per degree of freedom: the estimator's, times
        `bandwidth_scale`."""
        return tuple(float(b) * self.bandwidth_scale for b in self.bandwidths)

    def metrics(self, method, solution):
        if self.truth is None:
            return {}
        if method == "estimator" and solution.summary is not None:
            rms = solution.summary.rms
        else:  # a baseline, or the low-passed estimate (`filter_hz`): from the outputs
            truth = held(self.ts, self.truth, solution.ts)
            rms = self._window().over(solution.ts, solution.outputs, truth).rms
        return {"rms_worst": jnp.max(rms), "rms": rms}

    def trivial(self):
        """The metrics of answering zero velocity over the scoring window: the RMS of the
        true velocity there."""
        if self.truth is None:
            return {}

        w = self._window()
        rms = (
            WindowRMS(w.t_start, w.t_end).over(self.ts, jnp.zeros_like(self.truth), self.truth).rms
        )
        return {"rms_worst": jnp.max(rms), "rms": rms}

    def innovation(self, method, params, solution, inputs):
        """The estimator's output error $\\tilde e$ against the noise its measurements imply
        (`estimators.velocity_innovation`) over the scoring window; `None` for the
        baselines (not observers of $e$) and a solution saved without its time series."""

        if method != "estimator" or getattr(solution, "diagnostics", None) is None:
            return None
        stream, est = self._estimator(self.resolve(params), inputs["pixels"])
        t0 = self.ts[0]
        a, b = self.window
        return velocity_innovation(
            stream, solution, est, t_start=t0 + a, t_end=t0 + b + 1e-9, step=self.dt
        )

    def truth_outputs(self, method, solution):
        """`v_hat`: the true velocity held at the solution's times (none without one)."""
        if self.truth is None or not hasattr(solution.outputs, "v_hat"):
            return {}
        return {"v_hat": held(self.ts, self.truth, solution.ts)}

    def uncertainty(self, method, solution):
        """`rms_std` (6,): per degree of freedom, the fit's predicted standard deviation of
        the velocity (`SmootherDiagnostics.cov`) as an RMS over the window of `rms`,
        $\\sqrt{\\operatorname{mean}_k \\operatorname{var}(\\hat v_{k,i})}$: the pixel noise's
        share of `rms` (its bias, a fit lagging a fast motion, not included); NaN for the
        estimator and the EKF (an observer's or a filter's own spread is not propagated)."""
        if self.truth is None:
            return {}
        if method not in ("batch", "batch_window"):
            return {"rms_std": jnp.full(6, jnp.nan, self.ts.dtype)}
        var = jnp.diagonal(solution.diagnostics.cov, axis1=-2, axis2=-1)
        window = self._window()
        inside = (solution.ts >= window.t_start) & (solution.ts < window.t_end)
        count = jnp.maximum(jnp.sum(inside), 1).astype(var.dtype)
        mean = jnp.sum(jnp.where(inside[:, None], var, 0.0), axis=0) / count
        return {"rms_std": jnp.sqrt(mean)}

    def updates(self, method):
        return 1 if method == "batch" else int(self.ts.shape[0])

    def settings(self) -> dict:
        return {
            "source": self.source,
            "noise_px": float(self.noise_px),
            "K_reference": np.asarray(self.K).tolist(),
            "rho_reference": np.asarray(self.rho).tolist(),
            "window_s": list(self.window),
            "estimator_bandwidth_hz": list(self.bandwidths),
            "fit_bandwidth_hz": list(self._fit_bandwidths()),
            "fit_degree": 2,
            "ekf_r_px": max(float(self.noise_px), 0.05),
            "ekf_max_jerk": self.max_jerk,
            "robust": (
                f"fits: per-frame poses by the Cauchy loss, scale {ROBUST_SCALE_PX:g} px; "
                f"EKF: gate {ROBUST_GATE:g} on each pixel pair"
                if self.robust
                else "none (least squares, no gate)"
            ),
            "n_star": np.asarray(self.n_star).tolist(),
            "z1_star": float(self.z1_star),
            "constants_from": (
                "each draw's own frames (the known length on its first frame)"
                if self.constants == "per_draw"
                else "the noise-free pixels (calibration), shared by all methods"
            ),
            "known_length": None
            if self.known_length is None
            else [*self.known_length[:2], float(self.known_length[2])],
            "per_run": "pixel noise; homography, decomposition and J recomputed",
            "latency": "batch: one fit over all frames per call; others: per sample",
            "chunk": self.chunk,
            "integration_step_s": self.dt,
            "filter_hz": self.filter_hz,
            "filter_delay_s": None if self.filter_hz is None else lowpass_delay(self.filter_hz),
        }

    def figure(self, method, solution):
        """Like Fig. 2 of Chitrakaran et al. (`plots.plot_velocity`): per degree of freedom
        the truth and the estimate, and their difference; the estimate alone without a
        truth."""

        ts = solution.ts
        truth = None if self.truth is None else held(self.ts, self.truth, ts)
        return plot_velocity(
            np.asarray(ts),
            None if truth is None else np.asarray(truth),
            np.asarray(solution.outputs.v_hat),
            title=f"{self.title}: {method}",
        )


def velocity_problem(
    *,
    data=None,
    noise_px: float = 0.1,
    duration: float = 10.0,
    rate_hz: float = 1000.0,
    max_jerk: float | None = None,
    chunk: int = 256,
    adjoint: AbstractAdjoint | None = None,
    constants: str = "calibration",
    robust: bool = False,
    filter_hz: float | None = None,
) -> VelocityProblem:
    """The `velocity` problem (`VelocityProblem`) on the section-6 simulation of
    Chitrakaran et al. (`duration` at `rate_hz`, gains of eq. (63)) or on a
    `visjax.io.VelocityData` file (its gains, eq. (63) if none), with `noise_px` of pixel
    noise per seed. Scored over the paper's window (5-10 s, the second half of a shorter
    run) for its simulation and over the second half of a file.

    Stated settings: the EKF assumes the pixel noise `max(noise_px, 0.05)` and the largest
    jerk `max_jerk` (default 0.2 m/s^3 and rad/s^3 for the paper's scenario, whose velocity
    is 0.2 sin t; 1.0 for a file). `chunk`: frames per fused chunk of the stream
    (`velocity_stream`); fastest on a 2-core CPU at about 16,000 frames per chunk call, chunk
    x the vmapped batch. `adjoint`: the runner's (default `DirectAdjoint()`;
    `CheckpointAdjoint()` for reverse-mode tuning of many gains). `constants`: where
    $n^*$ and $z_1^*$ come from: `"calibration"` (default), measured once from the
    noise-free pixels and shared by every draw; `"per_draw"`, measured from each draw's
    noisy frames (what `visjax velocity` reports). $z_1^*$ comes from a known length
    (the paper's premise, section 5): in the simulation the distance between features 1
    and 3 (the square's diagonal), in a file its `length` (if it has none, from the
    object frame's origin, `depth_from_known_length`). `robust`: the baselines' robust
    settings (`VelocityProblem`). `filter_hz`: the estimator's estimate through a causal
    2nd-order low-pass at this cutoff (`estimators.lowpass`) before it is scored and saved
    (`visjax velocity --data FILE --filter-hz F`); its delay is `lowpass_delay(filter_hz)`.
    """

    if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
        raise ValueError(f"`chunk` must be a positive int (frames per chunk); got {chunk!r}.")
    if not (np.isfinite(noise_px) and noise_px >= 0):
        raise ValueError(f"`noise_px` must be finite and non-negative; got {noise_px!r}.")
    if filter_hz is not None and not (np.isfinite(filter_hz) and filter_hz > 0):
        raise ValueError(f"`filter_hz` must be a positive number of Hz; got {filter_hz!r}.")
    if constants not in ("calibration", "per_draw"):
        raise ValueError(f'`constants` must be "calibration" or "per_draw"; got {constants!r}.')
    if data is None:
        sc = section6_scenario(duration, rate_hz)
        ts, clean, A, R_star, s1 = sc.ts, sc.pixels, sc.A, sc.R_star, sc.s[0]
        truth, p_ref, K, rho = sc.velocity, None, K_EQ63, RHO_EQ63
        known_length = (0, 2, float(jnp.linalg.norm(sc.s[0] - sc.s[2])))  # the diagonal
        source = f"section-6 simulation, {duration:g} s at {rate_hz:g} Hz"
    else:
        d = VelocityData.load(data)
        ts, clean, A, R_star, s1 = (
            jnp.asarray(x, float) for x in (d.t, d.pixels, d.A, d.R_star, d.s1)
        )
        truth = None if d.velocity is None else jnp.asarray(d.velocity, float)
        known_length = d.length
        p_ref = None if d.reference_pixels is None else jnp.asarray(d.reference_pixels)
        K = K_EQ63 if d.K is None else d.K
        rho = RHO_EQ63 if d.rho is None else d.rho
        source = str(data)
    dropouts = bool(np.any(~np.isfinite(np.asarray(clean))))
    camera = fixed_camera(
        clean,
        A,
        R_star,
        s1,
        known_length=known_length,
        reference_pixels=p_ref,
        dropped="hold" if dropouts else "stop",
    )
    n_star, z1_star = camera.n_star, camera.z1_star
    K, rho = jnp.asarray(K, float), jnp.asarray(rho, float)
    # the estimator's integration step: `run`'s rule (`dt="auto"`) at the default gains,
    # chosen once here (the file's own rate where the gains allow it, else a held step)
    stream = velocity_stream(ts, clean, camera, dropped="hold" if dropouts else "stop", throw=False)
    dt = integration_step(stream, VelocityEstimator(K=K, rho=rho))
    jerk = (0.2 if data is None else 1.0) if max_jerk is None else float(max_jerk)
    span = float(ts[-1]) - float(ts[0])
    return VelocityProblem(
        ts=ts,
        clean=jnp.asarray(clean, float),
        A=A,
        R_star=R_star,
        s1=s1,
        truth=truth,
        K=K,
        rho=rho,
        n_star=n_star,
        z1_star=z1_star,
        reference_pixels=p_ref,
        noise_px=jnp.asarray(float(noise_px)),
        window=window(span) if data is None else (span / 2, span),
        bandwidths=tuple(velocity_observer_bandwidth_hz(K)),
        max_jerk=jerk,
        dropouts=dropouts,
        chunk=chunk,
        source=Note(source),
        interval=float(np.median(np.diff(np.asarray(ts)))),
        dt=dt,
        times=None if dt is None else Frozen(np.asarray(ts)),
        known_length=None if known_length is None else _length(known_length),
        constants=constants,
        adjoint=DirectAdjoint() if adjoint is None else adjoint,
        robust=bool(robust),
        filter_hz=None if filter_hz is None else float(filter_hz),
    )


def _length(known_length) -> tuple:
    i, j, length = known_length
    return (int(i), int(j), jnp.asarray(float(length), dtype=float))
