"""Active structure from motion: the inverse depth of static points seen by a moving,
calibrated camera whose velocity is known.

R. Spica, P. Robuffo Giordano, F. Chaumette, *Active Structure from Motion: Application to
Point, Sphere, and Cylinder*, IEEE Transactions on Robotics 30(6), 2014 (and R. Spica,
P. Robuffo Giordano, *A framework for active estimation: Application to structure from
motion*, IEEE CDC 2013).

Built on visjax's public contract only (`visjax.estimators.AbstractEstimator`, `Stream`,
`checked_samples`), as a user's estimator would be (`docs/extending.md`).

**The model** (the paper's framework, for a point: one unknown, $p = 1$). With the
measurable part $s$, the unknown $\\chi$ and the camera twist $u = (v, \\omega)$ in the
camera frame,

$$\\dot s = f_m(s, u) + \\Omega^T(s, v)\\, \\chi, \\qquad \\dot \\chi = f_u(s, \\chi, u).$$

- Planar projection: $s = (x, y) = (X/Z, Y/Z)$, $\\chi = 1/Z$;
  $f_m = [[xy, -(1+x^2), y], [1+y^2, -xy, -x]]\\, \\omega$,
  $\\Omega^T = (x v_z - v_x,\\ y v_z - v_y)$,
  $f_u = v_z \\chi^2 + (y \\omega_x - x \\omega_y)\\chi$.
- Spherical projection: $s = P / \\|P\\|$ (a unit vector), $\\chi = 1/\\|P\\|$;
  $f_m = [s]_\\times \\omega$, $\\Omega^T = (s s^T - I) v$, $f_u = (s^T v)\\chi^2$.

Both follow from the motion of a static point in the camera frame, $\\dot P = -v - \\omega
\\times P$ (the tests check them against finite differences of simulated points).

**The observer** (the paper's estimation scheme), $\\xi = s - \\hat s$:
$\\dot{\\hat s} = f_m(s, u) + \\Omega^T \\hat\\chi + H \\xi$,
$\\dot{\\hat \\chi} = f_u(s, \\hat\\chi, u) + \\alpha\\, \\Omega\\, \\xi$,
here with $H = h I$. Its error $z = \\chi - \\hat\\chi$ behaves, to first order, as a
second-order system whose stiffness is $\\alpha \\|\\Omega\\|^2$: the camera's linear
velocity sets the convergence rate (the active strategy of the paper chooses $v$ to hold
$\\alpha\\|\\Omega\\|^2$ at a desired value).

Equation numbers: the paper's text was not available to this transcription, so the
equations are cited by name, not number; each is the model above, checked against the
kinematics by the tests.
"""

from typing import Any, ClassVar, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from .._results import RESULTS
from ..baselines import AbstractEKFModel, extended_kalman_filter, triangulate_point
from ..estimators import (
    AbstractEstimator,
    Stream,
    checked_samples,
    moving_point_stream,
    run,
)
from ..geometry import pixel_to_normalized, skew
from ..studies import AbstractProblem, Parameter

_Projection = Literal["planar", "spherical"]


class PointDepthMeasurement(eqx.Module):
    """One sample: `s` (n, 2) normalized image coordinates (planar) or (n, 3) unit
    vectors (spherical), one row per point; `u` (6,) the camera twist $(v, \\omega)$ in
    the camera frame (m/s, rad/s)."""

    s: Float[Array, "*batch n d"]
    u: Float[Array, "*batch 6"]


class PointDepthState(eqx.Module):
    """`s_hat` (n, d) the estimate of the measured part; `chi_hat` (n,) of the inverse
    depth (1/m)."""

    s_hat: Float[Array, "*batch n d"]
    chi_hat: Float[Array, "*batch n"]


class PointDepthOutput(eqx.Module):
    """`chi_hat` (n,) the inverse depth (1/Z planar, 1/distance spherical, 1/m);
    `depth` (n,) its inverse (m); `point` (n, 3) the estimated point in the camera frame."""

    chi_hat: Float[Array, "*batch n"]
    depth: Float[Array, "*batch n"]
    point: Float[Array, "*batch n 3"]


