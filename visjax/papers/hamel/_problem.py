"""The problems `homography` (a camera moving before a planar target, the SL(3) observer of
Hamel et al. against per-frame homographies) and `velocity_front_end` (the observer as the
front end of the velocity problem of Chitrakaran et al.)."""

import textwrap
from typing import Any, ClassVar, final

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..._results import RESULTS
from ..._util import number_text
from ...baselines import ransac_homographies
from ...estimators import (
    HomographyEstimator,
    SaveAt,
    homography_bearings,
    homography_stream,
    innovation,
    run,
    unit_bearings,
)
from ...geometry import (
    euclidean_reconstruction,
    find_homography_robust,
    skew,
    sl3_normalize,
)
from ...sim import (
    HomographyScene,
    homography_scene,
)
from ...studies import (
    AbstractProblem,
    Parameter,
    noise_parameter,
)
from ..chitrakaran import velocity_problem
from ._scene import ROBUST_ITERATIONS, ROBUST_THRESHOLD_PX


def homography_error(H_hat: Float[ArrayLike, "*N 3 3"], H: Float[ArrayLike, "*N 3 3"]):
    """$\\|\\hat H H^{-1} - I\\|_F$ with $\\hat H$ brought to SL(3) (`H` in SL(3)): 0 when
    the estimate is the truth; NaN for a failed (NaN) estimate."""
    H_hat = jnp.vectorize(sl3_normalize, signature="(3,3)->(3,3)")(jnp.asarray(H_hat))
    E = jnp.linalg.solve(jnp.swapaxes(H, -1, -2), jnp.swapaxes(H_hat, -1, -2))
    E = jnp.swapaxes(E, -1, -2)
    return jnp.linalg.norm(E - jnp.broadcast_to(jnp.eye(3, dtype=E.dtype), E.shape), axis=(-2, -1))


class FrameHomographies(eqx.Module):
    """A per-frame baseline's solution: `ts`, `H` (N, 3, 3) current to reference in SL(3)
    (NaN where a frame failed), `result` (the first failure, or success)."""

    ts: Float[Array, " N"]
    H: Float[Array, "N 3 3"]
    result: Any


def _to_observer_convention(G, K):
    """A projective homography `G` (reference to current pixels) as the observer's
    Euclidean one, current to reference bearings, in SL(3): $(K^{-1} G K)^{-1}$."""
    H = jnp.linalg.solve(K, G @ K)
    return sl3_normalize(jnp.linalg.inv(H))


