"""The adaptive least-squares Euclidean structure estimator of Nath et al., section IV.

Source: Nath, Dawson, Tatlicioglu, *Euclidean position estimation of static features using a
moving uncalibrated camera*. Two laws run together: the camera-parameter law (37)-(39) on
the known features, and the structure law (41)-(45) on the unknown ones, which uses the
current camera estimate; the output is the scale-recovered position of every unknown
feature (eqs. (50)-(51)).

Numerics (see the issue note):

- Eqs. (39) and (45) are integrated for the information matrices $\\Gamma_c^{-1}$, $\\Gamma^{-1}$
  (they grow linearly and stay positive definite under Euler steps), and $\\Gamma$ is solved
  for at each step; an Euler step on $\\Gamma$ itself (eq. (46)) turns it indefinite.
- The camera parameters are hundreds of pixels while the regressors hold metres. The law is
  run in normalised coordinates $\\theta_c = D\\varphi$ with a fixed diagonal $D$ (the scale
  of each parameter): eq. (39) and the resetting to $\\eta_0 I_{16}$ apply to $\\varphi$. In
  $\\theta_c$ this is $\\Gamma_c = D\\Gamma_\\varphi D$, the paper's law with a diagonal
  preconditioner.
  `from_nominal` takes the Jacobi scaling of the regressor's columns for $D$.
- `Proj` is the standard continuous projection for the linear constraints
  $\\Pi_{xj}\\hat\\theta_{c2} > \\varepsilon_c$ and $\\hat\\Pi\\hat\\theta_{si} > \\varepsilon_s$:
  when an estimate sits on the boundary and the update points outwards, the update's component
  along the constraint's normal (in the $\\Gamma$ metric) is removed.
- Pixel normalisation: the laws run on $p' = Np$ with a fixed upper-triangular $N$ whose
  last row is $[0, 0, 1]$ (`from_nominal` takes $N = A_{nom}^{-1}$, the inverse of the
  nominal intrinsics). That is the paper's model exactly, for the camera $A' = NA$ (still
  upper triangular, last row $[0, 0, 1]$, as eq. (4)); the pixels then are $O(1)$ and
  centred, as in Hartley's normalisation, and the camera parameters $\\theta_c'$ are close
  to $[R_c^T, -R_c^Tx_c]$. `camera(state)` returns $A = N^{-1}A'$ in pixels.
- Dropouts: a feature whose pixel is NaN at a sample (occluded, out of view) is not
  measured there. `platform_measurements` turns it into a visibility flag (0/1) and a zero
  pixel; both laws multiply that feature's rows of the regressor and prediction error by
  the flag, so it adds nothing to eqs. (37), (39), (41), (45) at that sample and its
  structure estimate is held. A NaN (or infinite) pose, or an infinite pixel, is still a
  non-finite measurement.
"""

from typing import final

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._results import all_finite
from .._util import as_float, check_shape, positive_finite
from ..geometry import (
    camera_from_parameters,
    camera_parameters,
    known_feature_regressors,
    to_homogeneous,
    unknown_feature_regressors,
)
from ._base import AbstractJumpEstimator, Stream, checked_samples, reject_mask


@final
class StaticPointsMeasurement(eqx.Module):
    """One sample for the estimator of Nath et al.: the measured platform pose `R_b`, `x_b`,
    homogeneous pixels of the unknown (`p_s`, (n, 3)) and known (`p_c`, (m, 3)) features,
    the known features' regressors `W_x` (m, 3, 12), `Pi_x` (m, 4) of eq. (12), and the
    visibility flags `visible_s` (n,), `visible_c` (m,): 1 where the feature's pixel was
    measured, 0 where it was missing (NaN; its pixel is then stored as 0)."""

    R_b: Float[Array, "*batch 3 3"]
    x_b: Float[Array, "*batch 3"]
    p_s: Float[Array, "*batch n 3"]
    p_c: Float[Array, "*batch m 3"]
    W_x: Float[Array, "*batch m 3 12"]
    Pi_x: Float[Array, "*batch m 4"]
    visible_s: Float[Array, "*batch n"]
    visible_c: Float[Array, "*batch m"]


def _visible(p):
    """A missing pixel (NaN in either coordinate) as a 0/1 flag and a zero pixel; an
    infinite pixel stays infinite (a bad measurement, not a missing one)."""
    missing = jnp.any(jnp.isnan(p), axis=-1)
    return jnp.where(missing[..., None], 0.0, p), jnp.where(missing, 0.0, 1.0).astype(p.dtype)


@jax.jit
def _known_regressors(R_b, x_b, omega_c):
    """$W_{xj}$, $\\Pi_{xj}$ of eq. (12) for every sample and known feature (compiled once
    per shape, not dispatched operation by operation)."""

    def one(R, x):
        W, Pi = jax.vmap(lambda w: known_feature_regressors(R, x, w))(omega_c)
        return W, Pi[:, 0, :]

    return jax.vmap(one)(R_b, x_b)


