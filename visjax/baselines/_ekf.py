"""A generic extended Kalman filter as one pure `jax.lax.scan` (the baselines' filter core).

The filter alternates, per sample $k$ of a stream: an update with the measurement $z_k$
(the components that are NaN are missing and skipped), then a prediction to the next
sample time in `substeps` equal steps of the model's discrete transition. The textbook
equations (not from the papers; e.g. Bar-Shalom, Li and Kirubarajan, "Estimation with
Applications to Tracking and Navigation", ch. 10):

- predict: $x \\leftarrow f(x, u, \\delta)$, $P \\leftarrow F P F^T + Q(x, u, \\delta)$, with
    $F = \\partial f / \\partial x$ (forward-mode Jacobian);
- update: $S = H P H^T + R$, $K = P H^T S^{-1}$, $x \\leftarrow x + K (z - h(x, u))$,
    $P \\leftarrow (I - K H) P (I - K H)^T + K R K^T$ (Joseph form: symmetric and positive
    semi-definite in floating point), with $H = \\partial h / \\partial x$.

A missing component gets zero innovation and a zero row of $H$: it leaves the mean and the
covariance as they are. The result code says whether the run stayed finite and valid; after
a failure the mean and covariance are frozen at their last good values.
"""

from typing import final

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float, Int, PyTree

from .._results import RESULTS, all_finite, first_failure, raise_or_keep
from .._util import as_float
from ..estimators import Solution


class AbstractEKFModel(eqx.Module):
    """The model of an extended Kalman filter: a discrete transition over a step `dt` under a
    held known input `u` (a sample of the stream's inputs, or `None`) and a measurement.

    Required: `transition(x, u, dt)`, `process_noise(x, u, dt)` ((n, n)), `measure(x, u)`
    ((m,)), `measurement_noise(x, u)` ((m, m)). Optional: `valid(x, u)` (the standing
    assumptions on the state, e.g. a positive inverse depth; default: always valid).
    """

    def transition(self, x: Float[Array, " n"], u: PyTree, dt) -> Float[Array, " n"]:
        raise NotImplementedError

    def process_noise(self, x: Float[Array, " n"], u: PyTree, dt) -> Float[Array, "n n"]:
        raise NotImplementedError

    def measure(self, x: Float[Array, " n"], u: PyTree) -> Float[Array, " m"]:
        raise NotImplementedError

    def measurement_noise(self, x: Float[Array, " n"], u: PyTree) -> Float[Array, "m m"]:
        raise NotImplementedError

    def valid(self, x: Float[Array, " n"], u: PyTree) -> Bool[Array, ""]:
        return jnp.array(True)


@final
class EKFSolution(eqx.Module):
    """What `extended_kalman_filter` returns: `ts` (N,), the filtered means `xs` (N, n) and
    covariances `Ps` (N, n, n) after each sample's update, `result` (a `RESULTS` item) and
    `failed_sample` (the sample at which the filter left its valid set or became
    non-finite, -1 if it did not)."""

    ts: Float[Array, " N"]
    xs: Float[Array, "N n"]
    Ps: Float[Array, "N n n"]
    result: RESULTS
    failed_sample: Int[Array, ""]


def _update(model, x, P, z, u):
    seen = jnp.isfinite(z)
    H = jax.jacfwd(model.measure)(x, u)
    H = jnp.where(seen[:, None], H, 0.0)
    innovation = jnp.where(seen, z - model.measure(x, u), 0.0)
    R = model.measurement_noise(x, u)
    # a missing component: a unit variance on its own, decoupled from the others
    both = seen[:, None] & seen[None, :]
    R = jnp.where(both, R, jnp.eye(R.shape[0], dtype=R.dtype))
    S = H @ P @ H.T + R
    gain = jnp.linalg.solve(S, H @ P).T  # P H^T S^{-1}, S and P symmetric
    x_new = x + gain @ innovation
    I_KH = jnp.eye(x.shape[0], dtype=x.dtype) - gain @ H
    P_new = I_KH @ P @ I_KH.T + gain @ R @ gain.T
    return x_new, 0.5 * (P_new + P_new.T)


def _predict(model, x, P, u, dt, substeps):
    def step(_, carry):
        x, P = carry
        F = jax.jacfwd(model.transition)(x, u, dt)
        Q = model.process_noise(x, u, dt)
        P = F @ P @ F.T + Q
        return model.transition(x, u, dt), 0.5 * (P + P.T)

    return jax.lax.fori_loop(0, substeps, step, (x, P))


