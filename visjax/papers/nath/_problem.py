"""The `static_points` problem: the Euclidean positions of static features from a moving
uncalibrated camera (Nath, Dawson, Tatlicioglu, *Euclidean position estimation of static
features using a moving uncalibrated camera*), with the adaptive estimator and its
baselines."""

from typing import Any, final

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float

from ..._util import Frozen, Note, number_text
from ...baselines import bundle_adjustment, cauchy, static_points_ekf
from ...estimators import (
    AbstractAdjoint,
    DirectAdjoint,
    SaveAt,
    StaticPointsEstimator,
    Stream,
    integration_step,
    run,
    static_points_stream,
)
from ...io import StaticPointsData
from ...plots import plot_feature_estimates
from ...sim import add_pixel_noise
from ...studies import AbstractProblem, Parameter, noise_parameter, robust_parameters
from . import _scene as nath

# the robust settings (a stated choice, not tuned to any result): the Cauchy loss, whose
# influence vanishes for large residuals (Huber's bounded influence still lets a third of a
# track 17 px off bias a feature by 2 cm: tests/baselines/test_uncertainty.py), at 1 px
ROBUST_SCALE_PX = 1.0  # the Cauchy loss' scale of the robust bundle adjustments, px
ROBUST_REJECT_PX = 3.0  # then least squares without the observations further than this
ROBUST_GATE = 0.9999  # the robust EKF's gate on each feature's pixel pair


class FinalEstimate(eqx.Module):
    """A method's solution on the `static_points` problem: `result`, `failed_sample`,
    `omega_s` (n, 3) the final estimate of the unknown features' world positions, and,
    when asked for (`outputs=True`), `ts` and `outputs` (the method's saved outputs) and,
    for the estimator, `diagnostics` (its saved `StaticPointsDiagnostics`: prediction
    errors, depths, the information rate, $\\lambda_{\\min}(\\Gamma_c)$, resets);
    `omega_s_std` (n, 3) the standard deviation of `omega_s` the method predicts (a bundle
    adjustment's covariance, the EKF's final covariance; NaN for the estimator)."""

    result: Any
    failed_sample: Any
    omega_s: Any
    ts: Any = None
    outputs: Any = None
    diagnostics: Any = None
    omega_s_std: Any = None