def platform_measurements(R_b, x_b, p_s, p_c, omega_c) -> StaticPointsMeasurement:
    """Build the measurements of all samples at once (vmapped before the time loop).

    `R_b` (N, 3, 3), `x_b` (N, 3), pixels `p_s` (N, n, 2) and `p_c` (N, m, 2), known
    feature positions `omega_c` (m, 3). A NaN pixel marks a feature not seen at that sample
    (occluded, out of view): it becomes `visible_* = 0` and a zero pixel, and the laws
    ignore it there (module docstring). A NaN or infinite pose, or an infinite pixel, stays
    non-finite, and `run` reports `nonfinite_measurement` at that sample.
    """
    R_b, x_b, p_s, p_c, omega_c = (as_float(x) for x in (R_b, x_b, p_s, p_c, omega_c))
    if p_s.ndim != 3 or p_c.ndim != 3 or p_s.shape[-1] != 2 or p_c.shape[-1] != 2:
        raise ValueError(
            f"`p_s` and `p_c` must be (N, n, 2) and (N, m, 2); got {p_s.shape}, {p_c.shape}."
        )
    n = p_s.shape[0]
    check_shape(R_b, (n, 3, 3), "R_b")
    check_shape(x_b, (n, 3), "x_b")
    check_shape(p_c, (n, None, 2), "p_c")
    check_shape(omega_c, (None, 3), "omega_c")
    if p_c.shape[1] != omega_c.shape[0]:
        raise ValueError(
            f"`p_c` has {p_c.shape[1]} known features but `omega_c` has {omega_c.shape[0]}."
        )

    W_x, Pi_x = _known_regressors(R_b, x_b, omega_c)
    p_s, visible_s = _visible(p_s)
    p_c, visible_c = _visible(p_c)
    return StaticPointsMeasurement(
        R_b=R_b,
        x_b=x_b,
        p_s=to_homogeneous(p_s),
        p_c=to_homogeneous(p_c),
        W_x=W_x,
        Pi_x=Pi_x,
        visible_s=visible_s,
        visible_c=visible_c,
    )


def static_points_stream(
    ts, R_b, x_b, p_s, p_c, omega_c, *, reject=None, truth=None, throw=True
) -> Stream:
    """The measurement `Stream` of `StaticPointsEstimator` from raw measurements.

    **Arguments:** `ts` (N,) the sample times (any rate; `run(..., dt=...)` holds the
    samples); the measured platform pose `R_b` (N, 3, 3), `x_b` (N, 3) in the world frame;
    the pixels of the unknown (`p_s`, (N, n, 2)) and known (`p_c`, (N, m, 2)) features, NaN
    where a feature was not seen (`platform_measurements`); the known features' world
    positions `omega_c` (m, 3); `truth` for a reducer. `reject`: what an outlier test
    rejected, treated as not seen: (N,) bool whole samples (every feature of that sample),
    or (N, n + m) single features (the unknown ones first, then the known ones, in the
    order of `p_s` and `p_c`). `throw`: a sample that is not finite
    once the features not seen are masked (a NaN or infinite pose, an infinite pixel)
    raises here, naming the sample; with `throw=False` `run` stops there with
    `RESULTS.nonfinite_measurement`.
    """
    ts = as_float(ts)
    check_shape(ts, (None,), "ts")
    if reject is not None:
        p_s, p_c = as_float(p_s), as_float(p_c)
        n, m = p_s.shape[1], p_c.shape[1]
        reject = reject_mask(reject, ts.shape[0], n + m)
        if reject.ndim == 1:
            reject = jnp.broadcast_to(reject[:, None], (ts.shape[0], n + m))
        p_s = jnp.where(reject[:, :n, None], jnp.nan, p_s)
        p_c = jnp.where(reject[:, n:, None], jnp.nan, p_c)
    ys = platform_measurements(R_b, x_b, p_s, p_c, omega_c)
    if ys.p_s.shape[0] != ts.shape[0]:
        raise ValueError(f"`ts` has {ts.shape[0]} samples but the pixels have {ys.p_s.shape[0]}.")
    return checked_samples(Stream(ts=ts, ys=ys, truth=truth), "static_points_stream", throw)