def extended_kalman_filter(
    model: AbstractEKFModel,
    ts: Float[ArrayLike, " N"],
    zs: Float[ArrayLike, "N m"],
    us: PyTree,
    x0: Float[ArrayLike, " n"],
    P0: Float[ArrayLike, "n n"],
    *,
    present: Bool[ArrayLike, " N"] | None = None,
    substeps: int = 1,
    throw: bool = True,
) -> EKFSolution:
    """Run an extended Kalman filter over a sampled stream (one `jax.lax.scan`).

    **Arguments:**

    - `model`: an `AbstractEKFModel`.
    - `ts` (N,): the sample times (any rate; the prediction covers each interval).
    - `zs` (N, m): the measurements; a NaN component is missing at that sample and is
        skipped (an infinite one is a bad measurement: `RESULTS.nonfinite_measurement`).
    - `us`: the known inputs, a pytree of leading size N (the held input of each interval),
        or `None`.
    - `x0` (n,), `P0` (n, n): the prior at `ts[0]`, before the first update.
    - `present` (N,): `False` skips a sample's update entirely (a dropped frame).
    - `substeps`: the interval between two samples is predicted in this many equal steps
        (static: the model's transition is a discretisation at step `dt`).
    - `throw`: raise on failure (default), else return the result code.

    Works under `jit`, `vmap` (over streams, noise seeds, models) and `grad` (a
    fixed-length scan).
    """
    ts, zs, x0, P0 = (as_float(a) for a in (ts, zs, x0, P0))
    if ts.ndim != 1 or ts.shape[0] < 1:
        raise ValueError(f"`ts` must have shape (N,); got {ts.shape}.")
    n_samples = ts.shape[0]
    if zs.ndim != 2 or zs.shape[0] != n_samples:
        raise ValueError(f"`zs` must have shape ({n_samples}, m); got {zs.shape}.")
    if x0.ndim != 1:
        raise ValueError(f"`x0` must have shape (n,); got {x0.shape}.")
    n = x0.shape[0]
    if P0.shape != (n, n):
        raise ValueError(f"`P0` must have shape ({n}, {n}); got {P0.shape}.")
    us = jax.tree_util.tree_map(jnp.asarray, us)
    for leaf in jax.tree_util.tree_leaves(us):
        if jnp.ndim(leaf) < 1 or jnp.shape(leaf)[0] != n_samples:
            raise ValueError(
                f"every leaf of `us` must have leading size {n_samples}; got {jnp.shape(leaf)}."
            )
    if present is None:
        present = jnp.ones(n_samples, dtype=bool)
    present = jnp.asarray(present, dtype=bool)
    if present.shape != (n_samples,):
        raise ValueError(f"`present` must have shape ({n_samples},); got {present.shape}.")
    if not (isinstance(substeps, int) and substeps >= 1):
        raise ValueError(f"`substeps` must be a positive int; got {substeps!r}.")

    dts = jnp.diff(ts, append=ts[-1:]) / substeps
    sample = lambda tree, k: jax.tree_util.tree_map(lambda a: a[k], tree)  # noqa: E731

    def body(carry, k):
        x, P, result, failed = carry
        u = sample(us, k)
        z = zs[k]
        bad_z = jnp.any(jnp.isinf(z))
        x_u, P_u = _update(model, x, P, z, u)
        x_u = jnp.where(present[k], x_u, x)
        P_u = jnp.where(present[k], P_u, P)
        ok_u = all_finite((x_u, P_u)) & model.valid(x_u, u)
        x_p, P_p = _predict(model, x_u, P_u, u, dts[k], substeps)
        ok_p = all_finite((x_p, P_p)) & model.valid(x_p, u)
        code = RESULTS.where(
            bad_z & present[k],
            RESULTS.nonfinite_measurement,
            RESULTS.where(
                all_finite((x_u, P_u, x_p, P_p)), RESULTS.diverged, RESULTS.nonfinite_state
            ),
        )
        fails = ((bad_z & present[k]) | ~ok_u) | ~ok_p
        code = RESULTS.where(fails, code, RESULTS.successful)
        result, failed = first_failure(result, failed, code, k)
        keep = failed < 0
        x_out = jnp.where(keep, x_u, x)
        P_out = jnp.where(keep, P_u, P)
        x_next = jnp.where(keep, x_p, x)
        P_next = jnp.where(keep, P_p, P)
        return (x_next, P_next, result, failed), (x_out, P_out)

    init = (x0, P0, RESULTS.successful, jnp.array(-1))
    (_, _, result, failed), (xs, Ps) = jax.lax.scan(body, init, jnp.arange(n_samples))
    xs = raise_or_keep(result, xs, throw)
    return EKFSolution(ts=ts, xs=xs, Ps=Ps, result=result, failed_sample=failed)


def baseline_solution(ts, outputs, result, failed_sample, diagnostics=None) -> Solution:
    """A baseline's answer in the estimators' `Solution`: `outputs` per time of `ts`, the
    result code, the failed sample (-1 if none) and the baseline's own diagnostics."""
    return Solution(
        ts=ts,
        outputs=outputs,
        diagnostics=diagnostics,
        states=None,
        final_state=None,
        summary=None,
        result=result,
        failed_sample=jnp.asarray(failed_sample),
    )