def point_model(
    s: Float[ArrayLike, " d"], u: Float[ArrayLike, "6"], projection: _Projection = "planar"
) -> tuple[Float[Array, " d"], Float[Array, " d"]]:
    """`(f_m, Omega)` of one point: $\\dot s = f_m + \\Omega^T \\chi$ (module docstring)."""
    s, u = jnp.asarray(s), jnp.asarray(u)
    v, w = u[:3], u[3:]
    if projection == "planar":
        x, y = s[0], s[1]
        f_m = jnp.stack(
            [
                x * y * w[0] - (1 + x * x) * w[1] + y * w[2],
                (1 + y * y) * w[0] - x * y * w[1] - x * w[2],
            ]
        )
        omega = jnp.stack([x * v[2] - v[0], y * v[2] - v[1]])
        return f_m, omega
    f_m = skew(s) @ w
    omega = s * jnp.dot(s, v) - v
    return f_m, omega


def point_depth_rate(
    s: Float[ArrayLike, " d"],
    chi: Float[ArrayLike, ""],
    u: Float[ArrayLike, "6"],
    projection: _Projection = "planar",
) -> Float[Array, ""]:
    """$f_u(s, \\chi, u)$, the time derivative of the inverse depth (module docstring)."""
    s, chi, u = jnp.asarray(s), jnp.asarray(chi), jnp.asarray(u)
    v, w = u[:3], u[3:]
    if projection == "planar":
        return v[2] * chi**2 + (s[1] * w[0] - s[0] * w[1]) * chi
    return jnp.dot(s, v) * chi**2


class PointDepthObserver(AbstractEstimator):
    """The observer of Spica et al. for `n` static points at once (module docstring):
    `alpha` ($\\alpha > 0$, the inverse depth's gain), `h` ($H = h I$, $h > 0$, 1/s) and
    `chi0` (the initial inverse-depth estimate of every point, 1/m); `projection`
    `"planar"` or `"spherical"` (static)."""

    alpha: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    h: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    chi0: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    projection: _Projection = eqx.field(static=True, default="planar")

    dims: ClassVar[dict] = {"planar": 2, "spherical": 3}

    def __check_init__(self):
        if self.projection not in self.dims:
            raise ValueError(
                f'`projection` must be "planar" or "spherical"; got {self.projection!r}.'
            )

    def init(self, y0: PointDepthMeasurement) -> PointDepthState:
        n = y0.s.shape[0]
        return PointDepthState(s_hat=y0.s, chi_hat=jnp.full((n,), self.chi0, y0.s.dtype))

    def vector_field(self, t, state: PointDepthState, y: PointDepthMeasurement):
        def one(s, s_hat, chi_hat):
            f_m, omega = point_model(s, y.u, self.projection)
            xi = s - s_hat
            s_dot = f_m + omega * chi_hat + self.h * xi
            chi_dot = point_depth_rate(s, chi_hat, y.u, self.projection) + self.alpha * jnp.dot(
                omega, xi
            )
            return s_dot, chi_dot

        s_dot, chi_dot = jax.vmap(one)(y.s, state.s_hat, state.chi_hat)
        return PointDepthState(s_hat=s_dot, chi_hat=chi_dot)

    def output(self, t, state: PointDepthState, y: PointDepthMeasurement) -> PointDepthOutput:
        chi = state.chi_hat
        depth = 1.0 / chi
        if self.projection == "planar":
            bearing = jnp.concatenate([y.s, jnp.ones_like(y.s[:, :1])], axis=1)
        else:
            bearing = y.s
        return PointDepthOutput(chi_hat=chi, depth=depth, point=bearing * depth[:, None])

    def valid(self, state: PointDepthState, y: PointDepthMeasurement) -> Bool[Array, ""]:
        # a point in front of the camera has a positive inverse depth; a non-positive
        # estimate is reported (RESULTS.diverged), never a negative depth
        return jnp.all(state.chi_hat > 0)

    def checks(self):
        return (
            (self.alpha > 0, "`alpha` must be positive"),
            (self.h > 0, "`h` must be positive"),
            (self.chi0 > 0, "`chi0` (the initial inverse depth) must be positive"),
        )

    def max_stable_dt(self, y: PointDepthMeasurement):
        """Euler on the linearised error dynamics at the first sample: along $\\Omega$,
        $\\dot\\xi = -h\\xi + \\sigma z$, $\\dot z = -\\alpha\\sigma\\xi$ ($\\sigma =
        \\|\\Omega\\|$), eigenvalues $(-h \\pm \\sqrt{h^2 - 4\\alpha\\sigma^2})/2$; across it,
        $-h$. The smallest bound over the points."""
        sigma2 = jax.vmap(lambda s: jnp.sum(point_model(s, y.u, self.projection)[1] ** 2))(y.s)
        disc = self.h**2 - 4 * self.alpha * sigma2
        real = 4.0 / (self.h + jnp.sqrt(jnp.maximum(disc, 0.0)))
        complex_ = self.h / jnp.maximum(self.alpha * sigma2, 1e-300)
        bound = jnp.where(disc >= 0, real, complex_)
        return jnp.minimum(jnp.min(bound), 2.0 / self.h)