def _ls_step_bound(rate, alpha, depth, amplification=1e3, steps=512):
    """The largest Euler step of a least-squares law whose transient amplification stays
    below `amplification`.

    Along the fastest direction the law is $\\dot{\\tilde\\theta} = -r_k\\tilde\\theta$ with
    $r_k = r_0 / (1 + g k)$: the gain $\\Gamma$ decays as the information $\\Gamma^{-1}$ grows
    by $2hW^TW$ per step (eqs. (39), (45)), $g = 2 h r_0 \\bar z / \\alpha$ ($\\bar z$ the mean
    predicted depth). A step above the plain bound $2/r_0$ therefore only amplifies the
    error for the first steps after a start or a reset, by $\\prod_k \\max(1, |1 - h r_k|)$;
    with $\\alpha_c = 100$ at 1 ms that is about 40, with $\\alpha_c = 300$ about 1e20. The
    bound is the largest step, on a log grid from 1 us to 1 s, below `amplification`.
    """
    h = jnp.logspace(-6.0, 0.0, 241, dtype=jnp.result_type(rate))
    g = 2.0 * h * rate * depth / alpha

    def r(k):
        return rate / (1.0 + g * k)

    def add(k, log_growth):  # a loop over k: memory O(len(h)), also under a large vmap
        step = jnp.log(jnp.maximum(1.0, jnp.abs(1.0 - h * r(k.astype(h.dtype)))))
        return log_growth + step

    log_growth = jax.lax.fori_loop(0, steps, add, jnp.zeros_like(h))
    # still growing after `steps` steps: never settles
    settles = h * r(jnp.asarray(steps - 1, h.dtype)) <= 2.0
    ok = (log_growth <= jnp.log(amplification)) & settles
    return jnp.max(jnp.where(ok, h, 0.0))


def _project(tau, theta, normals, margin, Gamma):
    """Continuous projection of the update `tau` for the constraints `normals @ theta > margin`."""
    for k in range(normals.shape[0]):
        a = normals[k]
        active = (a @ theta <= margin) & (a @ tau < 0.0)
        Ga = Gamma @ a
        tau = jnp.where(active, tau - Ga * (a @ tau) / (a @ Ga), tau)
    return tau


@final
class StaticPointsState(eqx.Module):
    """The state of the two laws: `theta_c` (16,) the camera parameters; `info_c` (16, 16)
    $\\Gamma_\\varphi^{-1}$ (normalised, see the module docstring); `theta_s` (n, 4) the
    structure parameters; `info_s` (n, 4, 4) the diagonal blocks of $\\Gamma^{-1}$ (eq. (45):
    $\\bar W_s$ is block diagonal, eq. (22)); `resets` the number of covariance resets."""

    theta_c: Float[Array, "16"]
    info_c: Float[Array, "16 16"]
    theta_s: Float[Array, "n 4"]
    info_s: Float[Array, "n 4 4"]
    resets: Float[Array, ""]


@final
class StaticPointsOutput(eqx.Module):
    """The unknown features' world positions, scale recovered (eqs. (50)-(51)), and the
    camera recovered from the camera-parameter estimate (the paper's footnote 3): the
    intrinsics `A` (pixels), the mounting `R_c`, `x_c` (eq. (5): a platform-frame point $q$
    is at $R_c^T(q - x_c)$ in the camera frame)."""

    omega_s: Float[Array, "n 3"]
    A: Float[Array, "3 3"]
    R_c: Float[Array, "3 3"]
    x_c: Float[Array, "3"]


@final
class StaticPointsDiagnostics(eqx.Module):
    """Prediction errors (px) of the known (`p_tilde_c`) and unknown (`p_tilde_s`)
    features, NaN where the feature is not seen at that sample; predicted depths
    `depth_s`, `depth_c`; the minimum eigenvalue of $\\Gamma_\\varphi$; the reset count;
    `theta_c` the camera parameters in pixels ($\\theta_{c1}$ of $A$, not of $NA$);
    `info_rate_s` (n, 4, 4), the integrand $\\bar W_{si}^T\\bar W_{si}$ of eq. (49) (zero
    for a feature not seen)."""

    p_tilde_c: Float[Array, " m"]
    p_tilde_s: Float[Array, " n"]
    depth_s: Float[Array, " n"]
    depth_c: Float[Array, " m"]
    lambda_min_gamma_c: Float[Array, ""]
    resets: Float[Array, ""]
    theta_c: Float[Array, "16"]
    info_rate_s: Float[Array, "n 4 4"]


# The scale-derived gains (`StaticPointsEstimator.from_nominal`).
_LS_EXPONENT = 10.0  # alpha / (2 z): the decay exponent of a least-squares direction
_STEP_FRACTION = 1.0  # h * (initial fastest rate): half of Euler's bound 2
_RESET_RATIO = 100.0  # eta0 / eta1 of eq. (39)
_MARGIN_FRACTION = 0.2  # projection margins: this fraction of the nearest known depth
_GAIN_NAMES = ("alpha_c", "alpha", "eta0", "eta1", "gamma_s0", "D", "eps_c", "eps_s")


