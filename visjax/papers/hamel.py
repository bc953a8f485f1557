"""The homography observer on SL(3) from direct point correspondences.

T. Hamel, R. Mahony, J. Trumpf, P. Morin, M.-D. Hua, *Homography estimation on the Special
Linear group based on direct point correspondence*, IEEE CDC-ECC 2011.

Built on visjax's public contract only (`visjax.estimators.AbstractJumpEstimator`,
`Stream`, `checked_samples`; `visjax.geometry`'s SL(3) functions), as a user's estimator
would be (`docs/extending.md`).

**The model.** The homography $H \\in SL(3)$ maps the current image to the reference one,
$\\mathring p_i \\propto H p_i$ for the bearing directions $p_i$ (current) and
$\\mathring p_i$ (reference, unit vectors) of points of a plane, and evolves as
$\\dot H = H A$ with the group velocity $A \\in \\mathfrak{sl}(3)$, here known.

**The observer** (the case of a known group velocity), with gain $k_P > 0$:
$e_i = \\hat H p_i / |\\hat H p_i|$,
$\\Delta = \\sum_i (I - e_i e_i^T)\\, \\mathring p_i\\, e_i^T$,
$\\dot{\\hat H} = \\hat H A + k_P \\Delta \\hat H$. No homography is computed per frame: the
innovation $\\Delta$ is built from the correspondences directly.

Why it converges (derived here, and what the tests check): the error $E = \\hat H H^{-1}$
obeys $\\dot E = k_P \\Delta E$ whatever $A$, $e_i = E\\mathring p_i / |E \\mathring p_i|$,
and $f = \\sum_i (1 - e_i^T \\mathring p_i)$ decreases as $\\dot f = -k_P \\|\\Delta\\|^2$;
$\\mathrm{tr}\\,\\Delta = 0$, so $\\hat H$ stays in SL(3). At $\\hat H = H$, $e_i =
\\mathring p_i$ and $\\Delta = 0$: the truth is kept. With four or more points, no three
collinear, $\\Delta = 0$ only at $E = I$ near the identity.

**A partly known group velocity** (the paper's observer with the camera's angular velocity
measured, and the rest of the group velocity estimated): with $A = A_m + \\Gamma$, $A_m$
measured (e.g. $[\\Omega]_\\times$, or zero) and $\\Gamma$ unknown and constant,
$\\dot{\\hat H} = \\hat H (A_m + \\hat\\Gamma) + k_P \\Delta \\hat H$,
$\\dot{\\hat\\Gamma} = k_I\\, \\mathrm{Ad}_{\\hat H^T} \\Delta = k_I \\hat H^T \\Delta
\\hat H^{-T}$. Derived here: now $\\dot E = (k_P \\Delta - \\hat H \\tilde\\Gamma \\hat H^{-1}) E$
with $\\tilde\\Gamma = \\Gamma - \\hat\\Gamma$, so with
$\\mathcal{L} = f + \\|\\tilde\\Gamma\\|^2 / (2 k_I)$,
$\\dot{\\mathcal{L}} = -k_P\\|\\Delta\\|^2$
$+ \\langle \\hat H^T \\Delta \\hat H^{-T} - \\dot{\\hat\\Gamma} / k_I,
\\tilde\\Gamma\\rangle = -k_P \\|\\Delta\\|^2$; $\\mathrm{Ad}_{\\hat H^T}\\Delta$ is trace-free, so
$\\hat\\Gamma$ stays in $\\mathfrak{sl}(3)$. For a camera with angular velocity $\\Omega$
and linear velocity $V$ (its own frame) before a plane of normal $n$ at distance $d$,
$A = [\\Omega]_\\times + V n^T / d - (n^T V / (3d)) I$: the unknown part is
$\\Gamma = V n^T/d - (n^T V/(3d)) I$, constant when $V / d$ and $n$ are.

The runner integrates $\\hat H$ in the ambient $\\mathbb{R}^{3\\times 3}$; at each new sample
the estimate is brought back to its unit-determinant representative (`jump`,
`visjax.geometry.sl3_normalize`), so the saved estimates have det 1 to round-off.

Equation numbers: the paper's text was not available to this transcription; the observer
is cited by name and its properties derived above and tested.
"""