def point_depth_stream(
    ts: Float[ArrayLike, " N"],
    pixels: Float[ArrayLike, "N n 2"],
    twists: Float[ArrayLike, "N 6"],
    A: Float[ArrayLike, "3 3"],
    *,
    projection: _Projection = "planar",
    truth=None,
    throw: bool = True,
) -> Stream:
    """The observer's stream from pixel tracks (N, n, 2) of a camera with intrinsics `A`
    and its twists (N, 6) in the camera frame: normalized coordinates (planar) or their
    unit bearing vectors (spherical). `throw`: a non-finite sample raises, naming it
    (`checked_samples`); with `throw=False` the run stops there."""
    ts, pixels, twists = (jnp.asarray(a, float) for a in (ts, pixels, twists))
    if pixels.ndim != 3 or pixels.shape[-1] != 2 or pixels.shape[0] != ts.shape[0]:
        raise ValueError(f"`pixels` must have shape (N, n, 2) with N = {ts.shape[0]}.")
    if twists.shape != (ts.shape[0], 6):
        raise ValueError(f"`twists` must have shape ({ts.shape[0]}, 6); got {twists.shape}.")
    if projection not in PointDepthObserver.dims:
        raise ValueError(f'`projection` must be "planar" or "spherical"; got {projection!r}.')
    m = pixel_to_normalized(pixels, A)
    if projection == "spherical":
        m = jnp.concatenate([m, jnp.ones_like(m[..., :1])], axis=-1)
        m = m / jnp.linalg.norm(m, axis=-1, keepdims=True)
    stream = Stream(ts=ts, ys=PointDepthMeasurement(s=m, u=twists), truth=truth)
    return checked_samples(stream, "point_depth_stream", throw)


class InverseDepthModel(AbstractEKFModel):
    """The EKF baseline's model of one point (planar projection), state $(x, y, \\chi)$:
    the transition is an Euler step of the model of the module docstring under the held
    camera twist `u` (6,), the measurement is $(x, y)$. `q_s`, `q_chi`: the process noise
    densities of the image coordinates and of the inverse depth (per second); `r` the
    measurement variance (normalized coordinates squared)."""

    q_s: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    q_chi: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    r: Float[Array, ""] = eqx.field(converter=jnp.asarray)

    def transition(self, x, u, dt):
        s, chi = x[:2], x[2]
        f_m, omega = point_model(s, u, "planar")
        s_dot = f_m + omega * chi
        return jnp.concatenate([s + dt * s_dot, (chi + dt * point_depth_rate(s, chi, u))[None]])

    def process_noise(self, x, u, dt):
        return jnp.diag(jnp.stack([self.q_s, self.q_s, self.q_chi])) * dt

    def measure(self, x, u):
        return x[:2]

    def measurement_noise(self, x, u):
        return self.r * jnp.eye(2, dtype=x.dtype)

    def valid(self, x, u):
        return x[2] > 0


# ---------------------------------------------------------------------------------------
# The problem `point-depth`: the inverse depth of static points seen by a camera moving with
# a known velocity (scene of its own: not the paper's motion)

