"""The point-depth observer of Spica et al. in a closed loop with the active strategy
(*Active Structure from Motion*, IEEE Transactions on Robotics 30(6), 2014: keep
$\\alpha\\|\\Omega\\|^2$ at a desired value): `ActivePointDepth`, an estimator whose state
holds the simulated camera and points, the controller and the observer, on visjax's runner
unchanged; `active_sigma2`, `active_velocity` and `servo_angular_velocity`, the laws of the
loop. `visjax.papers.spica.active_point_depth_run` runs it; the derivation follows."""

from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from ..geometry import skew
from ._base import AbstractJumpEstimator
from ._point_depth import (
    PointDepthEstimator,
    PointDepthMeasurement,
    PointDepthState,
    point_model,
)

_Projection = Literal["planar", "spherical"]


# The active strategy and a controller in the loop
#
# **The error dynamics** (derived here from the observer above). With $\xi = s - \hat s$,
# $z = \chi - \hat\chi$ and $H = h I$, subtracting the observer from the model:
#
# $$\dot\xi = \Omega^T z - h\,\xi, \qquad
#   \dot z = [f_u(s, \chi, u) - f_u(s, \hat\chi, u)] - \alpha\,\Omega\,\xi.$$
#
# With $\Omega$ constant and the $f_u$ difference neglected, differentiating the second
# equation and substituting the first: $\ddot z = -\alpha\Omega(\Omega^T z - h\xi) =
# -\sigma^2 z - h\dot z$, i.e. $\ddot z + h\dot z + \sigma^2 z = 0$ with $\sigma^2 = \alpha
# \|\Omega\|^2$. Holding $\sigma^2$ at $\sigma_d^2$ and choosing $h = 2\zeta\sigma_d$, the
# error is a second-order system with the poles of $\lambda^2 + h\lambda + \sigma_d^2$
# ($\zeta = 1$: a double pole at $-\sigma_d$). The neglected terms: the $f_u$ difference,
# $(v_z(\chi + \hat\chi) + y\omega_x - x\omega_y)\,z$ (planar) or $(s^T v)(\chi +
# \hat\chi)\,z$ (spherical) (from `point_depth_rate`: $a\chi^2 - a\hat\chi^2 = a(\chi +
# \hat\chi) z$), and the rotation of the direction of $\Omega$.
#
# **The active law** (designed here after the paper's statement: keep $\alpha\|\Omega\|^2$
# at a desired value). $\Omega^T(s, v) = L(s)\, v$ is linear in $v$: planar $L = [[-1, 0,
# x], [0, -1, y]]$, spherical $L = s s^T - I$ (from `point_model`). For $n$ points this
# transcription holds the MEAN $\sigma^2 = \frac{\alpha}{n}\sum_i \|L_i v\|^2 = v^T M v$,
# $M = \frac{\alpha}{n}\sum_i L_i^T L_i$ (smooth in $s$, where the minimum over the points
# is not). The linear velocity is a state of the controller, $\dot v = a$, with $a$ such
# that $\frac{d}{dt}\sigma^2 = J a + v^T \dot M v = k_\sigma(\sigma_d^2 - \sigma^2)$,
# $J = 2 v^T M$:
#
# $$a = J^+\big(k_\sigma(\sigma_d^2 - \sigma^2) - v^T \dot M v\big)
#       + (I - J^+ J)(-k_0\, v), \qquad J^+ = J^T / \|J\|^2,$$
#
# the minimum-norm solution plus a null-space damping of the part of $v$ that does not
# change $\sigma^2$ (planar, at the image centre: $v_z$; `k_null` = $k_0$, default 0).
# $\dot M$ is $M$'s derivative along $\dot s$, taken from the model with the ESTIMATE,
# $\dot s = f_m(s, \omega) + \Omega^T\hat\chi$ (the controller never sees $\chi$). With
# $\hat\chi = \chi$ the law gives $\sigma^2$ exactly the first-order response
# $k_\sigma$; with a wrong estimate the drift is off by $v^T \dot M v$ evaluated on
# $\Omega^T z$, small while the points stay near the centre.
#
# **The angular velocity** keeps the points at the image centre with the estimated depth
# (visual servoing, a wrong estimate moves the points in the image: the loop closes
# through $\hat\chi$): planar $\dot s = L_\omega(s)\,\omega + \Omega^T\hat\chi$ with the
# target $\dot s = -\lambda_s s$; spherical $\dot s = [s]_\times\omega + \Omega^T\hat\chi$
# with the target $\dot s = \lambda_s (I - s s^T) e_3$ (towards the optical axis along the
# sphere); $\omega = \mathrm{pinv}(L_\omega)(\text{target} - \Omega^T\hat\chi)$ stacked
# over the points (one point: exact; several: the least-squares compromise).