@final
class StaticPointsEstimator(AbstractJumpEstimator):
    """Nath et al.: camera-parameter law (37)-(39) and structure law (41)-(45), output
    (50)-(51), and the camera recovered from the estimate (footnote 3).

    **Fields:** `alpha_c`, `alpha`: the gains of eqs. (38) and (42) (positive constants
    here: $1 + \\bar\\rho/\\bar\\varepsilon$ with constant bounds); `eta0 > eta1 > 0` of eq. (39);
    `gamma_s0`: the initial structure covariance $\\Gamma(t_0) = \\gamma_{s0} I$; `D` (16,) the
    scale of each camera parameter; `eps_c`, `eps_s`: the projection margins on the
    predicted depths (metres); `theta_c0` (16,), `theta_s0` (n, 4): initial estimates
    ($\\theta_c$ of the normalised camera $NA$); `scale_min`: the scale entries
    $\\hat\\lambda_i$ of eq. (50) must stay above it in magnitude (default 1e-6); `N` (3, 3)
    the pixel normalisation (module docstring; default the identity: the laws run on
    pixels). Build it from nominal values with `from_nominal`.

    Checks (under `jit` and `vmap`): every gain, `D` and the margins positive and finite,
    $\\eta_0 > \\eta_1 > 0$, the initial estimates finite, `N` upper triangular with a
    positive diagonal and last row $[0, 0, 1]$. Valid state: every predicted depth above
    half its projection margin (the projection keeps it above the margin up to one Euler
    step), every scale entry away from zero. Euler stability: near the estimate both laws
    are gradient flows, $\\dot{\\tilde\\theta} \\approx -\\alpha\\Gamma W^T \\Lambda^{-1}
    W\\tilde\\theta$ ($\\Lambda$ the predicted depths), fastest at $\\Gamma_\\varphi = \\eta_0 I$
    and $\\Gamma = \\gamma_{s0} I$, and decaying as information accumulates:
    `max_stable_dt(y)` is the largest step whose transient amplification stays below 1e3
    (`_ls_step_bound`), at the sample `y` and the initial estimates.
    """

    alpha_c: Float[Array, ""] = eqx.field(converter=as_float)
    alpha: Float[Array, ""] = eqx.field(converter=as_float)
    eta0: Float[Array, ""] = eqx.field(converter=as_float)
    eta1: Float[Array, ""] = eqx.field(converter=as_float)
    gamma_s0: Float[Array, ""] = eqx.field(converter=as_float)
    D: Float[Array, "16"] = eqx.field(converter=as_float)
    eps_c: Float[Array, ""] = eqx.field(converter=as_float)
    eps_s: Float[Array, ""] = eqx.field(converter=as_float)
    theta_c0: Float[Array, "16"] = eqx.field(converter=as_float)
    theta_s0: Float[Array, "n 4"] = eqx.field(converter=as_float)
    scale_min: Float[Array, ""] = eqx.field(converter=as_float, default=1e-6)
    N: Float[Array, "3 3"] = eqx.field(converter=as_float, default_factory=lambda: jnp.eye(3))

    def __check_init__(self):
        for name in ("alpha_c", "alpha", "eta0", "eta1", "gamma_s0", "eps_c", "eps_s"):
            if jnp.shape(getattr(self, name)) != ():
                raise ValueError(
                    f"`{name}` must be a scalar; got shape {jnp.shape(getattr(self, name))}."
                )
        if jnp.shape(self.theta_c0) != (16,) or jnp.shape(self.D) != (16,):
            raise ValueError(
                f"`theta_c0` and `D` must have shape (16,); got {jnp.shape(self.theta_c0)} "
                f"and {jnp.shape(self.D)}."
            )
        if jnp.ndim(self.theta_s0) != 2 or jnp.shape(self.theta_s0)[1] != 4:
            raise ValueError(f"`theta_s0` must have shape (n, 4); got {jnp.shape(self.theta_s0)}.")
        if jnp.shape(self.N) != (3, 3):
            raise ValueError(f"`N` must have shape (3, 3); got {jnp.shape(self.N)}.")

    @classmethod
    def from_nominal(
        cls,
        stream: Stream,
        A_nominal: Float[ArrayLike, "3 3"],
        R_c_nominal: Float[ArrayLike, "3 3"],
        x_c_nominal: Float[ArrayLike, "3"],
        *,
        dt: float | None = None,
        depth_guess: float | ArrayLike | None = None,
        omega_s_guess: Float[ArrayLike, "n 3"] | None = None,
        gains: dict | None = None,
    ) -> "StaticPointsEstimator":
        """The estimator from nominal values only: never from the truth.

        **Arguments:**

        - `stream`: the `static_points_stream` it will run on (its first sample fixes the scale
            of the scene; its times the step).
        - `A_nominal`, `R_c_nominal`, `x_c_nominal`: the camera as the user knows it (data
            sheet intrinsics, a mounting measured with a ruler), with the conventions of
            eq. (5). The laws run on pixels normalised by $N = A_{nom}^{-1}$; $\\theta_{c0}$ is
            the nominal camera's (section III).
        - `dt`: the integration step `run` will use (`None`: the largest sample interval).
        - `depth_guess`: the initial depth of every unknown feature (metres; `None`: the
            median depth of the known features at the first sample under the nominal
            camera). Each feature is guessed on its nominal ray at the first sample where it
            is seen, at this depth (on the nominal optical axis if it is never seen).
        - `omega_s_guess`: (n, 3) initial world positions instead of the rays.
        - `gains`: overrides of any of `alpha_c`, `alpha`, `eta0`, `eta1`, `gamma_s0`, `D`,
            `eps_c`, `eps_s` (the others are still derived, from the overridden values).

        **Gains derived from the scene's scale** (at the first sample and the initial
        estimates, $\\bar z$ the median and $z_{min}$ the least depth of the known features,
        $h$ the step):

        - $\\alpha_c = \\alpha = 2k\\bar z$ with $k = 10$: the laws' rate is
            $\\alpha\\Gamma W^T\\Lambda^{-1}W$ (eqs. (37), (41)) while the information grows by
            $2W^TW$ (eqs. (39), (45)), so along a fixed direction the error decays as
            $(1 + 2\\lambda\\gamma t)^{-\\alpha/(2z)}$: $\\alpha/(2z)$ is the dimensionless
            exponent. ($k$ from a sweep of $k \\in \\{1, 3, 5, 10, 33\\}$ of the structure
            law alone, given the true camera, on a first version of the tilted scene of
            `benchmarks/scenes_euclidean.py` (its nominal intrinsics right but for the skew)
            with the step rule at 0.5: the largest errors at 40 s were 4, 0.3, 0.06, 0.006
            and 3.5 mm. Version 1's hand gains on the project's scene had $k = 33$.)
        - `D`: the Jacobi scaling of the regressor $W_c$ of eq. (36), $D_k =
            (\\sum_r W_{c,rk}^2/z_r)^{-1/2}$, divided by its largest entry, so that the
            16 normalised parameters are excited alike (the resetting of eq. (39) is
            triggered by the largest eigenvalue).
        - $\\eta_0 = 1/(h\\,\\alpha_c\\lambda_{max}(D W_c^T\\Lambda^{-1}W_c D))$ and
            $\\gamma_{s0} = 1/(h\\,\\alpha\\max_i\\lambda_{max}(\\bar W_{si}^T\\bar W_{si})/z_i)$:
            the fastest initial rate at half of Euler's bound $2/h$ (on that first version
            of the tilted scene the largest final errors were 2.2, 1.1, 1.0 mm with 0.5,
            1.0, 1.5 in place of 1, and 1.7, 0.9, 0.7 mm on the project's scene after 20
            s); $\\eta_1 = \\eta_0/100$ (1000: no better).
        - $\\varepsilon_c = \\varepsilon_s = 0.2\\,z_{min}$.

        **Returns:** an `StaticPointsEstimator`. `ValueError` for a wrong shape or an
        unknown gain name.
        """
        if not isinstance(stream, Stream) or not isinstance(stream.ys, StaticPointsMeasurement):
            raise ValueError("`stream` must be a Stream of `static_points_stream`.")
        A_nominal, R_c_nominal, x_c_nominal = (
            as_float(x) for x in (A_nominal, R_c_nominal, x_c_nominal)
        )
        check_shape(A_nominal, (3, 3), "A_nominal")
        check_shape(R_c_nominal, (3, 3), "R_c_nominal")
        check_shape(x_c_nominal, (3,), "x_c_nominal")
        gains = dict(gains or {})
        unknown = sorted(set(gains) - set(_GAIN_NAMES))
        if unknown:
            raise ValueError(f"`gains` has unknown names {unknown}; known: {list(_GAIN_NAMES)}.")
        ys = stream.ys
        n = ys.p_s.shape[1]
        if omega_s_guess is not None:
            omega_s_guess = as_float(omega_s_guess)
            check_shape(omega_s_guess, (n, 3), "omega_s_guess")
        if depth_guess is not None:
            depth_guess = as_float(depth_guess)
            if jnp.shape(depth_guess) not in ((), (n,)):
                raise ValueError(
                    f"`depth_guess` must be a scalar or have shape ({n},); got shape "
                    f"{jnp.shape(depth_guess)}."
                )
        if dt is None:
            h = jnp.max(jnp.diff(stream.ts))
        else:
            if not (isinstance(dt, (int, float)) and dt > 0):
                raise ValueError(f"`dt` must be a positive number or None; got {dt!r}.")
            h = jnp.asarray(dt, stream.ts.dtype)

        return _from_nominal(
            cls, stream, A_nominal, R_c_nominal, x_c_nominal, h, depth_guess, omega_s_guess, gains
        )

    def checks(self):
        N = self.N
        upper = (N[1, 0] == 0) & (N[2, 0] == 0) & (N[2, 1] == 0) & (N[2, 2] == 1)
        return (
            (positive_finite(self.alpha_c), "`alpha_c` must be positive (eq. (38))."),
            (positive_finite(self.alpha), "`alpha` must be positive (eq. (42))."),
            (
                (self.eta0 > self.eta1) & positive_finite(self.eta1) & jnp.isfinite(self.eta0),
                "need eta0 > eta1 > 0 (eq. (39)).",
            ),
            (
                positive_finite(self.gamma_s0),
                "`gamma_s0` must be positive: Gamma(t0) > 0 (eq. (45)).",
            ),
            (positive_finite(self.D), "`D`, the scale of each camera parameter, must be positive."),
            (
                positive_finite(self.eps_c) & positive_finite(self.eps_s),
                "the projection margins `eps_c`, `eps_s` must be positive.",
            ),
            (
                jnp.isfinite(self.scale_min) & (self.scale_min >= 0),
                "`scale_min` must be non-negative.",
            ),
            (
                all_finite((self.theta_c0, self.theta_s0)),
                "the initial estimates `theta_c0`, `theta_s0` must be finite.",
            ),
            (
                all_finite(N) & upper & (N[0, 0] > 0) & (N[1, 1] > 0),
                "the pixel normalisation `N` must be finite and upper triangular with a "
                "positive diagonal and last row [0, 0, 1] (an intrinsic matrix of eq. (4)).",
            ),
        )

    def init(self, y0: StaticPointsMeasurement) -> StaticPointsState:
        dtype = y0.p_s.dtype
        n = self.theta_s0.shape[0]
        info_c = jnp.eye(16, dtype=dtype) / self.eta0  # Gamma_phi(t0) = eta0 I
        info_s = jnp.broadcast_to(jnp.eye(4, dtype=dtype) / self.gamma_s0, (n, 4, 4))
        return StaticPointsState(
            theta_c=self.theta_c0,
            info_c=info_c,
            theta_s=self.theta_s0,
            info_s=info_s,
            resets=jnp.zeros((), dtype),
        )

    def _signals(self, state: StaticPointsState, y: StaticPointsMeasurement):
        """Prediction errors and regressors in normalised pixels $Np$; the rows of a feature
        not seen at this sample are zero in `W_c` and both prediction errors."""
        theta_c, theta_s = state.theta_c, state.theta_s
        t1, t2 = theta_c[:12], theta_c[12:]
        vis_c, vis_s = y.visible_c[:, None], y.visible_s[:, None]
        # known features: eqs. (30)-(36)
        depth_c = y.Pi_x @ t2
        p_hat_c = (y.W_x @ t1) / depth_c[:, None]
        p_tilde_c = vis_c * (y.p_c @ self.N.T - p_hat_c)
        Pi_x = -(p_hat_c[:, :, None] * y.Pi_x[:, None, :])  # eq. (33)
        W_c = (vis_c[:, :, None] * jnp.concatenate([y.W_x, Pi_x], axis=-1)).reshape(-1, 16)
        # unknown features: eqs. (15), (20), (22) with the current camera estimate
        W, Pi = unknown_feature_regressors(y.R_b, y.x_b, t1, t2)
        depth_s = theta_s @ Pi[0]
        p_hat_s = (theta_s @ W.T) / depth_s[:, None]
        p_tilde_s = vis_s * (y.p_s @ self.N.T - p_hat_s)
        W_bar = W[None, :, :] - p_hat_s[:, :, None] * Pi[None, :, :]  # blocks of eq. (22)
        return p_tilde_c, W_c, p_tilde_s, W_bar, Pi[0], depth_c, depth_s

    def max_stable_dt(self, y: StaticPointsMeasurement):
        state = self.init(y)
        _, W_c, _, W_bar, _, depth_c, depth_s = self._signals(state, y)
        WD = W_c * self.D[None, :]
        weights = jnp.repeat(1.0 / depth_c, 3)
        rate_c = self.alpha_c * self.eta0 * jnp.linalg.eigvalsh(WD.T @ (WD * weights[:, None]))
        info = jnp.einsum("nki,nkj->nij", W_bar, W_bar) / depth_s[:, None, None]
        rate_s = self.alpha * self.gamma_s0 * jnp.linalg.eigvalsh(info)[:, -1]
        bound_c = _ls_step_bound(rate_c[-1], self.alpha_c, jnp.mean(depth_c))
        bound_s = _ls_step_bound(jnp.max(rate_s), self.alpha, jnp.mean(depth_s))
        return jax.lax.stop_gradient(jnp.minimum(bound_c, bound_s))

    def vector_field(
        self, t, state: StaticPointsState, y: StaticPointsMeasurement
    ) -> StaticPointsState:
        theta_c, info_c, theta_s, info_s = state.theta_c, state.info_c, state.theta_s, state.info_s
        p_tilde_c, W_c, p_tilde_s, W_bar, Pi_hat, _, _ = self._signals(state, y)
        WD = W_c * self.D[None, :]
        Gamma_phi = jnp.linalg.inv(info_c)
        Gamma_c = self.D[:, None] * Gamma_phi * self.D[None, :]
        tau_c = self.alpha_c * Gamma_c @ (W_c.T @ p_tilde_c.reshape(-1))  # eq. (37)
        normals_c = jnp.concatenate([jnp.zeros((y.Pi_x.shape[0], 12), y.Pi_x.dtype), y.Pi_x], 1)
        tau_c = _project(tau_c, theta_c, normals_c, self.eps_c, Gamma_c)
        d_info_c = 2.0 * WD.T @ WD  # eq. (39); an unseen feature's rows are zero
        Gamma_s = jnp.linalg.inv(info_s)
        tau_s = self.alpha * jnp.einsum(
            "nij,nkj,nk->ni", Gamma_s, W_bar, p_tilde_s
        )  # eq. (41), per feature (zero for a feature not seen: its p_tilde_s is zero)
        tau_s = jax.vmap(lambda tau, th, G: _project(tau, th, Pi_hat[None, :], self.eps_s, G))(
            tau_s, theta_s, Gamma_s
        )
        d_info_s = 2.0 * jnp.einsum("nki,nkj->nij", W_bar, W_bar)  # eq. (45)
        d_info_s = y.visible_s[:, None, None] * d_info_s
        return StaticPointsState(
            theta_c=tau_c,
            info_c=d_info_c,
            theta_s=tau_s,
            info_s=d_info_s,
            resets=jnp.zeros_like(state.resets),
        )

    def jump(self, state: StaticPointsState, y) -> StaticPointsState:
        """Covariance resetting of eq. (39): $\\Gamma_\\varphi \\to \\eta_0 I$ when its minimum
        eigenvalue reaches $\\eta_1$ (the largest eigenvalue of `info_c` reaches $1/\\eta_1$)."""
        lam_max = jnp.linalg.eigvalsh(jax.lax.stop_gradient(state.info_c))[-1]
        reset = lam_max >= 1.0 / self.eta1
        info_c = jnp.where(reset, jnp.eye(16, dtype=state.info_c.dtype) / self.eta0, state.info_c)
        return eqx.tree_at(
            lambda s: (s.info_c, s.resets),
            state,
            (info_c, state.resets + reset.astype(state.resets.dtype)),
        )

    def camera(self, state: StaticPointsState):
        """$A$ (pixels), $R_c$, $x_c$ from the camera-parameter estimate (the paper's
        footnote 3, `geometry.camera_from_parameters`): the estimate is of $A' = NA$, so
        $A = N^{-1}A'$. Exact when `state.theta_c` is the truth (at any scale)."""
        A_n, R_c, x_c = camera_from_parameters(state.theta_c[:12])
        return jnp.linalg.solve(self.N, A_n), R_c, x_c

    def output(self, t, state: StaticPointsState, y) -> StaticPointsOutput:
        theta_s = state.theta_s
        lam = theta_s[:, 3]  # eq. (50)
        A, R_c, x_c = self.camera(state)
        return StaticPointsOutput(
            omega_s=theta_s[:, :3] / lam[:, None], A=A, R_c=R_c, x_c=x_c
        )  # (51)

    def diagnostics(self, t, state: StaticPointsState, y) -> StaticPointsDiagnostics:
        p_tilde_c, _, p_tilde_s, W_bar, _, depth_c, depth_s = self._signals(state, y)
        lam = jnp.linalg.eigvalsh(jax.lax.stop_gradient(state.info_c))[-1]
        N_inv = jnp.linalg.inv(self.N)

        def pixels(p_tilde, visible):  # back to pixels: N^{-1} (N p - p_hat)
            err = jnp.linalg.norm((p_tilde @ N_inv.T)[:, :2], axis=-1)
            return jnp.where(visible > 0, err, jnp.nan)

        t1 = state.theta_c[:12]
        t1 = jnp.concatenate([(N_inv @ t1[:9].reshape(3, 3)).reshape(9), N_inv @ t1[9:]])
        return StaticPointsDiagnostics(
            p_tilde_c=pixels(p_tilde_c, y.visible_c),
            p_tilde_s=pixels(p_tilde_s, y.visible_s),
            depth_s=depth_s,
            depth_c=depth_c,
            lambda_min_gamma_c=1.0 / lam,
            resets=state.resets,
            theta_c=jnp.concatenate([t1, state.theta_c[12:]]),
            info_rate_s=y.visible_s[:, None, None]
            * jnp.einsum("nki,nkj->nij", W_bar, W_bar),  # integrand of (49)
        )

    def valid(self, state: StaticPointsState, y: StaticPointsMeasurement):
        depth_c = y.Pi_x @ state.theta_c[12:]
        _, Pi = unknown_feature_regressors(y.R_b, y.x_b, state.theta_c[:12], state.theta_c[12:])
        depth_s = state.theta_s @ Pi[0]
        return (
            jnp.all(depth_c > 0.5 * self.eps_c)
            & jnp.all(depth_s > 0.5 * self.eps_s)
            & jnp.all(jnp.abs(state.theta_s[:, 3]) > self.scale_min)
        )