import functools
from typing import Any, ClassVar, final

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .._results import RESULTS
from .._util import number_text, renamed
from ..estimators import (
    AbstractJumpEstimator,
    SaveAt,
    Stream,
    checked_samples,
    innovation,
    reject_mask,
    rejected_samples,
    run,
)
from ..geometry import (
    euclidean_reconstruction,
    find_homography_robust,
    pixel_to_normalized,
    skew,
    sl3_normalize,
    so3_exp,
)
from ..io import Outputs
from ..plots import plot_comparison
from ..sim import sample_times
from ..studies import (
    AbstractProblem,
    Parameter,
    Study,
    compare,
    noise_parameter,
    reproduction_row,
)
from ._reproduction import Reproduction, write_report
from .chitrakaran import velocity_problem


class HomographyMeasurement(eqx.Module):
    """One sample: `p` (n, 3) the unit bearing directions of the points in the current
    image; `A` (3, 3) the group velocity ($\\dot H = H A$, trace-free)."""

    p: Float[Array, "*batch n 3"]
    A: Float[Array, "*batch 3 3"]


class HomographyState(eqx.Module):
    """`H` (3, 3): the estimate of the homography (current to reference); `Gamma` (3, 3):
    the estimate of the unknown part of the group velocity (zero and constant with
    `k_I = 0`)."""

    H: Float[Array, "*batch 3 3"]
    Gamma: Float[Array, "*batch 3 3"]


class HomographyOutput(eqx.Module):
    """`H` (3, 3) the estimate in SL(3); `A` (3, 3) the group velocity it integrates (the
    measured part plus the estimate $\\hat\\Gamma$); `cost` the correspondence misfit
    $\\sum_i (1 - e_i^T \\mathring p_i)$ (0 at the truth)."""

    H: Float[Array, "*batch 3 3"]
    A: Float[Array, "*batch 3 3"]
    cost: Float[Array, "*batch"]


def _bearings(H, p):
    q = p @ H.T
    return q / jnp.linalg.norm(q, axis=-1, keepdims=True)


def homography_innovation(
    H_hat: Float[ArrayLike, "3 3"], p: Float[ArrayLike, "n 3"], p_ref: Float[ArrayLike, "n 3"]
) -> Float[Array, "3 3"]:
    """The innovation $\\Delta = \\sum_i (I - e_i e_i^T)\\, \\mathring p_i\\, e_i^T$ with
    $e_i = \\hat H p_i / |\\hat H p_i|$ (module docstring): trace-free, zero at
    $\\hat H = H$. `p` (n, 3) current directions, `p_ref` (n, 3) reference unit directions."""
    H_hat, p, p_ref = (jnp.asarray(a) for a in (H_hat, p, p_ref))
    e = _bearings(H_hat, p)
    proj = p_ref - e * jnp.sum(e * p_ref, axis=-1, keepdims=True)  # (I - e e^T) p_ref
    return jnp.einsum("ni,nj->ij", proj, e)