def _translation_matrix(s: Float[Array, " d"], projection: _Projection) -> Float[Array, "d 3"]:
    """$L(s)$ with $\\Omega^T(s, v) = L(s)\\,v$ (from `point_model`'s $\\Omega$)."""
    if projection == "planar":
        x, y = s[0], s[1]
        one, zero = jnp.ones_like(x), jnp.zeros_like(x)
        return jnp.stack([jnp.stack([-one, zero, x]), jnp.stack([zero, -one, y])])
    return jnp.outer(s, s) - jnp.eye(3, dtype=s.dtype)


def _rotation_matrix(s: Float[Array, " d"], projection: _Projection) -> Float[Array, "d 3"]:
    """$L_\\omega(s)$ with $f_m(s, \\omega) = L_\\omega(s)\\,\\omega$ (from `point_model`)."""
    if projection == "planar":
        x, y = s[0], s[1]
        return jnp.stack([jnp.stack([x * y, -(1 + x * x), y]), jnp.stack([1 + y * y, -x * y, -x])])
    return skew(s)


def active_sigma2(
    s: Float[ArrayLike, "n d"],
    v: Float[ArrayLike, "3"],
    alpha: Float[ArrayLike, ""],
    projection: _Projection = "planar",
) -> Float[Array, ""]:
    """$\\sigma^2 = \\frac{\\alpha}{n}\\sum_i \\|\\Omega_i(s_i, v)\\|^2$, the mean over the
    points of the error's stiffness $\\alpha\\|\\Omega\\|^2$ (the active strategy's
    controlled quantity, comment above `_translation_matrix`)."""
    s, v = jnp.asarray(s), jnp.asarray(v)
    omega = jax.vmap(lambda si: _translation_matrix(si, projection) @ v)(s)
    return jnp.asarray(alpha) * jnp.mean(jnp.sum(omega**2, axis=-1))


