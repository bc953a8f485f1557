"""Trajectories: the pose and twist of a rigid body over time."""

from collections.abc import Callable
from typing import final

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._util import as_float, check_shape
from ..kinematics import integrate_pose


@final
class Trajectory(eqx.Module):
    """A rigid body's pose and twist at sample times.

    **Fields:** `ts` (N,); `R` (N, 3, 3) and `x` (N, 3): the body's orientation and the
    position of its origin in the fixed frame; `twist` (N, 6): $[v, \\omega]$, the linear
    velocity of its origin and its angular velocity, both in the fixed frame
    ($[\\omega]_\\times = \\dot R R^T$).
    """

    ts: Float[Array, " N"]
    R: Float[Array, "N 3 3"]
    x: Float[Array, "N 3"]
    twist: Float[Array, "N 6"]


def integrate_twist(
    twist: Callable[[Array], Array],
    x0: Float[ArrayLike, "3"],
    R0: Float[ArrayLike, "3 3"],
    ts: Float[ArrayLike, " N"],
) -> Trajectory:
    """The trajectory of a body moving with `twist(t)` $= [v, \\omega]$ (fixed frame) from
    the pose `(x0, R0)` at `ts[0]`: an 8th-order solve at tolerance 1e-12
    (`visjax.kinematics.integrate_pose`)."""
    ts = as_float(ts)
    check_shape(ts, (None,), "ts")
    x, R = integrate_pose(twist, x0, R0, ts)
    return Trajectory(ts=ts, R=R, x=x, twist=_sampled(twist, ts))


@eqx.filter_jit
def _sampled(f, ts):
    return jax.vmap(f)(ts)


def sample_times(duration: float | int, rate_hz: float | int) -> Float[Array, " N"]:
    """$t_k = k / f$ for $k = 0 \\ldots \\mathrm{round}(T f) - 1$ (at least 2 samples)."""
    if not (duration > 0 and rate_hz > 0):
        raise ValueError(
            f"`duration` and `rate_hz` must be positive; got {duration!r}, {rate_hz!r}."
        )
    n = int(round(duration * rate_hz))
    if n < 2:
        raise ValueError(f"duration * rate_hz must give at least 2 samples; got {n}.")
    return jnp.arange(n, dtype=jnp.result_type(float)) / rate_hz
