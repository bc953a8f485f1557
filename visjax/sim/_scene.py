"""Scene builders: rigid trajectories, camera rigs, feature sets and a sampler.

Conventions (used by all three problems):

- A `Trajectory` is a body's pose in a fixed (world) frame: orientation `R`, origin `x`,
  and its twist $[v, \\omega]$ in the world frame ($\\dot x = v$, $\\dot R = [\\omega]_\\times R$).
- A `CameraRig` is a camera with intrinsics `A` mounted on a body at `(R_c, x_c)`: the
  camera's orientation and origin in the body frame. A world point $w$ is at
  $R_c^T(R_b^T(w - x_b) - x_c)$ in the camera frame (Nath, Dawson, Tatlicioglu, *Euclidean
  position estimation of static features using a moving uncalibrated camera*, eq. (5)),
  with $(R_b, x_b)$ the body's pose. A fixed camera is a rig with no body (the world frame
  is the camera frame, as in Chitrakaran et al., *Identification of a moving object's
  velocity with a fixed camera*, section 2).
- A `Sampler` turns the continuous scene into what a camera records: sample times at any
  rate with optional jitter, Gaussian pixel noise, random dropouts, and the field of view:
  a feature outside the image (or behind the camera) is NaN, never reported.

Nothing here knows a paper's numbers.
"""

import functools
from collections.abc import Sequence
from typing import final

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, PRNGKeyArray

from .._util import as_float, check_shape
from ..geometry import intrinsics_from_camera, so3_exp, so3_log
from ._trajectory import Trajectory, integrate_twist


def _pose_args(x0, R0):
    x0 = as_float(x0)
    R0 = as_float(R0)
    check_shape(x0, (3,), "x0")
    check_shape(R0, (3, 3), "R0")
    return x0, R0


def constant_twist_trajectory(
    twist: Float[ArrayLike, "6"],
    x0: Float[ArrayLike, "3"],
    R0: Float[ArrayLike, "3 3"],
    ts: Float[ArrayLike, " N"],
) -> Trajectory:
    """A body moving with a constant twist $[v, \\omega]$ (world frame: $v$ the velocity of
    its origin) from `(x0, R0)` at `ts[0]`, in closed form: $x(t) = x_0 + v\\tau$,
    $R(t) = \\exp(\\tau[\\omega]_\\times) R_0$, $\\tau = t - t_0$."""
    twist = as_float(twist)
    check_shape(twist, (6,), "twist")
    x0, R0 = _pose_args(x0, R0)
    ts = as_float(ts)
    check_shape(ts, (None,), "ts")
    return _constant_twist(twist, x0, R0, ts)


# The arithmetic of the builders in this module, compiled: one program per shape when
# called outside `jit` (not one compiled operation per line); inlined under `jit`.
@jax.jit
def _constant_twist(twist, x0, R0, ts):
    tau = ts - ts[0]
    R = jax.vmap(lambda s: so3_exp(s * twist[3:]) @ R0)(tau)
    x = x0[None, :] + tau[:, None] * twist[None, :3]
    return Trajectory(ts=ts, R=R, x=x, twist=jnp.broadcast_to(twist, (ts.shape[0], 6)))


def sinusoidal_trajectory(
    amplitude: Float[ArrayLike, "6"],
    frequency_hz: Float[ArrayLike, "6"],
    x0: Float[ArrayLike, "3"],
    R0: Float[ArrayLike, "3 3"],
    ts: Float[ArrayLike, " N"],
    *,
    phase: ArrayLike | Sequence[float | int] = (0.0,) * 6,
    offset: ArrayLike | Sequence[float | int] = (0.0,) * 6,
) -> Trajectory:
    """A body whose twist (world frame) is $a_i \\sin(2\\pi f_i t + \\varphi_i) + c_i$ on
    each of its six entries $[v_x, v_y, v_z, \\omega_x, \\omega_y, \\omega_z]$, from
    `(x0, R0)` at `ts[0]` (`integrate_twist`)."""
    a, f, ph, c = (as_float(v) for v in (amplitude, frequency_hz, phase, offset))
    for v, name in ((a, "amplitude"), (f, "frequency_hz"), (ph, "phase"), (c, "offset")):
        check_shape(v, (6,), name)
    x0, R0 = _pose_args(x0, R0)

    return integrate_twist(_SinusoidalTwist(a, f, ph, c), x0, R0, ts)