def active_velocity(
    s: Float[ArrayLike, "n d"],
    v: Float[ArrayLike, "3"],
    s_dot: Float[ArrayLike, "n d"],
    *,
    alpha: Float[ArrayLike, ""],
    sigma_des: Float[ArrayLike, ""],
    k_sigma: Float[ArrayLike, ""],
    k_null: Float[ArrayLike, ""] = 0.0,
    projection: _Projection = "planar",
) -> tuple[Float[Array, "3"], Float[Array, ""]]:
    """The active law: `(a, sigma2)`, the linear acceleration $\\dot v = a$ and the current
    $\\sigma^2$, such that $\\frac{d}{dt}\\sigma^2 = k_\\sigma(\\sigma_d^2 - \\sigma^2)$ along
    $\\dot s$ = `s_dot` (derived in the comment block above `_translation_matrix`):

    $$a = J^+\\big(k_\\sigma(\\sigma_d^2 - \\sigma^2) - v^T\\dot M v\\big) + (I - J^+J)(-k_0 v),$$

    $M(s) = \\frac{\\alpha}{n}\\sum_i L_i^T L_i$, $\\sigma^2 = v^T M v$, $J = 2 v^T M$,
    $\\dot M$ the derivative of $M$ along `s_dot` (forward-mode, `jax.jvp`), $J^+ = J^T /
    \\|J\\|^2$. `s` (n, d) the measured features, `v` (3,) the camera's linear velocity,
    `s_dot` (n, d) their rate (the closed loop passes the model's with the estimated
    inverse depth). Where $J = 0$ ($\\Omega = 0$: no motion across a line of sight) no
    acceleration can change $\\sigma^2$ and only the null-space term acts."""
    s, v, s_dot = jnp.asarray(s), jnp.asarray(v), jnp.asarray(s_dot)
    alpha = jnp.asarray(alpha)

    def M(s):
        Ls = jax.vmap(lambda si: _translation_matrix(si, projection))(s)  # (n, d, 3)
        return alpha * jnp.mean(jnp.einsum("nki,nkj->nij", Ls, Ls), axis=0)

    M0, M_dot = jax.jvp(M, (s,), (s_dot,))
    sigma2 = v @ M0 @ v
    J = 2 * (M0 @ v)  # (3,), d(sigma^2)/dv
    drift = v @ M_dot @ v  # the part of d(sigma^2)/dt the features' motion makes
    JJ = J @ J
    ok = JJ > 0
    safe = jnp.where(ok, JJ, 1.0)
    rate = jnp.asarray(k_sigma) * (jnp.asarray(sigma_des) ** 2 - sigma2) - drift
    a_range = jnp.where(ok, J * rate / safe, 0.0)
    a0 = -jnp.asarray(k_null) * v
    a_null = a0 - jnp.where(ok, J * (J @ a0) / safe, 0.0)
    return a_range + a_null, sigma2


def servo_angular_velocity(
    s: Float[ArrayLike, "n d"],
    v: Float[ArrayLike, "3"],
    chi_hat: Float[ArrayLike, " n"],
    lambda_s: Float[ArrayLike, ""],
    projection: _Projection = "planar",
) -> Float[Array, "3"]:
    """The angular velocity that keeps the points at the image centre with the ESTIMATED
    inverse depth: $\\omega = \\mathrm{pinv}(L_\\omega)(\\dot s^* - \\Omega^T\\hat\\chi)$,
    stacked over the points, with $\\dot s^* = -\\lambda_s s$ (planar) or $\\lambda_s (I -
    s s^T) e_3$ (spherical) (comment block above `_translation_matrix`)."""
    s, v, chi_hat = jnp.asarray(s), jnp.asarray(v), jnp.asarray(chi_hat)
    lam = jnp.asarray(lambda_s)

    def rows(si, ci):
        omega_t = _translation_matrix(si, projection) @ v
        if projection == "planar":
            target = -lam * si
        else:
            e3 = jnp.zeros_like(si).at[2].set(1.0)
            target = lam * (e3 - si * jnp.dot(si, e3))
        return _rotation_matrix(si, projection), target - omega_t * ci

    A, b = jax.vmap(rows)(s, chi_hat)
    return jnp.linalg.pinv(A.reshape(-1, 3)) @ b.reshape(-1)


class ActivePointDepthState(eqx.Module):
    """The closed loop's state: the plant, the controller and the observer together.
    `points` (n, 3) the true points in the camera frame (the simulated plant); `v` (3,)
    the controller's linear velocity (m/s, camera frame); `s_meas` (n, d) the latched
    measurement (zero-order hold of the camera); `observer` the observer's state."""

    points: Float[Array, "*batch n 3"]
    v: Float[Array, "*batch 3"]
    s_meas: Float[Array, "*batch n d"]
    observer: PointDepthState


class ActivePointDepthOutput(eqx.Module):
    """`chi_hat` (n,) the estimate, `chi` (n,) the truth, `z` (n,) $\\chi - \\hat\\chi$ (1/m);
    `sigma2` the controlled $\\sigma^2$ (1/s^2, at the measurement); `v`, `w` (3,) the
    camera's twist (m/s, rad/s); `s` (n, d) the held measurement."""

    chi_hat: Float[Array, "*batch n"]
    chi: Float[Array, "*batch n"]
    z: Float[Array, "*batch n"]
    sigma2: Float[Array, "*batch"]
    v: Float[Array, "*batch 3"]
    w: Float[Array, "*batch 3"]
    s: Float[Array, "*batch n d"]


