"""Joint trajectories of serial robots and what their encoders report (no paper here).

`follow_tool_twist` drives a six-joint arm so that its tool follows a commanded twist, by
integrating the inverse velocity kinematics $\\dot q = J^{-1}(q)[\\ldots]$ (Crane and
Duffy's eq. (4.6) in Jang's thesis); `encoder_twist` is the tool twist a robot controller
computes from quantised joint encoders; `planar_path` integrates a body that turns about
one axis in a plane (the camera of a downward-looking rig).
"""

from collections.abc import Callable
from typing import final

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from .._results import RESULTS
from .._util import as_float, check_shape
from ..kinematics import SerialChain


@final
class JointTrajectory(eqx.Module):
    """Joint angles over time.

    **Fields:** `ts` (N,); `q` (N, n) rad; `sigma_min` (N,) the smallest singular value of
    the velocity Jacobian at each sample; `result` (`singular_configuration` when
    `sigma_min` fell below the threshold, `nonfinite_output`); `failed_sample` the first
    such sample (-1 when successful).
    """

    ts: Float[Array, " N"]
    q: Float[Array, "N n"]
    sigma_min: Float[Array, " N"]
    result: RESULTS
    failed_sample: Int[Array, ""]


# Modules rather than closures: diffrax's compiled solve is reused by every call with the
# same chain, twist (if it is itself a Module or a module-level function) and lengths.


class _JointField(eqx.Module):
    chain: SerialChain
    twist: Callable
    local: bool = eqx.field(static=True)

    def __call__(self, t, q, args):
        return self.chain.inverse_velocity(q, self.twist(t), local=self.local, throw=False).qdot


class _SigmaMin(eqx.Module):
    chain: SerialChain

    def __call__(self, q):
        return self.chain.inverse_velocity(q, jnp.zeros(6, q.dtype), throw=False).sigma_min


class _Singular(eqx.Module):
    sigma_min: _SigmaMin
    threshold: float

    def __call__(self, t, q, args, **kwargs):
        return ~(self.sigma_min(q) >= self.threshold)


def follow_tool_twist(
    chain: SerialChain,
    q0: Float[ArrayLike, "6"],
    twist: Callable[[Array], Array],
    ts: Float[ArrayLike, " N"],
    *,
    local: bool = True,
    min_singular_value: float = 1e-2,
    rtol: float = 1e-10,
    atol: float = 1e-12,
) -> JointTrajectory:
    """Joint angles that make the tool follow `twist(t)` from `q0` at `ts[0]`.

    Integrates $\\dot q = J^{-1}(q)[V_{tool} - \\omega \\times (P_{tool} - P_6); \\omega]$
    (Jang's thesis, eq. (4.6)) with an 8th-order adaptive solver. A configuration whose
    Jacobian's smallest singular value is below `min_singular_value` (m) at any sample is
    a `singular_configuration` result, with the first such sample.

    **Arguments:** `chain` a six-joint `SerialChain`; `q0` (6,); `twist(t)` (6,): the
    tool's $[V; \\omega]$, in the tool frame's basis (`local=True`, e.g. a camera's own
    velocities) or in the fixed frame; `ts` (N,) output times from `ts[0]`, increasing
    (or decreasing: integrated backwards in time).

    **Returns:** a `JointTrajectory`.
    """
    q0, ts = as_float(q0), as_float(ts)
    check_shape(q0, (chain.n_joints,), "q0")
    check_shape(ts, (None,), "ts")

    sigma_min = _SigmaMin(chain)
    # stop at the first singular configuration: near it the joint rates grow without bound
    # and an adaptive solver would take ever smaller steps
    event = diffrax.Event(_Singular(sigma_min, min_singular_value))
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(_JointField(chain, twist, local)),
        diffrax.Dopri8(),
        ts[0],
        ts[-1],
        dt0=None,
        y0=q0,
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        max_steps=100_000,
        event=event,
        throw=False,
    )
    q = sol.ys  # inf after an event
    sigma = jax.vmap(sigma_min)(q)
    bad = ~(sigma >= min_singular_value)
    nonfinite = ~jnp.all(jnp.isfinite(q), axis=1)
    failed = bad | nonfinite
    first = jnp.where(jnp.any(failed), jnp.argmax(failed), -1)
    # the event stops the solve at a singular configuration (the samples after it are inf)
    stopped = sol.result == diffrax.RESULTS.event_occurred
    result = RESULTS.where(
        jnp.any(nonfinite) & ~stopped,
        RESULTS.nonfinite_output,
        RESULTS.where(jnp.any(bad), RESULTS.singular_configuration, RESULTS.successful),
    )
    solver_ok = (sol.result == diffrax.RESULTS.successful) | (
        sol.result == diffrax.RESULTS.event_occurred
    )
    result = RESULTS.where(solver_ok, result, RESULTS.promote(sol.result))
    return JointTrajectory(ts=ts, q=q, sigma_min=sigma, result=result, failed_sample=first)


