"""The point-depth observer of Spica, Robuffo Giordano and Chaumette (*Active Structure
from Motion: Application to Point, Sphere, and Cylinder*, IEEE Transactions on Robotics
30(6), 2014): the inverse depth of static points seen by a moving, calibrated camera whose
velocity is known, `PointDepthEstimator`, and its stream builder `point_depth_stream`. Its
problem and reproduction are `visjax.papers.spica`'s.

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

from typing import ClassVar, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from ..geometry import pixel_to_normalized, skew
from ._base import AbstractEstimator, Stream, checked_samples, reject_mask, rejected_samples

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


class PointDepthEstimator(AbstractEstimator):
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
    reject: Bool[ArrayLike, " N"] | None = None,
    truth=None,
    throw: bool = True,
) -> Stream:
    """The observer's stream from pixel tracks (N, n, 2) of a camera with intrinsics `A`
    and its twists (N, 6) in the camera frame: normalized coordinates (planar) or their
    unit bearing vectors (spherical). `reject` (N,) bool: the samples an outlier test
    rejected, held over as dropped ones (`Stream.present`; the first must be kept).
    `throw`: a non-finite sample raises, naming it (`checked_samples`); with
    `throw=False` the run stops there."""
    ts, pixels, twists = (jnp.asarray(a, float) for a in (ts, pixels, twists))
    if pixels.ndim != 3 or pixels.shape[-1] != 2 or pixels.shape[0] != ts.shape[0]:
        raise ValueError(f"`pixels` must have shape (N, n, 2) with N = {ts.shape[0]}.")
    if twists.shape != (ts.shape[0], 6):
        raise ValueError(f"`twists` must have shape ({ts.shape[0]}, 6); got {twists.shape}.")
    if projection not in PointDepthEstimator.dims:
        raise ValueError(f'`projection` must be "planar" or "spherical"; got {projection!r}.')
    m = pixel_to_normalized(pixels, A)
    if projection == "spherical":
        m = jnp.concatenate([m, jnp.ones_like(m[..., :1])], axis=-1)
        m = m / jnp.linalg.norm(m, axis=-1, keepdims=True)
    stream = Stream(ts=ts, ys=PointDepthMeasurement(s=m, u=twists), truth=truth)
    stream = rejected_samples(stream, reject_mask(reject, ts.shape[0]))
    return checked_samples(stream, "point_depth_stream", throw)
