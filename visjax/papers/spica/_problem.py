"""The problem `point_depth` (Spica et al., *Active Structure from Motion*): the inverse
depth of static points seen by a camera moving with a known velocity, every method on one
scene of its own."""

import textwrap
from typing import Any, ClassVar, Literal, final

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..._results import RESULTS
from ..._util import number_text
from ...baselines import (
    InverseDepthModel,
    cauchy,
    extended_kalman_filter,
    triangulate_point,
)
from ...estimators import (
    PointDepthEstimator,
    SaveAt,
    innovation,
    moving_point_stream,
    point_depth_stream,
    run,
)
from ...geometry import pixel_to_normalized
from ...sim import (
    PointDepthScene,
    point_depth_scene,
)
from ...studies import AbstractProblem, Parameter, noise_parameter, robust_parameters
from ._scene import ROBUST_GATE, ROBUST_SCALE_PX

_Projection = Literal["planar", "spherical"]


def _first_failure(results, n):
    """The first failure over `n` points' results (batched by `vmap`), or success."""
    result = RESULTS.successful
    for k in range(n):
        result_k = jax.tree_util.tree_map(lambda v, k=k: v[k], results)
        result = RESULTS.where(result == RESULTS.successful, result_k, result)
    return result


class LeastSquaresDepth(eqx.Module):
    """A baseline's solution: `ts`, `depth` (N, n) (NaN before a least-squares window
    determines a point), `result` (the first failure over the points), `depth_std` (N, n)
    the standard deviation of each depth as the method predicts it (the least-squares
    triangulation: from its covariance; the EKF: from its inverse depth's variance; NaN
    where the depth is)."""

    ts: Float[Array, " N"]
    depth: Float[Array, "N n"]
    result: Any
    depth_std: Float[Array, "N n"]