class _SinusoidalTwist(eqx.Module):
    """$a \\sin(2\\pi f t + \\varphi) + c$ (a Module: the compiled integration is shared by
    every sinusoidal trajectory of the same length)."""

    a: Array
    f: Array
    ph: Array
    c: Array

    def __call__(self, t):
        return self.a * jnp.sin(2.0 * jnp.pi * self.f * t + self.ph) + self.c


def _natural_spline_slopes(knots, values):
    """The first derivatives at the knots of the natural cubic spline (second derivative 0
    at both ends) through `values` (K, d): the tridiagonal system of the C2 conditions."""
    h = jnp.diff(knots)
    k = knots.shape[0]
    delta = jnp.diff(values, axis=0) / h[:, None]
    # unknowns: slopes m_0..m_{K-1}; interior rows from continuity of the second derivative
    M = jnp.zeros((k, k), values.dtype)
    rhs = jnp.zeros_like(values)
    M = M.at[0, 0].set(2.0).at[0, 1].set(1.0)
    rhs = rhs.at[0].set(3.0 * delta[0])
    M = M.at[k - 1, k - 2].set(1.0).at[k - 1, k - 1].set(2.0)
    rhs = rhs.at[k - 1].set(3.0 * delta[-1])
    i = jnp.arange(1, k - 1)
    M = M.at[i, i - 1].set(1.0 / h[:-1])
    M = M.at[i, i].set(2.0 / h[:-1] + 2.0 / h[1:])
    M = M.at[i, i + 1].set(1.0 / h[1:])
    rhs = rhs.at[i].set(3.0 * (delta[:-1] / h[:-1, None] + delta[1:] / h[1:, None]))
    return jnp.linalg.solve(M, rhs)


def _hermite(knots, values, slopes, t):
    """The cubic Hermite interpolant through (values, slopes) at `knots`, at time t."""
    j = jnp.clip(jnp.searchsorted(knots, t, side="right") - 1, 0, knots.shape[0] - 2)
    h = knots[j + 1] - knots[j]
    s = (t - knots[j]) / h
    h00 = (1 + 2 * s) * (1 - s) ** 2
    h10 = s * (1 - s) ** 2
    h01 = s**2 * (3 - 2 * s)
    h11 = s**2 * (s - 1)
    return h00 * values[j] + h10 * h * slopes[j] + h01 * values[j + 1] + h11 * h * slopes[j + 1]


def spline_trajectory(
    knot_ts: Float[ArrayLike, " K"],
    R_knots: Float[ArrayLike, "K 3 3"],
    x_knots: Float[ArrayLike, "K 3"],
    ts: Float[ArrayLike, " N"],
) -> Trajectory:
    """A smooth trajectory through given poses: natural cubic splines (C2, zero second
    derivative at the ends) of the position and of the rotation vector
    $\\varphi_k = \\log(R_0^T R_k)$, $R(t) = R_0 \\exp([\\varphi(t)]_\\times)$; the twist is
    the exact derivative ($\\omega$ from $[\\omega]_\\times = \\dot R R^T$, by forward-mode
    differentiation). Rotations must stay within $\\pi$ of the first knot's.

    **Arguments:** `knot_ts` (K,) increasing, K >= 2; `R_knots` (K, 3, 3); `x_knots` (K, 3);
    `ts` (N,) within `[knot_ts[0], knot_ts[-1]]`.
    """
    knots, R_k, x_k, ts = (as_float(v) for v in (knot_ts, R_knots, x_knots, ts))
    check_shape(knots, (None,), "knot_ts")
    k = knots.shape[0]
    if k < 2:
        raise ValueError(f"`knot_ts` needs at least 2 knots; got {k}.")
    check_shape(R_k, (k, 3, 3), "R_knots")
    check_shape(x_k, (k, 3), "x_knots")
    check_shape(ts, (None,), "ts")
    known = _concrete(knots)
    if known is not None and not np.all(np.diff(known) > 0):
        raise ValueError("`knot_ts` must be strictly increasing.")
    return _spline(knots, R_k, x_k, ts)