def _project(P, noise, focal, projection):
    """The camera's measurement of points `P` (n, 3) with the image noise `noise` (n, 2)
    in pixels: normalized coordinates (planar) or their unit bearing (spherical)."""
    m = P[:, :2] / P[:, 2:] + noise / focal
    if projection == "planar":
        return m
    m = jnp.concatenate([m, jnp.ones_like(m[:, :1])], axis=1)
    return m / jnp.linalg.norm(m, axis=1, keepdims=True)


def _inverse_depth(P, projection):
    return 1.0 / (P[:, 2] if projection == "planar" else jnp.linalg.norm(P, axis=1))


class ActivePointDepth(AbstractJumpEstimator):
    """The observer of Spica et al. in a closed loop with the active strategy: a simulated
    camera whose velocity the estimate drives (comment block above `_translation_matrix`).

    How the loop is expressed on visjax's runner, unchanged: the estimator's STATE holds
    the plant (the true points in the camera frame, $\\dot P = -v - \\omega\\times P$), the
    controller (its linear velocity $v$, $\\dot v = a$ of `active_velocity`) and the
    observer (`PointDepthState`); the STREAM carries only the measurement noise (N, n, 2),
    pixels, drawn outside. `jump(state, y)` at each sample latches $s$ = the projection of
    the true points plus that sample's noise (the camera's zero-order hold);
    `vector_field` integrates the plant, the controller and the observer (its own
    `vector_field` under `PointDepthMeasurement(s, (v, w))`), with $\\omega$ =
    `servo_angular_velocity` from the held $s$ and the current estimate.

    **Fields:** `observer` a `PointDepthEstimator` (its `projection` is the loop's; its
    `chi0` the initial estimate of every point); `points0` (n, 3) the true points at the
    start (camera frame, m); `v0` (3,) the initial linear velocity (m/s); `sigma_des` the
    desired $\\sigma_d$ (1/s); `k_sigma` (1/s) the rate of $\\sigma^2$'s first-order
    convergence; `lambda_s` (1/s) the servo's gain; `focal` (px) the noise's scale;
    `k_null` (1/s) the null-space damping (default 0).

    Checks: the gains positive, every point of `points0` in front of the camera ($Z >
    0$), $\\sigma^2 > 0$ at the start (`v0` must move across a line of sight). Valid:
    every $\\hat\\chi > 0$ and every true point in front."""

    observer: PointDepthEstimator
    points0: Float[Array, "n 3"] = eqx.field(converter=jnp.asarray)
    v0: Float[Array, "3"] = eqx.field(converter=jnp.asarray)
    sigma_des: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    k_sigma: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    lambda_s: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    focal: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=600.0)
    k_null: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.0)

    def __check_init__(self):
        if jnp.ndim(self.points0) != 2 or jnp.shape(self.points0)[1] != 3:
            raise ValueError(f"`points0` must have shape (n, 3); got {jnp.shape(self.points0)}.")
        if jnp.shape(self.v0) != (3,):
            raise ValueError(f"`v0` must have shape (3,); got {jnp.shape(self.v0)}.")

    @property
    def projection(self) -> _Projection:
        return self.observer.projection

    def init(self, y0) -> ActivePointDepthState:
        s = _project(self.points0, y0, self.focal, self.projection)
        obs = self.observer.init(PointDepthMeasurement(s=s, u=jnp.zeros(6, s.dtype)))
        return ActivePointDepthState(points=self.points0, v=self.v0, s_meas=s, observer=obs)

    def jump(self, state: ActivePointDepthState, y) -> ActivePointDepthState:
        # the camera: a new image of the true points (plus this sample's noise), held
        s = _project(state.points, y, self.focal, self.projection)
        return eqx.tree_at(lambda st: st.s_meas, state, s)

    def _controls(self, state: ActivePointDepthState):
        """`(w, a, sigma2)` from the held measurement and the estimate (never the truth)."""
        s, v, chi_hat = state.s_meas, state.v, state.observer.chi_hat
        w = servo_angular_velocity(s, v, chi_hat, self.lambda_s, self.projection)
        u = jnp.concatenate([v, w])

        # the features' rate as the controller models it: with the ESTIMATED inverse depth
        def rate(si, ci):
            f_m, omega = point_model(si, u, self.projection)
            return f_m + omega * ci

        s_dot = jax.vmap(rate)(s, chi_hat)
        a, sigma2 = active_velocity(
            s,
            v,
            s_dot,
            alpha=self.observer.alpha,
            sigma_des=self.sigma_des,
            k_sigma=self.k_sigma,
            k_null=self.k_null,
            projection=self.projection,
        )
        return w, a, sigma2

    def vector_field(self, t, state: ActivePointDepthState, y) -> ActivePointDepthState:
        w, a, _ = self._controls(state)
        u = jnp.concatenate([state.v, w])
        # the plant: static points seen from the moving camera, P' = -v - w x P
        P_dot = -state.v[None, :] - jnp.cross(w[None, :], state.points)
        obs_dot = self.observer.vector_field(
            t, state.observer, PointDepthMeasurement(s=state.s_meas, u=u)
        )
        return ActivePointDepthState(
            points=P_dot, v=a, s_meas=jnp.zeros_like(state.s_meas), observer=obs_dot
        )

    def output(self, t, state: ActivePointDepthState, y) -> ActivePointDepthOutput:
        w, _, sigma2 = self._controls(state)
        chi = _inverse_depth(state.points, self.projection)
        chi_hat = state.observer.chi_hat
        return ActivePointDepthOutput(
            chi_hat=chi_hat, chi=chi, z=chi - chi_hat, sigma2=sigma2, v=state.v, w=w,
            s=state.s_meas,
        )  # fmt: skip

    def valid(self, state: ActivePointDepthState, y) -> Bool[Array, ""]:
        return jnp.all(state.observer.chi_hat > 0) & jnp.all(state.points[:, 2] > 0)

    def checks(self):
        s0 = _project(self.points0, jnp.zeros_like(self.points0[:, :2]), 1.0, self.projection)
        sigma2 = active_sigma2(s0, self.v0, self.observer.alpha, self.projection)
        front = "every point of `points0` must be in front of the camera (Z > 0)"
        across = "`v0` must move the camera across the points' lines of sight (sigma^2 > 0)"
        return (
            *self.observer.checks(),
            (self.points0[:, 2] > 0, front),
            (sigma2 > 0, across),
            (self.sigma_des > 0, "`sigma_des` must be positive"),
            (self.k_sigma > 0, "`k_sigma` must be positive"),
            (self.lambda_s > 0, "`lambda_s` must be positive"),
            (self.focal > 0, "`focal` must be positive"),
            (self.k_null >= 0, "`k_null` must be non-negative"),
        )  # fmt: skip

    def max_stable_dt(self, y):
        """Euler: the observer's bound (its `max_stable_dt`) at $\\sigma^2 = \\sigma_d^2$
        and at the start, and $2/k_\\sigma$, $2/\\lambda_s$, $2/k_0$ (first-order loops)."""
        h = self.observer.h
        sd2 = self.sigma_des**2
        disc = h**2 - 4 * sd2
        at_des = jnp.where(
            disc >= 0, 4.0 / (h + jnp.sqrt(jnp.maximum(disc, 0.0))), h / jnp.maximum(sd2, 1e-300)
        )
        s0 = _project(self.points0, y, self.focal, self.projection)
        u0 = jnp.concatenate([self.v0, jnp.zeros_like(self.v0)])
        at_start = self.observer.max_stable_dt(PointDepthMeasurement(s=s0, u=u0))
        first_order = 2.0 / jnp.maximum(
            jnp.maximum(self.k_sigma, self.lambda_s), jnp.maximum(self.k_null, 1e-300)
        )
        return jnp.minimum(jnp.minimum(at_des, at_start), first_order)