@final
class HomographyProblem(AbstractProblem):
    """Tracking the homography of a planar target from a moving camera (`homography_scene`):
    the observer of Hamel et al. with the group velocity measured (`estimator`) or only
    the camera's angular velocity (`gyro`, the rest by the integral term), against
    per-frame homographies: the four-point DLT of the target's corners (`dlt`,
    `visjax.geometry.euclidean_reconstruction`'s $G_n$; with `robust`, the command line's
    `--robust`: visjax's RANSAC and Huber-reweighted DLT on all eight points,
    `visjax.geometry.find_homography_robust`, 3 px) and OpenCV's `findHomography` with
    RANSAC on all eight points (`ransac`, threshold `ransac_px`, default 3 px). Each draw
    adds `noise_px` of Gaussian noise to the current and to the reference pixels. The
    observer starts at the identity (the truth is 0.3 away).

    Metrics: `error`, the RMS over the second half of $\\|\\hat H H^{-1} - I\\|_F$
    (`homography_error`); `final_error`, that error at the last sample."""

    methods: ClassVar[tuple] = ("estimator", "gyro", "dlt", "ransac")
    metric: ClassVar[str] = "error"
    label: ClassVar[str] = "RMS of |H_hat H^-1 - I| over the second half (-)"
    trivial_label: ClassVar[str] = "the identity (the reference image's homography)"
    grid: ClassVar[str] = "k_P=3:200:5"
    columns: ClassVar[dict] = {
        "H": lambda shape: [f"H_{i + 1}{j + 1}" for i in range(3) for j in range(3)],
        "A": lambda shape: [f"A_{i + 1}{j + 1}" for i in range(3) for j in range(3)],
    }  # fmt: skip
    units: ClassVar[dict] = {"error": "-", "final_error": "-", "H": "-", "A": "-"}
    own_parameters: ClassVar[dict] = {
        "estimator": ("k_P",), "gyro": ("k_P", "k_I"), "dlt": (), "ransac": ("ransac_px",)
    }  # fmt: skip
    title: ClassVar[str] = "homography of a planar target (Hamel et al.)"
    defaults_label: ClassVar[str] = "defaults"  # visjax's own gains, not a paper's

    data_parameters: ClassVar[tuple[str, ...]] = ("noise_px",)

    scene: HomographyScene
    noise_px: Float[ArrayLike, ""] = 0.0  # a data parameter (`at`): a noise sweep is one `vmap`
    robust: bool = eqx.field(static=True, default=False)

    def parameters(self):
        return {
            "k_P": Parameter(30.0, "1/s", True, "the gain of the innovation"),
            "k_I": Parameter(
                10.0, "1/s^2", False, "the integral gain (method gyro)", span=(0.1, 1000.0)
            ),
            "noise_px": noise_parameter(self.noise_px),
            "ransac_px": Parameter(3.0, "px", True, "OpenCV RANSAC's reprojection threshold"),
        }

    def settings(self):
        return {
            "noise_px": float(self.noise_px),
            "samples": int(self.scene.ts.shape[0]),
            "points": int(self.scene.reference.shape[0]),
            "ransac_threshold_px": 3.0,  # the default of `ransac_px`
            "dlt_points": (
                f"all points: find_homography_robust ({ROBUST_ITERATIONS} RANSAC hypotheses, "
                f"{ROBUST_THRESHOLD_PX:g} px, then Huber-reweighted DLT)"
                if self.robust
                else "the four corners"
            ),
            "per_run": "pixel noise on the current and the reference images",
        }

    def inputs(self, key):
        sc = self.scene
        k1, k2 = jax.random.split(key)
        pixels = sc.pixels + self.noise_px * jax.random.normal(k1, sc.pixels.shape)
        reference = sc.reference + self.noise_px * jax.random.normal(k2, sc.reference.shape)
        return {"pixels": pixels, "reference": reference}

    def solve(self, method, params, inputs, *, outputs=False):
        sc = self.scene
        pixels, reference = inputs["pixels"], inputs["reference"]
        if method in ("estimator", "gyro"):
            A = sc.A if method == "estimator" else jax.vmap(skew)(sc.omega)
            observer = HomographyEstimator(
                k_P=params["k_P"],
                p_ref=unit_bearings(reference, sc.K),
                k_I=params["k_I"] if method == "gyro" else 0.0,
            )
            stream = homography_stream(sc.ts, pixels, A, sc.K, throw=False)
            return run(observer, stream, throw=False)
        if method == "dlt" and self.robust:
            keys = jax.random.split(jax.random.key(0), pixels.shape[0])

            def one(key, p):
                fit = find_homography_robust(
                    key, reference, p, iterations=ROBUST_ITERATIONS,
                    threshold_px=ROBUST_THRESHOLD_PX, throw=False,
                )  # fmt: skip
                return fit.H, fit.result

            G, results = jax.vmap(one)(keys, pixels)
            G = jnp.where((results == RESULTS.successful)[:, None, None], G, jnp.nan)
            result = _first_failure_over(results)
        elif method == "dlt":

            def one(p):
                rec = euclidean_reconstruction(reference[:4], p[:4], sc.K, throw=False)
                return rec.G_n, rec.result

            G, results = jax.vmap(one)(pixels)
            # a failed frame's homography is NaN, never the reconstruction's placeholder
            G = jnp.where((results == RESULTS.successful)[:, None, None], G, jnp.nan)
            result = _first_failure_over(results)
        elif method == "ransac":
            G = ransac_homographies(reference, pixels, threshold_px=params["ransac_px"])
            ok = jnp.all(jnp.isfinite(G))
            result = RESULTS.where(ok, RESULTS.successful, RESULTS.degenerate_points)
        else:
            raise ValueError(f"unknown method {method!r}; choose {self.methods}.")
        H = jax.vmap(_to_observer_convention, in_axes=(0, None))(G, sc.K)
        return FrameHomographies(ts=sc.ts, H=H, result=result)

    def truth_outputs(self, method, solution):
        """`H`: the true homography at the solution's times (the scene's samples)."""
        outputs = getattr(solution, "outputs", solution)  # a baseline's: its own fields
        if not hasattr(outputs, "H") or outputs.H.shape != self.scene.H.shape:
            return {}
        return {"H": self.scene.H}

    def metrics(self, method, solution):
        H = solution.outputs.H if method in ("estimator", "gyro") else solution.H
        err = homography_error(H, self.scene.H)
        half = err[err.shape[0] // 2 :]
        return {"error": jnp.sqrt(jnp.mean(half**2)), "final_error": err[-1]}

    def innovation(self, method, params, solution, inputs):
        """The observers' output error over the second half: each current bearing $p_i$
        against the one the estimate predicts from the reference, $\\hat H^{-1}\\mathring
        p_i$ normalized, against the noise the bearings imply (`estimators.innovation`);
        `None` for the per-frame fits."""

        if method not in ("estimator", "gyro"):
            return None
        sc = self.scene
        p = unit_bearings(inputs["pixels"], sc.K)
        p_ref = unit_bearings(inputs["reference"], sc.K)
        predicted = jax.vmap(lambda H: homography_bearings(jnp.linalg.inv(H), p_ref))(
            solution.outputs.H
        )
        n = sc.ts.shape[0]
        y = p.reshape(n, -1)
        return innovation(y, y - predicted.reshape(n, -1), jnp.arange(n) >= n // 2)

    def trivial(self):
        """The metrics of the identity held (the observer's start: the reference image's
        homography), scored as every method is."""
        H = jnp.broadcast_to(jnp.eye(3, dtype=self.scene.H.dtype), self.scene.H.shape)
        return self.metrics("dlt", _Homographies(H))

    def figure(self, method, solution):
        import matplotlib.pyplot as plt

        H = solution.outputs.H if method in ("estimator", "gyro") else solution.H
        err = np.asarray(homography_error(H, self.scene.H))
        fig, ax = plt.subplots(figsize=(6, 3.5))
        ax.semilogy(np.asarray(self.scene.ts), err, lw=0.8)
        ax.set_xlabel("time [s]")
        ax.set_ylabel(r"$\|\hat H H^{-1} - I\|_F$ [-]")
        title = f"{self.title}: {method}, {number_text(self.noise_px)} px"
        ax.set_title(textwrap.fill(title, 60))  # 12 pt: about 10 characters an inch
        fig.tight_layout()
        return fig


class _Homographies(eqx.Module):
    H: jax.Array  # (N, 3, 3): what `HomographyProblem.metrics` reads of a per-frame method


def _first_failure_over(results):
    """The first failure over a batch of result codes (leading axis), or success."""
    bad = results != RESULTS.successful
    first = jax.tree_util.tree_map(lambda v: v[jnp.argmax(bad)], results)
    return RESULTS.where(jnp.any(bad), first, RESULTS.successful)


@final
class VelocityFrontEndProblem(AbstractProblem):
    """The velocity problem of Chitrakaran et al. (`visjax.papers.velocity_problem`, its
    scene, noise draws, gains and window) with two front ends for the velocity estimator:
    `four_point`, the homography of the four features solved at each frame (the paper's,
    the velocity problem's `estimator` as it stands), and `observer`, the homography of
    the observer of Hamel et al. fed to the same estimator.

    The observer knows nothing of the object's motion (its measured group velocity is
    zero: the integral term estimates all of it, `k_I`); it starts at the identity, the
    homography of the first frame, which is the reference image. Its homography $\\hat H(t)$
    reaches the velocity estimator as the pixels it predicts, $p_i \\propto K \\hat H^{-1}
    \\mathring p_i$: four points that fit $\\hat H$ exactly, so the estimator's own
    homography is the observer's. Everything else (the reference image, $n^*$, $z_1^*$,
    the decomposition, $J$) is the velocity problem's. Metric: the velocity problem's."""

    methods: ClassVar[tuple] = ("observer", "four_point")
    trivial_label: ClassVar[str] = "zero velocity"
    grid: ClassVar[str] = "k_P=10:400:4,k_I=100:100000:4"
    defaults_label: ClassVar[str] = "defaults"  # visjax's own gains, not a paper's

    base: Any  # the velocity problem (`VelocityProblem`)

    @property
    def metric(self):
        return self.base.metric

    @property
    def label(self):
        return self.base.label

    @property
    def columns(self):
        return self.base.columns

    @property
    def units(self):
        return self.base.units

    @property
    def title(self):
        return f"{self.base.title}; homography front ends (Hamel et al.)"

    def parameters(self):
        return {
            **self.base.parameters(),
            "k_P": Parameter(100.0, "1/s", True, "the observer's innovation gain"),
            "k_I": Parameter(1e4, "1/s^2", True, "the observer's integral gain"),
        }

    @property
    def data_parameters(self):
        return self.base.data_parameters

    @property
    def noise_px(self):
        """The velocity problem's noise level (a data parameter)."""
        return self.base.noise_px

    def at(self, params):
        """The velocity problem's data parameters (its noise level) set (`at`)."""
        return eqx.tree_at(lambda p: p.base, self, self.base.at(params))

    def settings(self):
        return {**self.base.settings(), "observer_group_velocity": "none measured (k_I)"}

    def inputs(self, key):
        return self.base.inputs(key)

    def observed_pixels(self, params, inputs):
        """The pixels of the observer's homography, $p_i \\propto K \\hat H^{-1}
        \\mathring p_i$ (N, n, 2), and the observer's run."""
        pixels = inputs["pixels"]
        K = self.base.A
        p_ref = unit_bearings(self.base.camera(inputs).p_ref, K)
        observer = HomographyEstimator(k_P=params["k_P"], p_ref=p_ref, k_I=params["k_I"])
        zero = jnp.zeros((pixels.shape[0], 3, 3), pixels.dtype)
        stream = homography_stream(self.base.ts, pixels, zero, K, throw=False)
        sol = run(observer, stream, saveat=SaveAt(outputs=True), throw=False)
        q = jnp.einsum("kij,nj->kni", jnp.linalg.inv(sol.outputs.H), p_ref)
        predicted = ((q / q[..., 2:]) @ K.T)[..., :2]
        # from a failed front end's failure on, NaN pixels: the velocity run stops there
        failed = (sol.result != RESULTS.successful) & (
            jnp.arange(pixels.shape[0], dtype=sol.failed_sample.dtype)
            >= jnp.maximum(sol.failed_sample, 0)
        )
        return jnp.where(failed[:, None, None], jnp.nan, predicted), sol

    def solve(self, method, params, inputs, *, outputs=False):
        if method == "four_point":
            return self.base.solve("estimator", params, inputs, outputs=outputs)
        if method != "observer":
            raise ValueError(f"unknown method {method!r}; choose {self.methods}.")
        predicted, front = self.observed_pixels(params, inputs)
        sol = self.base.solve("estimator", params, {"pixels": predicted}, outputs=outputs)
        # a failed front end fails the run (its pixels are NaN from there)
        result = RESULTS.where(front.result == RESULTS.successful, sol.result, front.result)
        return eqx.tree_at(lambda s: s.result, sol, result)

    def metrics(self, method, solution):
        return self.base.metrics("estimator", solution)

    def trivial(self):
        """The velocity problem's: zero velocity."""
        return self.base.trivial()

    def figure(self, method, solution):
        return self.base.figure("estimator", solution)


def homography_problem(
    *,
    noise_px: float = 0.0,
    duration: float | None = None,
    rate_hz: float = 1000.0,
    variant: str | None = None,
    robust: bool = False,
) -> HomographyProblem | VelocityFrontEndProblem:
    """The `homography` problem: `variant` (`--set`) `"tracking"` (default;
    `HomographyProblem` on `homography_scene(duration, rate_hz)`, 2 s by default) or
    `"velocity_front_end"` (`VelocityFrontEndProblem` on the velocity problem of
    Chitrakaran et al., its section-6 simulation, 10 s by default), with `noise_px` of
    Gaussian pixel noise per draw. `robust` (tracking only): the `dlt` baseline robust to
    outlier points (`HomographyProblem`)."""
    if not (np.isfinite(noise_px) and noise_px >= 0):
        raise ValueError(f"`noise_px` must be finite and non-negative; got {noise_px!r}.")
    variant = variant or "tracking"
    if variant == "tracking":
        scene = homography_scene(2.0 if duration is None else duration, rate_hz)
        return HomographyProblem(
            scene=scene, noise_px=jnp.asarray(float(noise_px)), robust=bool(robust)
        )
    if robust:
        raise ValueError('--robust applies to the variant "tracking" only')
    if variant == "velocity_front_end":
        base = velocity_problem(
            noise_px=noise_px, duration=10.0 if duration is None else duration, rate_hz=rate_hz
        )
        return VelocityFrontEndProblem(base=base)
    raise ValueError(f'the variant must be "tracking" or "velocity_front_end"; got {variant!r}.')