def quantise(q: Float[ArrayLike, "..."], resolution) -> Float[Array, "..."]:
    """Encoder readings: `q` rounded to a multiple of `resolution` (rad per count): one
    number, or one per joint (broadcast along `q`'s last axis)."""
    if not np.all(np.asarray(resolution) > 0):
        raise ValueError(f"`resolution` must be positive; got {resolution!r}.")
    q = as_float(q)
    resolution = jnp.broadcast_to(jnp.asarray(resolution, q.dtype), q.shape)
    return jnp.round(q / resolution) * resolution


def encoder_twist(
    chain: SerialChain,
    q: Float[ArrayLike, "N 6"],
    rate_hz: float,
    *,
    resolution,
    window: int,
    local: bool = True,
) -> Float[Array, "N 6"]:
    """The tool twist a controller computes from its joint encoders, at every sample.

    The readings are `quantise(q, resolution)` (rad per count: one number or one per
    joint); the joint rates are their backward difference over `window` samples,
    $(\\tilde q_k - \\tilde q_{k-w}) / (w / f)$ (the mean rate over the last `window`
    samples: a delay of half the window); the twist is eq. (4.5) at $\\tilde q_k$. The
    first `window` samples use the first reading as the earlier one (rate 0 at sample 0).

    **Returns:** (N, 6) $[V; \\omega]$ of the tool point, in the tool frame's basis
    (`local=True`) or in $F$.
    """
    q = as_float(q)
    check_shape(q, (None, chain.n_joints), "q")
    if not (isinstance(window, int) and window >= 1):
        raise ValueError(f"`window` must be a positive integer; got {window!r}.")
    qm = quantise(q, resolution)
    earlier = jnp.concatenate([jnp.repeat(qm[:1], window, axis=0), qm[:-window]], axis=0)
    k = jnp.arange(q.shape[0])
    span = jnp.minimum(k, window).astype(q.dtype)[:, None] / rate_hz
    qdot = jnp.where(span > 0, (qm - earlier) / jnp.where(span > 0, span, 1.0), 0.0)
    return jax.vmap(lambda q, qd: chain.tool_twist(q, qd, local=local))(qm, qdot)


class _PlanarField(eqx.Module):
    v: Callable
    omega: Array
    t_ref: Array

    def __call__(self, t, c, args):
        psi = self.omega * (t - self.t_ref)
        cs, sn = jnp.cos(psi), jnp.sin(psi)
        vt = self.v(t)
        return jnp.stack([cs * vt[0] - sn * vt[1], sn * vt[0] + cs * vt[1]])


def planar_path(
    v: Callable[[Array], Array],
    omega: Float[ArrayLike, ""],
    ts: Float[ArrayLike, " N"],
    t_ref: Float[ArrayLike, ""],
) -> tuple[Float[Array, " N"], Float[Array, "N 2"]]:
    """A body turning at the constant rate `omega` (rad/s) about an axis normal to a plane
    and translating with `v(t)` (2,) in its own basis: its heading $\\psi(t)$ and position
    $c(t)$ in the plane, with $\\psi = 0$ and $c = 0$ at `t_ref`.

    $\\dot\\psi = \\omega$, $\\dot c = R(\\psi) v(t)$, $R(\\psi)$ the planar rotation;
    integrated from `ts[0]` with an 8th-order solver, minus its value at `t_ref` (read off
    the dense solution), so `omega`, `t_ref` and the times may be traced (`jit`, `grad`).
    """
    ts = as_float(ts)
    check_shape(ts, (None,), "ts")
    omega, t_ref = as_float(omega), as_float(t_ref)

    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(_PlanarField(v, omega, t_ref)),
        diffrax.Dopri8(),
        ts[0],
        ts[-1],
        dt0=None,
        y0=jnp.zeros(2, ts.dtype),
        saveat=diffrax.SaveAt(ts=ts, dense=True),
        stepsize_controller=diffrax.PIDController(rtol=1e-12, atol=1e-14),
        max_steps=100_000,
    )
    return omega * (ts - t_ref), sol.ys - sol.evaluate(t_ref)[None, :]