@eqx.filter_jit
def _from_nominal(
    cls, stream, A_nominal, R_c_nominal, x_c_nominal, h, depth_guess, omega_s_guess, gains
):
    """The numerical part of `StaticPointsEstimator.from_nominal` (arguments checked
    there), compiled once per shape instead of dispatched operation by operation."""
    ys = stream.ys
    n = ys.p_s.shape[1]
    N = jnp.linalg.inv(A_nominal)
    t1, t2 = camera_parameters(jnp.eye(3, dtype=N.dtype), R_c_nominal, x_c_nominal)
    theta_c0 = jnp.concatenate([t1, t2])  # the nominal camera, normalised (A' = N A = I)
    y0 = jax.tree_util.tree_map(lambda x: x[0], ys)
    depth_c0 = y0.Pi_x @ t2  # eq. (12): the known features' depths, nominal camera
    if depth_guess is None:
        depth_guess = jnp.median(depth_c0)
    if omega_s_guess is None:
        # each feature on its nominal ray, at the first sample where it is seen
        k = jnp.argmax(ys.visible_s > 0, axis=0)
        seen = jnp.any(ys.visible_s > 0, axis=0)
        ray = jnp.einsum("ij,nj->ni", N, ys.p_s[k, jnp.arange(n)])
        axis = jnp.broadcast_to(jnp.array([0.0, 0.0, 1.0], ray.dtype), ray.shape)
        ray = jnp.where(seen[:, None], ray, axis)
        q = x_c_nominal[None, :] + (jnp.reshape(depth_guess, (-1, 1)) * ray) @ R_c_nominal.T
        omega_s_guess = ys.x_b[k] + jnp.einsum("nij,nj->ni", ys.R_b[k], q)
    theta_s0 = jnp.concatenate([omega_s_guess, jnp.ones((n, 1), omega_s_guess.dtype)], 1)

    alpha_c = as_float(gains.get("alpha_c", 2.0 * _LS_EXPONENT * jnp.median(depth_c0)))
    alpha = as_float(gains.get("alpha", 2.0 * _LS_EXPONENT * jnp.median(depth_c0)))
    ones = jnp.ones((16,), theta_c0.dtype)
    probe = cls(
        alpha_c=alpha_c, alpha=alpha, eta0=1.0, eta1=0.5, gamma_s0=1.0, D=ones,
        eps_c=1.0, eps_s=1.0, theta_c0=theta_c0, theta_s0=theta_s0, N=N,
    )  # fmt: skip
    _, W_c, _, W_bar, _, depth_c, depth_s = probe._signals(probe.init(y0), y0)
    weights = jnp.repeat(1.0 / depth_c, 3)
    if "D" in gains:
        D = as_float(gains["D"])
    else:
        col = jnp.sqrt(jnp.sum(W_c**2 * weights[:, None], axis=0))
        col = jnp.maximum(col, 1e-9 * jnp.max(col))  # a column never excited at t0
        D = jnp.min(col) / col
    WD = W_c * D[None, :]
    lam_c = jnp.linalg.eigvalsh(WD.T @ (WD * weights[:, None]))[-1]
    info_s = jnp.einsum("nki,nkj->nij", W_bar, W_bar) / depth_s[:, None, None]
    lam_s = jnp.max(jnp.linalg.eigvalsh(info_s)[:, -1])
    eta0 = as_float(gains.get("eta0", _STEP_FRACTION / (h * alpha_c * lam_c)))
    derived = {
        "eta1": eta0 / _RESET_RATIO,
        "gamma_s0": _STEP_FRACTION / (h * alpha * lam_s),
        "eps_c": _MARGIN_FRACTION * jnp.min(depth_c0),
        "eps_s": _MARGIN_FRACTION * jnp.min(depth_c0),
    }
    derived.update({k: v for k, v in gains.items() if k in derived})
    return cls(
        alpha_c=alpha_c,
        alpha=alpha,
        eta0=eta0,
        D=D,
        theta_c0=theta_c0,
        theta_s0=theta_s0,
        N=N,
        **derived,
    )