@final
class PointDepthProblem(AbstractProblem):
    """The depth of static points from a moving calibrated camera with known velocity
    (Spica et al.'s observer, module docstring), against a sliding-window least-squares
    triangulation on the same measurements (`visjax.baselines.triangulate_point`, the last
    `window` frames, a structural parameter; its warm-up ends at a window whose
    triangulation angle at the shared depth guess $1/\\chi_0$ is `ls_parallax` pixel-noise
    angles, `noise_px / f`, default 10, where a window of a few frames gives a depth of
    either sign) and an EKF on inverse depth per point
    (`InverseDepthModel`; planar coordinates for both projections: its prior is the
    observer's `chi0` with a standard deviation of `ekf_sigma_chi0` times `chi0`, default
    0.5, its measurement noise the problem's pixel noise, at least 0.1 px, its process noise
    `ekf_q` per second on every state, default 1e-8).

    Metrics: `depth_error` the worst relative depth error over the points at the last
    sample; `time_to_5pct` the first time from which every point's relative error stays
    below 5% (the run's length if never). Uncertainty (`uncertainty`): `depth_error_std`,
    the largest over the points of the predicted standard deviation of the depth over the
    true depth at the last sample (the baselines' own: the triangulation's covariance,
    the EKF's variance; NaN for the observer, which predicts none).

    `robust` (the command line's `--robust`): the baselines' robust settings for pixel
    tracks with outliers: the triangulation minimises the Cauchy loss of each frame's
    reprojection residual with the scale `ROBUST_SCALE_PX` (iteratively reweighted least
    squares, `triangulate_point(..., loss=...)`), and the EKF gates each point's measured
    pair at the `ROBUST_GATE` quantile (`ExtendedKalmanFilter`). The observer has no
    robust setting: it takes every sample it is given."""

    methods: ClassVar[tuple] = ("estimator", "least_squares", "ekf")
    metric: ClassVar[str] = "depth_error"
    trivial_label: ClassVar[str] = "the initial depth guess"
    label: ClassVar[str] = "worst relative depth error at the end (-)"
    grid: ClassVar[str] = "alpha=100:3000:5"
    units: ClassVar[dict] = {
        "depth_error": "-", "time_to_5pct": "s", "depth": "m", "chi_hat": "1/m",
        "point": "m", "z": "m", "chi": "1/m",
    }  # fmt: skip
    structural_parameters: ClassVar[tuple[str, ...]] = ("window",)
    own_parameters: ClassVar[dict] = {
        "estimator": ("alpha", "h", "chi0"),
        "least_squares": ("window", "ls_parallax", "robust_scale_px"),
        "ekf": ("chi0", "ekf_q", "ekf_sigma_chi0", "ekf_gate_tail"),
    }
    defaults_label: ClassVar[str] = "defaults"  # visjax's own gains, not a paper's
    data_parameters: ClassVar[tuple[str, ...]] = ("noise_px",)

    scene: PointDepthScene
    noise_px: Float[ArrayLike, ""] = 0.0  # a data parameter (`at`): a noise sweep is one `vmap`
    projection: str = eqx.field(static=True, default="planar")
    window: int = eqx.field(static=True, default=250)
    robust: bool = eqx.field(static=True, default=False)

    @property
    def title(self) -> str:
        return "depth of static points, moving camera (Spica et al.)" + (
            ", robust baselines" if self.robust else ""
        )

    def parameters(self):
        return {
            "alpha": Parameter(1000.0, "1/m^2", True, "the inverse depth's gain"),
            "h": Parameter(20.0, "1/s", True, "the measured part's gain, H = h I"),
            # the initial guess every method shares: not tuned (`compare --tune` would
            # learn the scene's depth from the training seeds)
            "chi0": Parameter(1.0 / 1.5, "1/m", True, "the initial inverse depth", tunable=False),
            "noise_px": noise_parameter(self.noise_px),
            "window": Parameter(float(self.window), "samples", True, "samples per window fit"),
            "ls_parallax": Parameter(
                10.0, "noise angles", True, "the least squares' smallest triangulation angle"
            ),
            "ekf_q": Parameter(
                1e-8, "1/s", True, "the EKF's process noise on every state", span=(1e-12, 1e-4)
            ),
            # two standard deviations from chi0 to 0: the prior within the model's valid set
            # (chi > 0); at 1, a sixth of it is behind the camera and the first updates, at
            # a parallax below the noise, take chi across 0 on many draws (`diverged`)
            "ekf_sigma_chi0": Parameter(0.5, "", True, "the EKF's prior spread / chi0"),
        } | (robust_parameters(ROBUST_SCALE_PX, ROBUST_GATE) if self.robust else {})

    def settings(self):
        return {
            "noise_px": float(self.noise_px),
            "projection": self.projection,
            "window_samples": self.window,
            "samples": int(self.scene.ts.shape[0]),
            "robust": (
                f"least squares: Cauchy loss, scale {ROBUST_SCALE_PX:g} px (iteratively "
                f"reweighted); EKF: gate {ROBUST_GATE:g} on each measured pair"
                if self.robust
                else "none (least squares, no gate)"
            ),
        }

    def inputs(self, key):
        noise = jax.random.normal(key, self.scene.pixels.shape, self.scene.pixels.dtype)
        return self.scene.pixels + self.noise_px * noise

    def solve(self, method, params, inputs, *, outputs=False):
        sc = self.scene
        if method == "estimator":
            observer = PointDepthEstimator(
                alpha=params["alpha"],
                h=params["h"],
                chi0=params["chi0"],
                projection=self.projection,
            )
            stream = point_depth_stream(
                sc.ts, inputs, sc.twists, sc.K, projection=self.projection, throw=False
            )
            return run(observer, stream, saveat=SaveAt(states=outputs), throw=False)

        if method == "ekf":
            return self._ekf(params, inputs)

        # the robust loss in normalised coordinates: its pixel scale over the focal length
        loss = cauchy(params["robust_scale_px"] / sc.K[0, 0]) if self.robust else None

        # the warm-up ends at a window whose triangulation angle at the shared depth guess
        # (1 / chi0) is `ls_parallax` pixel-noise angles
        min_baseline = params["ls_parallax"] * self.noise_px / sc.K[0, 0] / params["chi0"]

        def one(pixels):
            stream = moving_point_stream(sc.ts, pixels, sc.twists, sc.K, throw=False)
            sol = triangulate_point(
                stream, window=self.window, loss=loss, min_baseline=min_baseline, throw=False
            )
            m, cov = sol.outputs.position, sol.diagnostics.cov
            if self.projection == "spherical":
                # the distance |m|, to first order: var = u^T C u, u = m / |m|
                depth = jnp.linalg.norm(m, axis=-1)
                u = m / depth[:, None]
                var = jnp.einsum("ni,nij,nj->n", u, cov, u)
            else:
                depth, var = m[:, 2], cov[:, 2, 2]
            std = jnp.where(jnp.isfinite(depth), jnp.sqrt(jnp.maximum(var, 0.0)), jnp.nan)
            return depth, sol.result, std

        depth, results, std = jax.vmap(one, in_axes=1, out_axes=(1, 0, 1))(inputs)
        return LeastSquaresDepth(
            ts=sc.ts,
            depth=depth,
            result=_first_failure(results, depth.shape[1]),
            depth_std=std,
        )

    def _ekf(self, params, inputs):
        sc = self.scene
        focal = sc.K[0, 0]
        sigma = jnp.maximum(self.noise_px, 0.1)
        q = params["ekf_q"]
        model = InverseDepthModel(q_s=q, q_chi=q, r=(sigma / focal) ** 2)
        chi0 = params["chi0"]

        def one(pixels):
            m = pixel_to_normalized(pixels, sc.K)
            x0 = jnp.stack([m[0, 0], m[0, 1], chi0])
            sd_chi = params["ekf_sigma_chi0"] * chi0
            P0 = jnp.diag(jnp.stack([model.r, model.r, sd_chi**2]))
            sol = extended_kalman_filter(model, sc.ts, m, sc.twists, x0, P0, gate=gate, throw=False)
            chi = sol.outputs.x[:, 2]
            # the depth's standard deviation from the inverse depth's, to first order:
            # d(1/chi) = -d(chi)/chi^2
            std = jnp.sqrt(jnp.maximum(sol.outputs.P[:, 2, 2], 0.0)) / chi**2
            if self.projection == "spherical":  # the distance along the measured bearing
                scale = jnp.sqrt(1.0 + jnp.sum(m**2, axis=-1))
                depth, std = scale / chi, scale * std
            else:
                depth = 1.0 / chi
            std = jnp.where(jnp.isfinite(depth), std, jnp.nan)
            return depth, sol.result, std

        gate = 1.0 - params["ekf_gate_tail"] if self.robust else None
        depth, results, std = jax.vmap(one, in_axes=1, out_axes=(1, 0, 1))(inputs)
        return LeastSquaresDepth(
            ts=sc.ts,
            depth=depth,
            result=_first_failure(results, depth.shape[1]),
            depth_std=std,
        )

    def truth_outputs(self, method, solution):
        """`depth`: each point's true depth at the solution's times (the scene's samples;
        none where the solution saved others)."""
        outputs = getattr(solution, "outputs", solution)  # a baseline's: its own fields
        truth = self._truth()
        if not hasattr(outputs, "depth") or outputs.depth.shape != truth.shape:
            return {}
        return {"depth": truth}

    def _truth(self):
        P = self.scene.points
        return P[..., 2] if self.projection == "planar" else jnp.linalg.norm(P, axis=-1)

    def metrics(self, method, solution):
        depth = solution.outputs.depth if method == "estimator" else solution.depth
        err = jnp.abs(depth / self._truth() - 1.0)  # (N, n); NaN before a window
        within = jnp.all(err < 0.05, axis=1)  # NaN compares False
        settled = jnp.flip(jnp.cumprod(jnp.flip(within)))  # within from here to the end
        ts = self.scene.ts
        first = jnp.argmax(settled)
        time = jnp.where(jnp.any(settled), ts[first] - ts[0], ts[-1] - ts[0])
        return {"depth_error": jnp.max(err[-1]), "time_to_5pct": time}

    def trivial(self):
        """The metrics of the initial depth guess held, $1/\\chi_0$ (the default `chi0`)
        for every point at every sample, scored as every method is."""
        truth = self._truth()
        guess = jnp.full_like(truth, 1.0 / self.parameters()["chi0"].value)
        return self.metrics("least_squares", LeastSquaresDepth(
            ts=self.scene.ts, depth=guess, result=RESULTS.successful, depth_std=guess
        ))  # fmt: skip

    def innovation(self, method, params, solution, inputs):
        """The observer's output error $\\xi = s - \\hat s$ (every point's measured
        coordinates) over the second half, against the noise its measurements imply
        (`estimators.innovation`); `None` for the baselines and a solution saved without
        its states."""

        if method != "estimator" or getattr(solution, "states", None) is None:
            return None
        sc = self.scene
        stream = point_depth_stream(
            sc.ts, inputs, sc.twists, sc.K, projection=self.projection, throw=False
        )
        n = sc.ts.shape[0]
        s, s_hat = stream.ys.s.reshape(n, -1), solution.states.s_hat.reshape(n, -1)
        return innovation(s, s - s_hat, jnp.arange(n) >= n // 2)

    def uncertainty(self, method, solution):
        """`depth_error_std`: the largest over the points of the predicted standard
        deviation of the depth over the true depth at the last sample (the predicted spread
        of each point's relative depth error, which `depth_error` takes the largest of);
        NaN for the observer."""
        truth = self._truth()[-1]
        if method == "estimator":
            return {"depth_error_std": jnp.full((), jnp.nan, truth.dtype)}
        return {"depth_error_std": jnp.max(solution.depth_std[-1] / truth)}

    def figure(self, method, solution):
        """The relative depth error of every point over time (log scale), the 5% line."""
        import matplotlib.pyplot as plt

        depth = solution.outputs.depth if method == "estimator" else solution.depth
        err = np.abs(np.asarray(depth) / np.asarray(self._truth()) - 1.0)
        ts = np.asarray(self.scene.ts)
        fig, ax = plt.subplots(figsize=(7, 3.5))
        for i in range(err.shape[1]):
            z = float(np.asarray(self._truth())[0, i])
            ax.semilogy(ts, err[:, i], lw=0.8, label=f"point {i + 1} ({z:.1f} m)")
        ax.axhline(0.05, color="k", lw=0.6, ls="--", label="5%")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("relative depth error [-]")
        title = f"{self.title}: {method}, {self.projection}, {number_text(self.noise_px)} px"
        ax.set_title(textwrap.fill(title, 70))  # 12 pt: about 10 characters an inch
        ax.legend(fontsize=7)
        fig.tight_layout()
        return fig


def point_depth_problem(
    *,
    noise_px: float = 0.0,
    duration: float = 1.0,
    rate_hz: float = 1000.0,
    variant: str | None = None,
    window_s: float = 0.25,
    robust: bool = False,
) -> PointDepthProblem:
    """The `point_depth` problem on `point_depth_scene(duration, rate_hz)` with Gaussian
    pixel noise `noise_px`; `variant` (`--set`) the projection, `"planar"` (default) or
    `"spherical"`; `window_s` the least-squares baseline's window (s); `robust`: the
    baselines' robust settings (`PointDepthProblem`)."""
    projection = variant or "planar"
    if projection not in PointDepthEstimator.dims:
        raise ValueError(f'the variant must be "planar" or "spherical"; got {variant!r}.')
    if not noise_px >= 0:
        raise ValueError(f"`noise_px` must be non-negative; got {noise_px!r}.")
    window = max(2, int(round(window_s * rate_hz)))
    return PointDepthProblem(
        scene=point_depth_scene(duration, rate_hz),
        noise_px=jnp.asarray(float(noise_px)),
        projection=projection,
        window=window,
        robust=bool(robust),
    )