POINTS = (
    (0.1, -0.05, 0.5),
    (-0.3, 0.2, 1.2),
    (0.4, 0.3, 2.0),
    (-0.6, -0.4, 2.5),
    (0.2, -0.7, 3.0),
)  # five static points at 0.5-3 m in front of the camera's start (its frame: the world's)
TWIST = (
    0.3,
    0.2,
    0.05,
    0.02,
    -0.03,
    0.05,
)  # constant (world frame): sideways and forwards, turning
CAMERA = ((600.0, 0.0, 320.0), (0.0, 600.0, 240.0), (0.0, 0.0, 1.0))  # intrinsics, pixels


class PointDepthScene(eqx.Module):
    """The scene of `point_depth_scene`: `ts` (N,), `points` (N, n, 3) in the camera frame
    (the truth), `pixels` (N, n, 2), `twists` (N, 6) the camera's twist in its own frame
    $(v, \\omega)$, `K` (3, 3)."""

    ts: Float[Array, " N"]
    points: Float[Array, "N n 3"]
    pixels: Float[Array, "N n 2"]
    twists: Float[Array, "N 6"]
    K: Float[Array, "3 3"]


def point_depth_scene(duration: float = 1.0, rate_hz: float = 1000.0) -> PointDepthScene:
    """Five static points (`POINTS`) seen by a camera moving with the constant twist
    `TWIST` (closed form, `visjax.sim.constant_twist_trajectory`), `duration` s at
    `rate_hz`."""
    from ..sim import CameraRig, constant_twist_trajectory, points_in_camera, sample_times, view

    ts = sample_times(duration, rate_hz)
    body = constant_twist_trajectory(jnp.asarray(TWIST), jnp.zeros(3), jnp.eye(3), ts)
    rig = CameraRig(A=jnp.asarray(CAMERA), image_size=None)
    P = points_in_camera(rig, jnp.asarray(POINTS), body)
    R_T = jnp.swapaxes(body.R, 1, 2)
    v = jnp.einsum("kij,kj->ki", R_T, body.twist[:, :3])
    w = jnp.einsum("kij,kj->ki", R_T, body.twist[:, 3:])
    return PointDepthScene(
        ts=ts, points=P, pixels=view(rig, P), twists=jnp.concatenate([v, w], axis=1), K=rig.A
    )


def _first_failure(results, n):
    """The first failure over `n` points' results (batched by `vmap`), or success."""
    result = RESULTS.successful
    for k in range(n):
        result_k = jax.tree_util.tree_map(lambda v, k=k: v[k], results)
        result = RESULTS.where(result == RESULTS.successful, result_k, result)
    return result


class LeastSquaresDepth(eqx.Module):
    """A baseline's solution: `ts`, `depth` (N, n) (NaN before a least-squares window
    determines a point), `result` (the first failure over the points)."""

    ts: Float[Array, " N"]
    depth: Float[Array, "N n"]
    result: Any