def pe_measure(info_rate_s, ts, window: float):
    """The persistency of excitation of eq. (49) over a sliding window, per unknown feature.

    $\\int_{t-T}^{t}\\bar W_{si}^T\\bar W_{si}\\,d\\tau$ by the rectangle rule on the saved
    samples (`info_rate_s` (N, n, 4, 4) from the estimator's output, at times `ts`). Since
    $\\bar W_{si}\\hat\\theta_{si} = 0$ by construction (eq. (22): the scale direction of eq.
    (50)), its smallest eigenvalue is always 0; the measure is its second smallest
    eigenvalue divided by its largest (0: not exciting, up to 1). NaN until a full window.

    **Returns:** (N, n).
    """
    info_rate_s = jnp.asarray(info_rate_s)
    ts = jnp.asarray(ts)
    dt = ts[1] - ts[0]
    k = max(1, int(round(float(window) / float(dt))))
    csum = jnp.cumsum(info_rate_s, axis=0) * dt
    shifted = jnp.concatenate([jnp.zeros_like(csum[:k]), csum[:-k]], axis=0)
    integral = csum - shifted
    lam = jnp.linalg.eigvalsh(integral)
    measure = lam[..., 1] / jnp.maximum(lam[..., -1], jnp.finfo(lam.dtype).tiny)
    full = (jnp.arange(ts.shape[0]) >= k)[:, None]
    return jnp.where(full, measure, jnp.nan)