class HomographyEstimator(AbstractJumpEstimator):
    """The observer of Hamel et al. (module docstring): `k_P` the gain of the innovation
    (1/s), `p_ref` (n, 3) the reference unit directions (n >= 4), `H0` (3, 3) the initial
    estimate (default the identity; brought to SL(3)), `k_I` the gain of the integral term
    (1/s; default 0: the group velocity is measured whole).

    The stream's `A` is the measured part of the group velocity: all of it (`k_I = 0`), the
    camera's angular velocity $[\\Omega]_\\times$ only (the rest estimated by the integral
    term), or zero (all of it estimated)."""

    k_P: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    p_ref: Float[Array, "n 3"] = eqx.field(converter=jnp.asarray)
    H0: Float[Array, "3 3"] = eqx.field(
        converter=jnp.asarray, default=((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    )
    k_I: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.0)

    def __check_init__(self):
        if self.p_ref.ndim != 2 or self.p_ref.shape[-1] != 3 or self.p_ref.shape[0] < 4:
            raise ValueError(
                f"`p_ref` must be (n, 3) reference directions with n >= 4; got {self.p_ref.shape}."
            )

    def init(self, y0: HomographyMeasurement) -> HomographyState:
        H = sl3_normalize(self.H0).astype(y0.p.dtype)
        return HomographyState(H=H, Gamma=jnp.zeros_like(H))

    def vector_field(self, t, state: HomographyState, y: HomographyMeasurement):
        delta = homography_innovation(state.H, y.p, self.p_ref)
        # dH/dt = H (A + Gamma) + k_P Delta H; dGamma/dt = k_I Ad_{H^T} Delta = k_I H^T
        # Delta H^-T (module docstring: the integral term)
        H = state.H
        gamma_dot = self.k_I * H.T @ jnp.linalg.solve(H, delta.T).T
        return HomographyState(H=H @ (y.A + state.Gamma) + self.k_P * delta @ H, Gamma=gamma_dot)

    def jump(self, state: HomographyState, y: HomographyMeasurement) -> HomographyState:
        return HomographyState(H=sl3_normalize(state.H), Gamma=state.Gamma)

    def output(self, t, state: HomographyState, y: HomographyMeasurement) -> HomographyOutput:
        e = _bearings(state.H, y.p)
        cost = jnp.sum(1.0 - jnp.sum(e * self.p_ref, axis=-1))
        return HomographyOutput(H=state.H, A=y.A + state.Gamma, cost=cost)

    def valid(self, state: HomographyState, y: HomographyMeasurement) -> Bool[Array, ""]:
        # an invertible estimate (det 1 after each jump; far from 0 between them) that maps
        # every current direction to within 90 degrees of its reference direction: beyond,
        # a point would be sent behind the reference camera (RESULTS.diverged)
        e = _bearings(state.H, y.p)
        ahead = jnp.all(jnp.sum(e * self.p_ref, axis=-1) > 0)
        return (jnp.abs(jnp.linalg.det(state.H)) > 1e-6) & ahead

    def max_stable_dt(self, y: HomographyMeasurement):
        """Euler on the linearised error. Near $E = \\hat H H^{-1} = I + \\varepsilon$,
        $\\Delta \\approx -L\\varepsilon$ with $L\\varepsilon = \\sum_i \\Pi_i\\, \\varepsilon\\,
        \\mathring p_i \\mathring p_i^T$ ($\\Pi_i = I - \\mathring p_i \\mathring p_i^T$), a
        symmetric positive semi-definite map of eigenvalues $\\mu \\in [0, n]$; then
        $\\dot\\varepsilon = -k_P L\\varepsilon - \\tilde\\Gamma$,
        $\\dot{\\tilde\\Gamma} = k_I L \\varepsilon$: per mode
        $\\lambda^2 + k_P\\mu\\lambda + k_I\\mu = 0$. Euler is stable for real roots when
        $\\Delta t < 2/(k_P n)$ and for complex ones when $\\Delta t < k_P / k_I$ (from
        $|1 + \\lambda\\Delta t| < 1$, whatever $\\mu$): the smaller bound. A longer step is
        refused (`RESULTS.unstable_step`), never integrated into garbage."""
        bound = 2.0 / (self.k_P * self.p_ref.shape[0])
        return jnp.where(self.k_I > 0, jnp.minimum(bound, self.k_P / self.k_I), bound)

    def checks(self):
        d = jnp.linalg.det(self.H0)
        return (
            (self.k_P > 0, "`k_P` must be positive"),
            (self.k_I >= 0, "`k_I` must be non-negative"),
            (jnp.isfinite(d) & (d != 0), "`H0` must be invertible"),
        )


def unit_bearings(pixels: Float[ArrayLike, "... 2"], K: Float[ArrayLike, "3 3"]):
    """Unit bearing directions $m / |m|$, $m = K^{-1} [u, v, 1]^T$, of pixels."""
    m = pixel_to_normalized(pixels, K)
    m = jnp.concatenate([m, jnp.ones_like(m[..., :1])], axis=-1)
    return m / jnp.linalg.norm(m, axis=-1, keepdims=True)


def homography_stream(
    ts: Float[ArrayLike, " N"],
    pixels: Float[ArrayLike, "N n 2"],
    group_velocity: Float[ArrayLike, "N 3 3"],
    K: Float[ArrayLike, "3 3"],
    *,
    reject: Bool[ArrayLike, " N"] | None = None,
    truth=None,
    throw: bool = True,
) -> Stream:
    """The observer's stream from pixel tracks (N, n, 2) of a camera with intrinsics `K`
    and the group velocity (N, 3, 3) at each sample. `reject` (N,) bool: the samples an
    outlier test rejected, held over as dropped ones (`Stream.present`; the first must be
    kept). `throw`: a non-finite sample raises, naming it; with `throw=False` the run
    stops there."""
    ts, pixels, A = (jnp.asarray(a, float) for a in (ts, pixels, group_velocity))
    if pixels.ndim != 3 or pixels.shape[-1] != 2 or pixels.shape[0] != ts.shape[0]:
        raise ValueError(f"`pixels` must have shape (N, n, 2) with N = {ts.shape[0]}.")
    if A.shape != (ts.shape[0], 3, 3):
        raise ValueError(f"`group_velocity` must have shape ({ts.shape[0]}, 3, 3); got {A.shape}.")
    stream = Stream(ts=ts, ys=HomographyMeasurement(p=unit_bearings(pixels, K), A=A), truth=truth)
    stream = rejected_samples(stream, reject_mask(reject, ts.shape[0]))
    return checked_samples(stream, "homography_stream", throw)


# ---------------------------------------------------------------------------------------
# The problem `homography`: a camera moving before a planar target (its own scene, not the
# paper's), the observer against per-frame homographies; and the observer as the front end
# of the velocity problem of Chitrakaran et al.

PLANE_POINTS = (
    (-0.8, -0.6),
    (0.8, -0.6),
    (0.8, 0.6),
    (-0.8, 0.6),
    (0.2, 0.3),
    (-0.4, 0.1),
    (0.5, -0.2),
    (-0.1, -0.4),
)  # (X, Y) on the plane Z = PLANE_DISTANCE of the reference camera; the first four the corners
PLANE_DISTANCE = 2.0  # m, the plane's distance from the reference camera (normal e_3)
START = (0.2, -0.1, -0.3)  # m, the camera's start in the reference camera's frame
START_ROTATION = (0.05, 0.1, -0.02)  # rad, its orientation there (rotation vector)
VELOCITY = (0.1, 0.05, 0.15)  # m/s, constant, reference frame
ANGULAR_VELOCITY = (0.05, -0.1, 0.08)  # rad/s, constant, reference frame
CAMERA = ((600.0, 0.0, 640.0), (0.0, 600.0, 480.0), (0.0, 0.0, 1.0))  # 1280 x 960 px, ~93 deg


def plane_group_velocity(
    omega: Float[ArrayLike, "3"],
    v: Float[ArrayLike, "3"],
    n: Float[ArrayLike, "3"],
    d: Float[ArrayLike, ""],
) -> Float[Array, "3 3"]:
    """The group velocity $A = [\\Omega]_\\times + V n^T / d - (n^T V / (3d)) I$ of the
    homography of a plane (unit normal `n`, distance `d`, in the current camera frame)
    seen by a camera with angular velocity `omega` and linear velocity `v` (its own frame):
    $\\dot H = H A$ (module docstring; the tests check it against $H^{-1}\\dot H$)."""
    omega, v, n, d = (jnp.asarray(a) for a in (omega, v, n, d))
    nv = jnp.dot(n, v) / (3.0 * d)
    return skew(omega) + jnp.outer(v, n) / d - nv * jnp.eye(3, dtype=v.dtype)


class HomographyScene(eqx.Module):
    """The scene of `homography_scene`: `ts` (N,), `pixels` (N, n, 2) the current image,
    `reference` (n, 2) the reference image, `H` (N, 3, 3) the true homography in SL(3)
    (current to reference, $\\mathring p_i \\propto H p_i$), `A` (N, 3, 3) the true group
    velocity, `omega` (N, 3) the camera's angular velocity in its own frame, `K` (3, 3)."""

    ts: Float[Array, " N"]
    pixels: Float[Array, "N n 2"]
    reference: Float[Array, "n 2"]
    H: Float[Array, "N 3 3"]
    A: Float[Array, "N 3 3"]
    omega: Float[Array, "N 3"]
    K: Float[Array, "3 3"]


def homography_scene(duration: float = 2.0, rate_hz: float = 1000.0) -> HomographyScene:
    """A camera moving with a constant twist (`VELOCITY`, `ANGULAR_VELOCITY`) from
    `START` before the planar target `PLANE_POINTS` (eight points on the plane at
    `PLANE_DISTANCE` of the reference camera), `duration` s at `rate_hz`, in closed form:
    the pose $R(t) = \\exp(t[\\omega]_\\times) R_0$, $\\xi(t) = \\xi_0 + t v$ in the reference
    frame; a point $X$ of the reference frame is $R^T(X - \\xi)$ in the current one; the
    homography $H \\propto (I + \\xi n^T / (d - n^T\\xi))\\, R$ brought to SL(3)."""

    ts = sample_times(duration, rate_hz)
    K = jnp.asarray(CAMERA)
    n0 = jnp.array([0.0, 0.0, 1.0])
    XY = jnp.asarray(PLANE_POINTS)
    X_ref = jnp.concatenate([XY, jnp.full((XY.shape[0], 1), PLANE_DISTANCE)], axis=1)
    R0 = so3_exp(jnp.asarray(START_ROTATION))
    v, w = jnp.asarray(VELOCITY), jnp.asarray(ANGULAR_VELOCITY)

    def frame(t):
        R = so3_exp(t * w) @ R0
        xi = jnp.asarray(START) + t * v
        d = PLANE_DISTANCE - n0 @ xi  # the current camera's distance to the plane
        X = (X_ref - xi[None, :]) @ R  # R^T (X - xi), row by row
        H = sl3_normalize((jnp.eye(3) + jnp.outer(xi, n0) / d) @ R)
        A = plane_group_velocity(R.T @ w, R.T @ v, R.T @ n0, d)
        return X, H, A, R.T @ w

    X, H, A, omega = jax.vmap(frame)(ts)
    m = X / X[..., 2:]
    pixels = (m @ K.T)[..., :2]
    reference = ((X_ref / X_ref[:, 2:]) @ K.T)[:, :2]
    return HomographyScene(ts, pixels, reference, H, A, omega, K)


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


def _ransac_host(reference, pixels, threshold):
    import cv2

    reference = np.asarray(reference, np.float64)
    out = np.full(pixels.shape[:-2] + (3, 3), np.nan)
    flat = np.asarray(pixels, np.float64).reshape((-1,) + pixels.shape[-2:])
    ref = np.broadcast_to(reference, pixels.shape[:-3] + reference.shape[-2:]).reshape(
        (-1,) + reference.shape[-2:]
    )
    frames = pixels.shape[-3]
    res = out.reshape((-1, 3, 3))
    for k in range(flat.shape[0]):
        G, _ = cv2.findHomography(ref[k // frames], flat[k], cv2.RANSAC, float(threshold))
        if G is not None:
            res[k] = G
    return res.reshape(out.shape)


def ransac_homographies(
    reference: Float[ArrayLike, "n 2"],
    pixels: Float[ArrayLike, "N n 2"],
    *,
    threshold_px: float = 3.0,
) -> Float[Array, "N 3 3"]:
    """OpenCV's `cv2.findHomography(reference, pixels[k], cv2.RANSAC, threshold_px)` at each
    frame, through `jax.pure_callback` (so it runs under `jit` and `vmap`, one frame after
    another on the host; not differentiable): the projective homographies $G_k$,
    $p \\sim G_k \\mathring p$ (N, 3, 3), NaN where OpenCV found none."""
    reference, pixels = jnp.asarray(reference), jnp.asarray(pixels)
    shape = jax.ShapeDtypeStruct(pixels.shape[:-2] + (3, 3), pixels.dtype)
    return jax.pure_callback(
        _ransac_host, shape, reference, pixels, threshold_px, vmap_method="expand_dims"
    )


ROBUST_ITERATIONS = 200  # RANSAC hypotheses per frame of the robust `dlt` (8 points)
ROBUST_THRESHOLD_PX = 3.0  # its inlier threshold, as the OpenCV `ransac` baseline's


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
    RANSAC on all eight points (`ransac`, 3 px threshold). Each draw adds `noise_px`
    of Gaussian noise to the current and to the reference pixels. The observer starts at
    the identity (the truth is 0.3 away).

    Metrics: `error`, the RMS over the second half of $\\|\\hat H H^{-1} - I\\|_F$
    (`homography_error`); `final_error`, that error at the last sample."""

    methods: ClassVar[tuple] = ("estimator", "gyro", "dlt", "ransac")
    metric: ClassVar[str] = "error"
    label: ClassVar[str] = "RMS of |H_hat H^-1 - I| over the second half (-)"
    trivial_label: ClassVar[str] = "the identity (the reference image's homography)"
    grid: ClassVar[str] = "k_P=3:200:5"
    title: ClassVar[str] = "homography of a planar target (Hamel et al.)"
    defaults_label: ClassVar[str] = "defaults"  # visjax's own gains, not a paper's

    data_parameters: ClassVar[tuple[str, ...]] = ("noise_px",)

    scene: HomographyScene
    noise_px: Any = 0.0  # a data parameter (`at`); the builder makes it an array
    robust: bool = eqx.field(static=True, default=False)

    def parameters(self):
        return {
            "k_P": Parameter(30.0, "1/s", True, "the gain of the innovation"),
            "k_I": Parameter(10.0, "1/s^2", False, "the integral gain (method gyro)"),
            "noise_px": noise_parameter(self.noise_px),
        }

    def settings(self):
        return {
            "noise_px": float(self.noise_px),
            "samples": int(self.scene.ts.shape[0]),
            "points": int(self.scene.reference.shape[0]),
            "ransac_threshold_px": 3.0,
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
            G = ransac_homographies(reference, pixels)
            ok = jnp.all(jnp.isfinite(G))
            result = RESULTS.where(ok, RESULTS.successful, RESULTS.degenerate_points)
        else:
            raise ValueError(f"unknown method {method!r}; choose {self.methods}.")
        H = jax.vmap(_to_observer_convention, in_axes=(0, None))(G, sc.K)
        return FrameHomographies(ts=sc.ts, H=H, result=result)

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
        predicted = jax.vmap(lambda H: _bearings(jnp.linalg.inv(H), p_ref))(solution.outputs.H)
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
        ax.set_xlabel("t (s)")
        ax.set_ylabel(r"$\|\hat H H^{-1} - I\|_F$")
        ax.set_title(f"{self.title}: {method}, {number_text(self.noise_px)} px")
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


def _records_metric(metric: str):
    """A record's `metric`, NaN where the run gave none (a failed run)."""

    def value(record):
        v = record[metric]
        return float("nan") if v is None else v

    return value


def reproduce_homography(
    out=None,
    *,
    quick: bool = False,
    quiet: bool = False,
    formats=("png",),
    noise: float = 0.1,
    seeds: int | None = None,
    duration: float | None = None,
    seed: int = 0,
) -> list[dict]:
    """The observer as the front end of the velocity problem (the variant
    `velocity_front_end`: Chitrakaran et al.'s estimator fed by the observer's homography
    or by the per-frame four-point one, on the same draws), registered as the reproduction
    `homography`: `studies.compare` over `seeds` noise seeds at `noise` px; `summary.json`
    (kind `homography`), `records.parquet/.csv` and `comparison.<format>` into `out`.
    `seeds`, `duration`: 5 seeds of 10 s (the scoring window 5-10 s), 2 of 4 s with `quick`.
    **Returns:** its rows: each front end's median worst-axis RMS against that of answering
    zero velocity (kind `trivial`)."""
    import pandas as pd

    seeds = (2 if quick else 5) if seeds is None else int(seeds)
    duration = (4.0 if quick else 10.0) if duration is None else float(duration)

    def reproduce(write):
        problem = homography_problem(
            noise_px=noise, duration=duration, variant="velocity_front_end"
        )
        keys = np.arange(seed, seed + seeds)
        records = compare(problem, keys, study=Study(progress=not quiet))
        metric = problem.metric
        trivial = float(problem.trivial()[metric])
        per = {}
        for m in problem.methods:
            mine = [r for r in records if r["method"] == m]
            good = [r[metric] for r in mine if r["result"] == "successful" and r[metric]]
            per[m] = {
                "median": float(np.median(good)) if good else None,
                "failed": sum(r["result"] != "successful" for r in mine),
            }
        if write is not None:
            draw = functools.partial(
                plot_comparison, records, _records_metric(metric), label=problem.label,
                title=problem.title,
            )  # fmt: skip
            write(
                Outputs(
                    tables={"records": pd.DataFrame(records)},
                    csv=("records",),
                    figures={"comparison": draw},
                )
            )
        lines = [f"{problem.title}: {seeds} seed(s); {metric}: {problem.label}"]
        lines.append(f"{'front end':<14}{'failed':>8}{metric + ' (median)':>24}")
        for m, v in per.items():
            value = "-" if v["median"] is None else f"{v['median']:.4g}"
            lines.append(f"{m:<14}{v['failed']:>8}{value:>24}")
        lines.append(f"{'zero velocity':<14}{'':>8}{trivial:>24.4g}")
        body = {
            "noise_px": float(noise),
            "seeds": seeds,
            "duration_s": duration,
            "metric": metric,
            "trivial": trivial,
            "methods": per,
        }
        return Reproduction(body, lines, seed=seed)

    settings = dict(noise=noise, seeds=seeds, duration=duration, seed=seed)
    summary = write_report("homography", settings, out, formats, reproduce)
    return [
        reproduction_row(
            f"Hamel et al., velocity front end ({m}): median worst-axis RMS at {noise:g} px",
            v["median"],
            summary["trivial"],
            "trivial",
            "m/s or rad/s",
        )
        for m, v in summary["methods"].items()
    ]


RENAMED = {"HomographyObserver": "HomographyEstimator"}
"""The names of visjax 0.3 (old -> new): still given, with a `FutureWarning`."""
__getattr__ = renamed("visjax.papers.hamel", RENAMED, globals())