class PointDepthProblem(AbstractProblem):
    """The depth of static points from a moving calibrated camera with known velocity
    (Spica et al.'s observer, module docstring), against a sliding-window least-squares
    triangulation on the same measurements (`visjax.baselines.triangulate_point`, the last
    `window` frames) and an EKF on inverse depth per point (`InverseDepthModel`; planar
    coordinates for both projections: its prior is the observer's `chi0` with a standard
    deviation of `chi0`, its measurement noise the problem's pixel noise, at least 0.1 px,
    its process noise 1e-8 per second on every state).

    Metrics: `depth_error` the worst relative depth error over the points at the last
    sample; `time_to_5pct` the first time from which every point's relative error stays
    below 5% (the run's length if never)."""

    methods: ClassVar[tuple] = ("estimator", "least_squares", "ekf")
    metric: ClassVar[str] = "depth_error"
    label: ClassVar[str] = "worst relative depth error at the end (-)"
    grid: ClassVar[str] = "alpha=100:3000:5"
    title: ClassVar[str] = "depth of static points, moving camera (Spica et al.)"

    scene: PointDepthScene
    noise_px: float = eqx.field(static=True, default=0.0)
    projection: str = eqx.field(static=True, default="planar")
    window: int = eqx.field(static=True, default=250)

    def parameters(self):
        return {
            "alpha": Parameter(1000.0, "1/m^2", True, "the inverse depth's gain"),
            "h": Parameter(20.0, "1/s", True, "the measured part's gain, H = h I"),
            "chi0": Parameter(1.0 / 1.5, "1/m", True, "the initial inverse depth"),
        }

    def settings(self):
        return {
            "noise_px": self.noise_px,
            "projection": self.projection,
            "window_samples": self.window,
            "samples": int(self.scene.ts.shape[0]),
        }

    def inputs(self, key):
        noise = jax.random.normal(key, self.scene.pixels.shape, self.scene.pixels.dtype)
        return self.scene.pixels + self.noise_px * noise

    def solve(self, method, params, inputs, *, outputs=False):
        sc = self.scene
        if method == "estimator":
            observer = PointDepthObserver(
                alpha=params["alpha"],
                h=params["h"],
                chi0=params["chi0"],
                projection=self.projection,
            )
            stream = point_depth_stream(
                sc.ts, inputs, sc.twists, sc.K, projection=self.projection, throw=False
            )
            return run(observer, stream, throw=False)

        if method == "ekf":
            return self._ekf(params, inputs)

        def one(pixels):
            stream = moving_point_stream(sc.ts, pixels, sc.twists, sc.K, throw=False)
            sol = triangulate_point(stream, window=self.window, throw=False)
            depth = sol.outputs.position[:, 2]
            if self.projection == "spherical":
                depth = jnp.linalg.norm(sol.outputs.position, axis=-1)
            return depth, sol.result

        depth, results = jax.vmap(one, in_axes=1, out_axes=(1, 0))(inputs)
        return LeastSquaresDepth(
            ts=sc.ts, depth=depth, result=_first_failure(results, depth.shape[1])
        )

    def _ekf(self, params, inputs):
        sc = self.scene
        focal = sc.K[0, 0]
        sigma = max(self.noise_px, 0.1)
        model = InverseDepthModel(q_s=1e-8, q_chi=1e-8, r=(sigma / focal) ** 2)
        chi0 = params["chi0"]

        def one(pixels):
            m = pixel_to_normalized(pixels, sc.K)
            x0 = jnp.stack([m[0, 0], m[0, 1], chi0])
            P0 = jnp.diag(jnp.stack([model.r, model.r, chi0**2]))
            sol = extended_kalman_filter(model, sc.ts, m, sc.twists, x0, P0, throw=False)
            chi = sol.outputs.x[:, 2]
            if self.projection == "spherical":  # the distance along the measured bearing
                depth = jnp.sqrt(1.0 + jnp.sum(m**2, axis=-1)) / chi
            else:
                depth = 1.0 / chi
            return depth, sol.result

        depth, results = jax.vmap(one, in_axes=1, out_axes=(1, 0))(inputs)
        return LeastSquaresDepth(
            ts=sc.ts, depth=depth, result=_first_failure(results, depth.shape[1])
        )

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


def point_depth_problem(
    *,
    noise_px: float = 0.0,
    duration: float = 1.0,
    rate_hz: float = 1000.0,
    variant: str | None = None,
    window_s: float = 0.25,
) -> PointDepthProblem:
    """The `point-depth` problem on `point_depth_scene(duration, rate_hz)` with Gaussian
    pixel noise `noise_px`; `variant` (`--set`) the projection, `"planar"` (default) or
    `"spherical"`; `window_s` the least-squares baseline's window (s)."""
    projection = variant or "planar"
    if projection not in PointDepthObserver.dims:
        raise ValueError(f'the variant must be "planar" or "spherical"; got {variant!r}.')
    if not noise_px >= 0:
        raise ValueError(f"`noise_px` must be non-negative; got {noise_px!r}.")
    window = max(2, int(round(window_s * rate_hz)))
    return PointDepthProblem(
        scene=point_depth_scene(duration, rate_hz),
        noise_px=float(noise_px),
        projection=projection,
        window=window,
    )