@final
class StaticPointsProblem(AbstractProblem):
    """The world positions of static features seen by a camera on a moving platform whose
    intrinsic and extrinsic parameters are only nominally known (Nath et al.). Build it
    with `static_points_problem`.

    Methods: `estimator`, the adaptive least-squares estimator (eqs. (37)-(51),
    `StaticPointsEstimator.from_nominal`: gains from the scene's scale, initial
    guesses from the nominal camera, derived per run from that run's noisy stream;
    integrated at 1 kHz on the held samples); `batch`, bundle adjustment over all frames;
    `batch_window`, over the last `window_s` seconds every `every_s` seconds (causal);
    `ekf`, `baselines.static_points_ekf`; all from the same initial guesses.

    Parameters: `alpha_scale` multiplies $\\alpha_c$ and $\\alpha$ (eqs. (37), (41)) and
    `gamma_scale` the initial gains $\\eta_0$, $\\eta_1$ and $\\gamma_{s0}$ (eqs. (39),
    (45)) of the derived gains (Nath et al. publish none for this scene); the baselines':
    `window_frames` (`batch_window`'s frames per fit, a structural parameter),
    `ekf_q_rate` (the EKF's process noise rate, `static_points_ekf`'s `q_rate`) and,
    when `robust`, `robust_scale_px` and `ekf_gate_tail` (`studies.robust_parameters`).
    Metrics: `error`
    (n,), each unknown feature's final position error (m), and `error_worst`, the largest.

    `robust` (the command line's `--robust`): the baselines' robust settings for pixel
    tracks with outliers: the bundle adjustments minimise the Cauchy loss of each
    feature's pixel residual with the scale `ROBUST_SCALE_PX` (an outlier observation's
    influence vanishes; the fit over all frames then leaves out the observations further
    than `ROBUST_REJECT_PX` and refits them by least squares), and the EKF gates each
    feature's pixel pair at the `ROBUST_GATE` quantile (`ExtendedKalmanFilter`). The
    adaptive estimator has no robust setting: it takes every sample it is given.
    """

    methods = ("estimator", "batch", "batch_window", "ekf")
    metric = "error_worst"
    label = "worst final position error (m)"
    trivial_label = "the initial guess"
    data_parameters = ("noise_px",)
    grid = "alpha_scale=0.1:10:5,gamma_scale=0.1:10:5"
    columns = {  # each unknown feature i's estimated world position: X_i, Y_i, Z_i
        "omega_s": lambda shape: [f"{c}_{i}" for i in range(shape[0]) for c in "XYZ"],
        "A": lambda shape: [f"A_{i + 1}{j + 1}" for i in range(3) for j in range(3)],
        "R_c": lambda shape: [f"R_c_{i + 1}{j + 1}" for i in range(3) for j in range(3)],
    }  # fmt: skip
    units = {
        "error": "m", "error_worst": "m", "omega_s": "m", "x_c": "m", "A": "px", "R_c": "-",
    }  # fmt: skip
    structural_parameters = ("window_frames",)
    own_parameters = {
        "estimator": ("alpha_scale", "gamma_scale"),
        "batch": ("robust_scale_px",),
        "batch_window": ("window_frames", "robust_scale_px"),
        "ekf": ("ekf_q_rate", "ekf_gate_tail"),
    }

    ts: Float[ArrayLike, " n"]
    R_b: Float[ArrayLike, "n 3 3"]
    x_b: Float[ArrayLike, "n 3"]
    omega_c: Float[ArrayLike, "k 3"]
    clean: Float[ArrayLike, "n m 2"]  # the noise-free pixels, the known features first
    truth: Float[ArrayLike, "u 3"] | None  # the unknown features' world positions, or None
    A_nominal: Float[ArrayLike, "3 3"]
    R_c_nominal: Float[ArrayLike, "3 3"]
    x_c_nominal: Float[ArrayLike, " 3"]
    n_known: int = eqx.field(static=True)
    noise_px: Float[ArrayLike, ""]  # a data parameter (`at`): a noise sweep is one `vmap`
    dt: float | None = eqx.field(static=True)
    window_frames: int = eqx.field(static=True)
    every_frames: int = eqx.field(static=True)
    source: str = eqx.field(static=True)  # a `Note`: it does not key compilation
    save_every: int = eqx.field(static=True, default=1)
    times: Frozen | None = eqx.field(static=True, default=None)  # `ts`, with a held step
    adjoint: AbstractAdjoint = DirectAdjoint()
    robust: bool = eqx.field(default=False, static=True)

    @property
    def title(self) -> str:
        return (
            f"static points, uncalibrated camera (Nath et al.), {self.source}, "
            f"{number_text(self.noise_px)} px noise" + (", robust baselines" if self.robust else "")
        )

    @property
    def scored(self) -> bool:
        return self.truth is not None

    def parameters(self) -> dict[str, Parameter]:
        return {
            "alpha_scale": Parameter(1.0, "", True, "multiplier of alpha_c and alpha"),
            "gamma_scale": Parameter(1.0, "", True, "multiplier of eta0, eta1, gamma_s0"),
            "noise_px": noise_parameter(self.noise_px),
            "window_frames": Parameter(
                float(self.window_frames), "frames", True, "frames per sliding-window fit"
            ),
            "ekf_q_rate": Parameter(
                1e-12, "1/s", True, "the EKF's process noise rate", span=(1e-16, 1e-8)
            ),
        } | (robust_parameters(ROBUST_SCALE_PX, ROBUST_GATE) if self.robust else {})

    def gains(self, params) -> dict:
        p = self.resolve(params)
        return {k: float(p[k]) for k in self.own_parameters["estimator"]}

    def inputs(self, key):

        return {"pixels": add_pixel_noise(key, self.clean, self.noise_px)}

    def _ts(self):
        # with a held step the runner maps the sample times onto its steps: concrete
        return self.ts if self.times is None else self.times.array

    def _estimator(self, pixels):

        k = self.n_known
        stream = static_points_stream(
            self._ts(),
            self.R_b,
            self.x_b,
            pixels[:, k:],
            pixels[:, :k],
            self.omega_c,
            throw=False,
        )
        est = StaticPointsEstimator.from_nominal(
            stream, self.A_nominal, self.R_c_nominal, self.x_c_nominal, dt=self.dt
        )
        return stream, est

    def solve(self, method, params, inputs, *, outputs=False):

        stream, est = self._estimator(inputs["pixels"])
        if method == "estimator":
            a, g = params["alpha_scale"], params["gamma_scale"]
            est = eqx.tree_at(
                lambda e: (e.alpha_c, e.alpha, e.eta0, e.eta1, e.gamma_s0),
                est,
                (a * est.alpha_c, a * est.alpha, g * est.eta0, g * est.eta1, g * est.gamma_s0),
            )
            sol = run(
                est,
                stream,
                dt=self.dt,
                saveat=SaveAt(every=self.save_every, outputs=outputs, diagnostics=outputs),
                adjoint=self.adjoint,
                throw=False,
            )
            last = jax.tree_util.tree_map(lambda x: x[-1], stream.ys)
            omega_s = est.output(self.ts[-1], sol.final_state, last).omega_s
            std = jnp.full_like(omega_s, jnp.nan)
        elif method in ("batch", "batch_window"):
            window = {} if method == "batch" else {"window": self.window_frames}
            if method == "batch_window":
                window["every"] = self.every_frames
            if self.robust:
                window["loss"] = cauchy(params["robust_scale_px"])
                if method == "batch":
                    window["reject_px"] = ROBUST_REJECT_PX
            sol = bundle_adjustment(est, stream, self.omega_c, throw=False, **window)
            omega_s = sol.outputs.omega_s[-1]
            std = sol.diagnostics.omega_s_std[-1]
        elif method == "ekf":
            sol = static_points_ekf(
                est, stream, self.omega_c, r_px=jnp.maximum(self.noise_px, 0.05),
                q_rate=params["ekf_q_rate"],
                gate=1.0 - params["ekf_gate_tail"] if self.robust else None, throw=False,
            )  # fmt: skip
            omega_s = sol.outputs.omega_s[-1]
            # the state ends with the features (static_points_ekf)
            var = jnp.diagonal(sol.diagnostics[-1])[-omega_s.size :]
            std = jnp.sqrt(jnp.maximum(var, 0.0)).reshape(omega_s.shape)
        else:
            raise ValueError(f"{self.title}: unknown method {method!r}; choose {self.methods}.")
        return FinalEstimate(
            sol.result,
            sol.failed_sample,
            omega_s,
            sol.ts if outputs else None,
            sol.outputs if outputs else None,
            getattr(sol, "diagnostics", None) if outputs else None,
            std,
        )

    def truth_outputs(self, method, solution):
        """`omega_s`: the unknown features' true world positions (static)."""
        outputs = getattr(solution, "outputs", None)
        if self.truth is None or not hasattr(outputs, "omega_s"):
            return {}
        return {"omega_s": self.truth}

    def metrics(self, method, solution):
        if self.truth is None:
            return {}
        error = jnp.linalg.norm(solution.omega_s - self.truth, axis=-1)
        return {"error_worst": jnp.max(error), "error": error}

    def trivial(self):
        """The metrics of the estimator's initial guess held (`from_nominal` on the noise-free
        pixels: each unknown feature on its nominal ray at the known features' median depth,
        where it is first seen), scored as every method is."""
        if self.truth is None:
            return {}
        stream, est = self._estimator(self.clean)
        y0 = jax.tree_util.tree_map(lambda x: x[0], stream.ys)
        omega_s = est.output(self.ts[0], est.init(y0), y0).omega_s
        error = jnp.linalg.norm(omega_s - self.truth, axis=-1)
        return {"error_worst": jnp.max(error), "error": error}

    def uncertainty(self, method, solution):
        """`error_std` (n,): each unknown feature's predicted RMS position error,
        $\\sqrt{\\operatorname{tr} C_i}$ of its covariance (the bundle adjustments'
        $\\hat\\sigma^2(J^TJ)^{-1}$, the EKF's final covariance); NaN for the estimator."""
        if self.truth is None:
            return {}
        return {"error_std": jnp.sqrt(jnp.sum(solution.omega_s_std**2, axis=-1))}

    def updates(self, method):
        n = int(self.ts.shape[0])
        return {"batch": 1, "batch_window": -(-n // self.every_frames)}.get(method, n)

    def settings(self) -> dict:
        return {
            "source": self.source,
            "noise_px": float(self.noise_px),
            "estimator": "from_nominal (gains from the scene's scale), 1 kHz on held samples",
            "reference_gains": "from_nominal's derived gains (Nath et al. give none for "
            "this scene)",
            "integration_step_s": self.dt,
            "window_frames": self.window_frames,
            "window_every_frames": self.every_frames,
            "ekf_r_px": max(float(self.noise_px), 0.05),
            "robust": (
                f"bundle adjustments: Cauchy loss, scale {ROBUST_SCALE_PX:g} px (batch: then "
                f"least squares without the observations beyond {ROBUST_REJECT_PX:g} px); "
                f"EKF: gate {ROBUST_GATE:g} on each pixel pair"
                if self.robust
                else "none (least squares, no gate)"
            ),
            "metric": "worst final position error of the unknown features (m)",
            "latency": "batch: one fit over all frames per call; batch_window: per fit; "
            "others: per sample",
        }

    def figure(self, method, solution):
        """Each unknown feature's estimated position and, with the truth, its error
        (`plots.plot_feature_estimates`), as Nath et al. show the structure's convergence."""

        return plot_feature_estimates(
            np.asarray(solution.ts),
            np.asarray(solution.outputs.omega_s),
            None if self.truth is None else np.asarray(self.truth),
            title=f"{self.title}: {method}",
        )


def static_points_problem(
    *,
    data=None,
    noise_px: float = 0.1,
    duration: float = 20.0,
    rate_hz: float = 100.0,
    window_s: float = 2.0,
    every_s: float = 1.0,
    adjoint: AbstractAdjoint | None = None,
    exciting: bool = True,
    robust: bool = False,
) -> StaticPointsProblem:
    """The `static_points` problem (`StaticPointsProblem`) on the project's scene
    (`papers.nath.scenario`, `duration` at `rate_hz`, the nominal camera of
    `nath.nominal_camera`) or on a `visjax.io.StaticPointsData` file, with `noise_px` of
    pixel noise per seed. The EKF assumes the pixel noise `max(noise_px, 0.05)`; its prior
    spreads are those of `static_points_ekf` (a nominal camera's uncertainty).
    `exciting=False`: the scene's platform only moves along its optical axis (not
    persistently exciting: the structure is not recoverable). `robust`: the baselines'
    robust settings (`StaticPointsProblem`)."""

    if not (np.isfinite(noise_px) and noise_px >= 0):
        raise ValueError(f"`noise_px` must be finite and non-negative; got {noise_px!r}.")
    if data is None:
        sc = nath.scenario(duration, rate_hz, exciting=exciting)
        ts, R_b, x_b, omega_c = sc.ts, sc.R_b, sc.x_b, sc.omega_c
        pixels = jnp.concatenate([sc.p_c, sc.p_s], axis=1)
        n_known, truth, nominal = sc.p_c.shape[1], sc.omega_s, nath.nominal_camera()
        source = f"the project's scene, {duration:g} s at {rate_hz:g} Hz" + (
            "" if exciting else ", not exciting"
        )
    else:
        if not exciting:
            raise ValueError("`exciting` chooses the project's scene; a data file has its own.")

        d = StaticPointsData.load(data)
        ts, R_b, x_b, omega_c = (
            jnp.asarray(x, float) for x in (d.t, d.platform_R, d.platform_x, d.known_features)
        )
        pixels, n_known = jnp.asarray(d.pixels, float), d.n_known
        truth = None if d.features is None else jnp.asarray(d.features, float)
        nominal = (d.A_nominal, d.R_c_nominal, d.x_c_nominal)
        source = str(data)
    interval = float(np.max(np.diff(np.asarray(ts))))
    # 1 kHz on held samples; `from_nominal` derives its gains for that step (no bound here)
    dt = integration_step(Stream(ts=ts, ys=ts), max_step=1e-3)
    A_n, R_n, x_n = (jnp.asarray(x, float) for x in nominal)
    saved = max(interval, 0.01)  # the estimator's saving interval, s
    return StaticPointsProblem(
        ts=ts,
        R_b=R_b,
        x_b=x_b,
        omega_c=omega_c,
        clean=pixels,
        truth=truth,
        A_nominal=A_n,
        R_c_nominal=R_n,
        x_c_nominal=x_n,
        n_known=int(n_known),
        noise_px=jnp.asarray(float(noise_px)),
        dt=None if dt is None else float(dt),
        window_frames=max(2, int(round(window_s / interval))),
        every_frames=max(1, int(round(every_s / interval))),
        source=Note(source),
        save_every=max(1, int(round(saved / (dt or saved)))),  # at most 100 Hz
        times=None if dt is None else Frozen(np.asarray(ts)),
        adjoint=DirectAdjoint() if adjoint is None else adjoint,
        robust=bool(robust),
    )