@jax.jit
def _spline(knots, R_k, x_k, ts):
    R0 = R_k[0]
    phi = jax.vmap(lambda R: so3_log(R0.T @ R).omega)(R_k)
    values = jnp.concatenate([x_k, phi], axis=1)
    slopes = _natural_spline_slopes(knots, values)

    def pose(t):
        q = _hermite(knots, values, slopes, t)
        return R0 @ so3_exp(q[3:]), q[:3]

    def pose_and_twist(t):
        (R, x), (dR, dx) = jax.jvp(pose, (t,), (jnp.ones_like(t),))
        W = dR @ R.T
        w = jnp.stack([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]]) / 2.0
        return R, x, jnp.concatenate([dx, w])

    R, x, twist = jax.vmap(pose_and_twist)(ts)
    return Trajectory(ts=ts, R=R, x=x, twist=twist)


def _concrete(x):
    try:
        return np.asarray(x)
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
        return None


@final
class CameraRig(eqx.Module):
    """A camera: intrinsics `A` (3, 3), mounted at `R_c` (3, 3), `x_c` (3,) (its orientation
    and origin in the frame of the body that carries it; identity and zero for a camera
    whose frame is the body's), and the image size `(width, height)` in pixels (static),
    or `None` for an unbounded image plane."""

    A: Float[Array, "3 3"] = eqx.field(converter=as_float)
    R_c: Float[Array, "3 3"] = eqx.field(
        converter=as_float, default=((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    )
    x_c: Float[Array, "3"] = eqx.field(converter=as_float, default=(0.0, 0.0, 0.0))
    image_size: tuple[int, int] | None = eqx.field(default=(640, 480), static=True)

    def __check_init__(self):
        for name, shape in (("A", (3, 3)), ("R_c", (3, 3)), ("x_c", (3,))):
            if jnp.shape(getattr(self, name)) != shape:
                raise ValueError(
                    f"`CameraRig.{name}` must have shape {shape}; got "
                    f"{jnp.shape(getattr(self, name))}."
                )
        size = self.image_size
        if size is not None and not (
            len(size) == 2 and all(isinstance(s, int) and s > 0 for s in size)
        ):
            raise ValueError(f"`image_size` must be (width, height) in pixels; got {size!r}.")


def intrinsics(
    fx: float,
    fy: float | None = None,
    cx: float = 320.0,
    cy: float = 240.0,
    *,
    skew_angle_deg: float = 90.0,
) -> Float[Array, "3 3"]:
    """An intrinsic matrix with focal lengths in pixels, principal point `(cx, cy)` and the
    angle $\\phi$ between the pixel axes (90 degrees: no skew), in the form of Nath et al.,
    eq. (4) with $f k_u = f_x$, $f k_v = f_y$:
    $A = [[f_x, f_x\\cot\\phi, c_x], [0, f_y/\\sin\\phi, c_y], [0, 0, 1]]$."""
    fy = fx if fy is None else fy
    if not (fx > 0 and fy > 0 and 0 < skew_angle_deg < 180):
        raise ValueError(
            "focal lengths must be positive and the skew angle in (0, 180) degrees; got "
            f"fx={fx!r}, fy={fy!r}, skew_angle_deg={skew_angle_deg!r}."
        )
    # eq. (4) with f k_u = fx, f k_v = fy
    return intrinsics_from_camera(1.0, fx, fy, jnp.deg2rad(skew_angle_deg), cx, cy)


def points_in_camera(
    rig: CameraRig,
    points: Float[ArrayLike, "*N n 3"],
    body: Trajectory | None = None,
) -> Float[Array, "N n 3"]:
    """World points (per sample, or fixed: shape (n, 3)) in the camera frame of `rig`,
    carried by `body` (Nath et al., eq. (5)), or fixed with its frame the world's."""
    points = as_float(points)
    if points.ndim == 2:
        check_shape(points, (None, 3), "points")
        n_samples = None if body is None else body.ts.shape[0]
        if n_samples is not None:
            points = jnp.broadcast_to(points, (n_samples,) + points.shape)
        else:
            points = points[None]
    check_shape(points, (None, None, 3), "points")
    if body is not None and points.shape[0] != body.ts.shape[0]:
        raise ValueError(
            f"`points` must have the body's {body.ts.shape[0]} samples first; got "
            f"{points.shape}."
        )
    return _points_in_camera(rig, points, body)


@jax.jit
def _points_in_camera(rig, points, body):
    if body is not None:
        local = jnp.einsum("kji,knj->kni", body.R, points - body.x[:, None, :])  # R_b^T (w-x_b)
    else:
        local = points
    return jnp.einsum("ji,knj->kni", rig.R_c, local - rig.x_c[None, None, :])  # R_c^T (. - x_c)


def object_points(body: Trajectory, points: Float[ArrayLike, "n 3"]) -> Float[Array, "N n 3"]:
    """Points fixed on a moving body (body frame, (n, 3)) in the world frame at every
    sample: $x + R s_i$ (Chitrakaran et al., eq. (5))."""
    points = as_float(points)
    check_shape(points, (None, 3), "points")
    return _object_points(body, points)


@jax.jit
def _object_points(body, points):
    return body.x[:, None, :] + jnp.einsum("nij,kj->nki", body.R, points)


def view(rig: CameraRig, points_camera: Float[ArrayLike, "... 3"]) -> Float[Array, "... 2"]:
    """Pixels $p = A m / z$ of points in the camera frame, NaN where a point is behind the
    camera ($z \\le 0$) or outside the image (`rig.image_size`): dropped, not reported."""
    return _view(rig, as_float(points_camera))


@jax.jit
def _view(rig, P):
    z = P[..., 2]
    ahead = z > 0.0
    z_safe = jnp.where(ahead, z, 1.0)
    m = P / z_safe[..., None]
    p = m @ rig.A.T
    p = p[..., :2]
    seen = ahead
    if rig.image_size is not None:
        w, h = rig.image_size
        seen = seen & (p[..., 0] >= 0) & (p[..., 0] <= w) & (p[..., 1] >= 0) & (p[..., 1] <= h)
    return jnp.where(seen[..., None], p, jnp.nan)


def planar_features(
    n: int,
    *,
    size: float,
    normal: ArrayLike | Sequence[float | int] = (0.0, 0.0, 1.0),
    offset: float = 0.0,
    seed: int = 0,
) -> Float[Array, "n 3"]:
    """`n` irregular coplanar points (body frame): uniform in a square of side `size` on the
    plane $\\{s : \\nu^T s = \\text{offset}\\}$, $\\nu$ = `normal` (normalised), so that the
    body origin is off the plane when `offset != 0`. NumPy random generator `seed`; points
    closer than `size / 10` to each other are redrawn (no near-coincident features)."""
    if not (isinstance(n, int) and n >= 2 and size > 0):
        raise ValueError(f"need n >= 2 points and size > 0; got n={n!r}, size={size!r}.")
    nu = np.asarray(normal, float)
    if nu.shape != (3,) or not np.linalg.norm(nu) > 0:
        raise ValueError(f"`normal` must be a nonzero 3-vector; got {normal!r}.")
    nu = nu / np.linalg.norm(nu)
    # an orthonormal basis (e1, e2) of the plane
    e1 = np.cross(nu, [1.0, 0.0, 0.0] if abs(nu[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(nu, e1)
    rng = np.random.default_rng(seed)
    uv = []
    while len(uv) < n:
        c = rng.uniform(-size / 2, size / 2, 2)
        if all(np.linalg.norm(c - o) > size / 10 for o in uv):
            uv.append(c)
    uv = np.asarray(uv)
    return jnp.asarray(offset * nu + uv[:, :1] * e1 + uv[:, 1:] * e2)


def box_features(
    n: int,
    low: ArrayLike | Sequence[float | int],
    high: ArrayLike | Sequence[float | int],
    *,
    seed: int = 0,
) -> Float[Array, "n 3"]:
    """`n` points uniform in the box `[low, high]` (not coplanar), NumPy generator `seed`."""
    low, high = np.asarray(low, float), np.asarray(high, float)
    if low.shape != (3,) or high.shape != (3,) or not np.all(high >= low):
        raise ValueError(f"`low` and `high` must be 3-vectors with low <= high; got {low}, {high}.")
    return jnp.asarray(np.random.default_rng(seed).uniform(low, high, (n, 3)))


@final
class Sampler(eqx.Module):
    """What a camera records of a scene.

    **Fields:** `rate_hz`: frames per second; `jitter_s`: each frame time is
    $k/f + \\delta_k$ with $\\delta_k$ uniform in $[-j, j]$ (kept increasing: $j < 1/(2f)$);
    `noise_px`: i.i.d. Gaussian noise (px) on every pixel coordinate; `dropout`: the
    probability that a feature is missed in a frame (NaN), independently per feature and
    frame (frame 0 is always complete: a reference).

    Features outside the image or behind the camera are NaN whatever these say
    (`view`).
    """

    rate_hz: float = eqx.field(static=True)
    jitter_s: float = eqx.field(default=0.0, static=True)
    noise_px: float = eqx.field(default=0.0, static=True)
    dropout: float = eqx.field(default=0.0, static=True)

    def __check_init__(self):
        if not self.rate_hz > 0:
            raise ValueError(f"`rate_hz` must be positive; got {self.rate_hz!r}.")
        if not 0 <= self.jitter_s < 0.5 / self.rate_hz:
            raise ValueError(
                f"`jitter_s` must be in [0, 1/(2 rate_hz)) = [0, {0.5 / self.rate_hz:.3g}); "
                f"got {self.jitter_s!r}."
            )
        if not self.noise_px >= 0:
            raise ValueError(f"`noise_px` must be non-negative; got {self.noise_px!r}.")
        if not 0 <= self.dropout < 1:
            raise ValueError(f"`dropout` must be in [0, 1); got {self.dropout!r}.")

    def times(self, duration: float, key: PRNGKeyArray | None = None) -> Float[Array, " N"]:
        """Frame times over `duration` seconds from 0 (frame 0 at exactly 0)."""
        n = int(round(duration * self.rate_hz))
        if not (duration > 0 and n >= 2):
            raise ValueError(
                f"`duration` times `rate_hz` must give at least 2 samples; got {duration!r}."
            )
        ts = jnp.arange(n, dtype=jnp.result_type(float)) / self.rate_hz
        if self.jitter_s > 0:
            if key is None:
                raise ValueError("a PRNG `key` is required for jitter.")
            d = jax.random.uniform(key, (n,), ts.dtype, -self.jitter_s, self.jitter_s)
            ts = ts + d.at[0].set(0.0)
        return ts

    def record(
        self,
        rig: CameraRig,
        points_camera: Float[ArrayLike, "N n 3"],
        key: PRNGKeyArray | None = None,
    ) -> tuple[Float[Array, "N n 2"], Bool[Array, "N n"]]:
        """Pixels of points given in the camera frame at the frame times, with noise and
        dropouts; `(pixels, seen)`, a missed feature NaN and `seen` False."""
        needs_key = self.noise_px > 0 or self.dropout > 0
        if needs_key and key is None:
            raise ValueError("a PRNG `key` is required for pixel noise or dropouts.")
        return _record(
            self.noise_px, self.dropout, rig, as_float(points_camera), key if needs_key else None
        )


@functools.partial(jax.jit, static_argnums=(0, 1))
def _record(noise_px, dropout, rig, points_camera, key):
    p = view(rig, points_camera)
    if key is not None:
        k_noise, k_drop = jax.random.split(key)
        if noise_px > 0:
            p = p + noise_px * jax.random.normal(k_noise, p.shape, p.dtype)
        if dropout > 0:
            kept = jax.random.uniform(k_drop, p.shape[:-1]) >= dropout
            kept = kept.at[0].set(True)
            p = jnp.where(kept[..., None], p, jnp.nan)
    seen = jnp.all(jnp.isfinite(p), axis=-1)
    return p, seen
