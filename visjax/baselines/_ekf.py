"""A generic extended Kalman filter, an estimator on `visjax.estimators.run` like the others
(the baselines' filter core): its `jump` at each new sample is the prediction from the
previous sample's time in `substeps` equal steps of the model's discrete transition, then
the update with the measurement $z_k$ (the components that are NaN are missing and
skipped). The textbook
equations (not from the papers; e.g. Bar-Shalom, Li and Kirubarajan, "Estimation with
Applications to Tracking and Navigation", ch. 10):

- predict: $x \\leftarrow f(x, u, \\delta)$, $P \\leftarrow F P F^T + Q(x, u, \\delta)$, with
    $F = \\partial f / \\partial x$ (forward-mode Jacobian);
- update: $S = H P H^T + R$, $K = P H^T S^{-1}$, $x \\leftarrow x + K (z - h(x, u))$,
    $P \\leftarrow (I - K H) P (I - K H)^T + K R K^T$ (Joseph form: symmetric and positive
    semi-definite in floating point), with $H = \\partial h / \\partial x$.

A missing component gets zero innovation and a zero row of $H$: it leaves the mean and the
covariance as they are.

The outlier gate (optional, `gate`): the measurement's components come in blocks of
`gate_size` (a feature's two pixel coordinates); a block $g$ whose squared Mahalanobis
distance $\\nu_g^T S_{gg}^{-1} \\nu_g$ (its innovation against its block of $S$, all seen
components' $S$) exceeds the `gate` quantile of the $\\chi^2$ distribution with
`gate_size` degrees of freedom is rejected: treated as missing in this update (the
textbook validation gate, Bar-Shalom et al., ch. 2.3).

The runner's result code says whether the run stayed finite and valid (`model.valid`);
after a failure the mean and covariance are frozen at their last good values.
"""

from typing import final

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, PyTree

from .._util import as_float
from ..estimators import (
    AbstractJumpEstimator,
    Solution,
    Stream,
    checked_samples,
    reject_mask,
    run,
)


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


def chi2_quantile(p, dof: int):
    """The `p` quantile of the $\\chi^2$ distribution with `dof` degrees of freedom (closed
    forms for 1 and 2; else bisection on the regularised incomplete gamma function)."""
    p = jnp.asarray(p)
    if dof == 1:
        return jax.scipy.special.ndtri(0.5 * (1.0 + p)) ** 2
    if dof == 2:
        return -2.0 * jnp.log1p(-p)

    def bisect(_, bounds):
        lo, hi = bounds
        mid = 0.5 * (lo + hi)
        below = jax.scipy.special.gammainc(0.5 * dof, 0.5 * mid) < p
        return jnp.where(below, mid, lo), jnp.where(below, hi, mid)

    hi = jnp.asarray(dof + 100.0 * (dof + 1.0), p.dtype)  # well past any quantile < 1 - 1e-20
    lo, hi = jax.lax.fori_loop(0, 200, bisect, (jnp.zeros_like(hi), hi))
    return 0.5 * (lo + hi)


def _innovation(model, x, P, z, seen, u):
    H = jax.jacfwd(model.measure)(x, u)
    H = jnp.where(seen[:, None], H, 0.0)
    innovation = jnp.where(seen, z - model.measure(x, u), 0.0)
    R = model.measurement_noise(x, u)
    # a missing component: a unit variance on its own, decoupled from the others
    both = seen[:, None] & seen[None, :]
    R = jnp.where(both, R, jnp.eye(R.shape[0], dtype=R.dtype))
    return H, innovation, R, H @ P @ H.T + R


def _gated(innovation, S, seen, gate, size):
    """The seen components whose block passes the gate (module docstring)."""
    m = innovation.shape[0]
    blocks = m // size
    nu = innovation.reshape(blocks, size)
    S_gg = jax.vmap(lambda g: jax.lax.dynamic_slice(S, (g * size, g * size), (size, size)))(
        jnp.arange(blocks)
    )
    seen_g = seen.reshape(blocks, size)
    # a block's components not seen: unit variance, zero innovation (decoupled already)
    d2 = jax.vmap(lambda v, Sg: v @ jnp.linalg.solve(Sg, v))(nu, S_gg)
    passed = d2 <= chi2_quantile(gate, size).astype(S.dtype)
    keep = seen_g & passed[:, None]
    rejected = jnp.sum(jnp.any(seen_g, axis=1) & ~passed)
    return keep.reshape(m), rejected


def _update(model, x, P, z, seen, u, gate=None, gate_size=1):
    """The update; with `gate`, also the number of blocks the gate rejected."""
    H, innovation, R, S = _innovation(model, x, P, z, seen, u)
    rejected = jnp.zeros((), jnp.int32)
    if gate is not None:
        keep, rejected = _gated(innovation, S, seen, gate, gate_size)
        H, innovation, R, S = _innovation(model, x, P, z, keep, u)
    gain = jnp.linalg.solve(S, H @ P).T  # P H^T S^{-1}, S and P symmetric
    x_new = x + gain @ innovation
    I_KH = jnp.eye(x.shape[0], dtype=x.dtype) - gain @ H
    P_new = I_KH @ P @ I_KH.T + gain @ R @ gain.T
    return x_new, 0.5 * (P_new + P_new.T), rejected.astype(x.dtype)


def _predict(model, x, P, u, dt, substeps):
    def step(_, carry):
        x, P = carry
        F = jax.jacfwd(model.transition)(x, u, dt)
        Q = model.process_noise(x, u, dt)
        P = F @ P @ F.T + Q
        return model.transition(x, u, dt), 0.5 * (P + P.T)

    return jax.lax.fori_loop(0, substeps, step, (x, P))


def _optional_float(x):
    return None if x is None else as_float(x)


@final
class EKFSample(eqx.Module):
    """One sample (in a `Stream`, all samples: a leading axis) of an EKF's stream: its time
    `t`, the measurement `z` (m,) with its missing components set to 0, which components
    were `seen` (m,) bool, and the known input `u` held from this sample to the next (or
    `None`)."""

    t: Float[Array, "*batch"]
    z: Float[Array, "*batch m"]
    seen: Bool[Array, "*batch m"]
    u: PyTree


@final
class EKFState(eqx.Module):
    """The filter's mean `x` and covariance `P` after the update at time `t`, the input
    `u` held since then (the next prediction's), and the number of measurement blocks the
    outlier gate has `rejected` so far (a float holding a whole number: the state is moved by
    the runner's integrator, between samples by nothing)."""

    x: Float[Array, " n"]
    P: Float[Array, "n n"]
    t: Float[Array, ""]
    u: PyTree
    rejected: Float[Array, ""]


@final
class EKFOutput(eqx.Module):
    """The filtered mean `x` (n,) and covariance `P` (n, n) after a sample's update, and the
    number of measurement blocks the outlier gate has `rejected` up to it."""

    x: Float[Array, "*batch n"]
    P: Float[Array, "*batch n n"]
    rejected: Float[Array, "*batch"]


@final
class ExtendedKalmanFilter(AbstractJumpEstimator):
    """An extended Kalman filter as an estimator on `visjax.estimators.run`: its `jump` (at
    each new sample) predicts from the previous sample's time to this one's in `substeps`
    equal steps of the model's transition under the input held since then, then updates
    with the sample's measurement (module docstring); between samples nothing moves.

    **Fields:** `model` (an `AbstractEKFModel`), the prior `x0` (n,) and `P0` (n, n) at the
    first sample (before its update), `substeps` (static); `gate`: `None` (default: every
    seen component is used) or the probability of the outlier gate (e.g. 0.999: a block
    of the measurement further than that quantile of $\\chi^2_{\\text{gate\\_size}}$ in
    Mahalanobis distance is rejected, module docstring); `gate_size` (static): the
    components per block (2: a feature's pixel pair), dividing the measurement's size.
    Its stream's samples are `EKFSample`s (`ekf_stream` builds them); run it at the sample
    times (`dt=None`).
    """

    model: AbstractEKFModel
    x0: Float[Array, " n"] = eqx.field(converter=as_float)
    P0: Float[Array, "n n"] = eqx.field(converter=as_float)
    substeps: int = eqx.field(default=1, static=True)
    gate: Float[Array, ""] | None = eqx.field(default=None, converter=_optional_float)
    gate_size: int = eqx.field(default=2, static=True)

    def __check_init__(self):
        if self.x0.ndim != 1:
            raise ValueError(f"`x0` must have shape (n,); got {self.x0.shape}.")
        n = self.x0.shape[0]
        if self.P0.shape != (n, n):
            raise ValueError(f"`P0` must have shape ({n}, {n}); got {self.P0.shape}.")
        if not (isinstance(self.substeps, int) and self.substeps >= 1):
            raise ValueError(f"`substeps` must be a positive int; got {self.substeps!r}.")
        if not (isinstance(self.gate_size, int) and self.gate_size >= 1):
            raise ValueError(f"`gate_size` must be a positive int; got {self.gate_size!r}.")
        if self.gate is not None:
            if self.gate.shape != ():
                raise ValueError(f"`gate` must be a scalar probability; got {self.gate.shape}.")
            try:
                value = float(np.asarray(self.gate))
            except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
                value = None  # traced: `checks` gives the result code
            if value is not None and not (0.0 < value < 1.0):
                raise ValueError(
                    f"`gate` must be a probability strictly between 0 and 1; got {value}."
                )

    def checks(self):
        if self.gate is None:
            return ()
        return ((jnp.isfinite(self.gate) & (self.gate > 0.0) & (self.gate < 1.0),
                 "`gate` must be a probability strictly between 0 and 1."),)  # fmt: skip

    def init(self, y0: EKFSample) -> EKFState:
        return EKFState(x=self.x0, P=self.P0, t=y0.t, u=y0.u, rejected=jnp.zeros((), self.x0.dtype))

    def vector_field(self, t, state: EKFState, y: EKFSample) -> EKFState:
        return jax.tree_util.tree_map(jnp.zeros_like, state)

    def jump(self, state: EKFState, y: EKFSample) -> EKFState:
        gap = y.t - state.t  # 0 at the first sample: no prediction
        x_p, P_p = _predict(self.model, state.x, state.P, state.u, gap / self.substeps,
                            self.substeps)  # fmt: skip
        later = gap > 0
        x = jnp.where(later, x_p, state.x)
        P = jnp.where(later, P_p, state.P)
        z_size = y.z.shape[0]
        if self.gate is not None and z_size % self.gate_size:
            raise ValueError(
                f"`gate_size` {self.gate_size} must divide the measurement's size {z_size}."
            )
        x, P, rejected = _update(self.model, x, P, y.z, y.seen, y.u, self.gate, self.gate_size)
        return EKFState(x=x, P=P, t=y.t, u=y.u, rejected=state.rejected + rejected)

    def output(self, t, state: EKFState, y: EKFSample) -> EKFOutput:
        return EKFOutput(x=state.x, P=state.P, rejected=state.rejected)

    def valid(self, state: EKFState, y: EKFSample):
        return self.model.valid(state.x, y.u)


def ekf_stream(
    ts: Float[ArrayLike, " N"],
    zs: Float[ArrayLike, "N m"],
    us: PyTree = None,
    *,
    present: Bool[ArrayLike, " N"] | None = None,
    reject: Bool[ArrayLike, " N"] | Bool[ArrayLike, "N m"] | None = None,
    throw: bool = True,
) -> Stream:
    """The `Stream` of an `ExtendedKalmanFilter` from its measurements.

    **Arguments:** `ts` (N,) the sample times (any rate); `zs` (N, m) the measurements, a
    NaN component missing at that sample (its update skipped); `us` the known inputs, a
    pytree of leading size N (the held input of each interval), or `None`; `present` (N,):
    `False` skips a sample's update entirely (a dropped frame; the prediction still covers
    its interval); `reject`: what an outlier test rejected, skipped as missing: (N,) whole
    samples (their update), (N, m) single components; `throw`: an infinite measurement
    component (a bad measurement, not a
    missing one) raises here, naming the sample; with `throw=False` `run` stops there with
    `RESULTS.nonfinite_measurement`.
    """
    ts, zs = as_float(ts), as_float(zs)
    if ts.ndim != 1 or ts.shape[0] < 1:
        raise ValueError(f"`ts` must have shape (N,); got {ts.shape}.")
    n_samples = ts.shape[0]
    if zs.ndim != 2 or zs.shape[0] != n_samples:
        raise ValueError(f"`zs` must have shape ({n_samples}, m); got {zs.shape}.")
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
    reject = reject_mask(reject, n_samples, zs.shape[1])
    if reject is not None:
        present = present & ~reject if reject.ndim == 1 else present
        zs = jnp.where(reject, jnp.nan, zs) if reject.ndim == 2 else zs
    # a dropped sample is an update with nothing seen (the mean and covariance unchanged)
    seen = ~jnp.isnan(zs) & present[:, None]
    z = jnp.where(seen, zs, 0.0)
    ys = EKFSample(t=ts, z=z, seen=seen, u=us)
    return checked_samples(Stream(ts=ts, ys=ys), "ekf_stream", throw)


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
    gate: float | ArrayLike | None = None,
    gate_size: int = 2,
    throw: bool = True,
) -> Solution:
    """Run an extended Kalman filter over a sampled stream: `run(ExtendedKalmanFilter(model,
    x0, P0, substeps, gate, gate_size), ekf_stream(ts, zs, us, present=present))` at the
    sample times.

    **Arguments:** as `ExtendedKalmanFilter` and `ekf_stream`; `x0` (n,), `P0` (n, n) the
    prior at `ts[0]`, before the first update; `gate`, `gate_size`: the outlier gate
    (`None`: off); `throw`: raise on failure (default), else return the result code.

    **Returns:** the runner's `Solution`: `outputs` an `EKFOutput` per sample (the mean and
    covariance after its update), `result`, `failed_sample` (the sample at which the
    filter left its valid set or became non-finite; a failed prediction is reported at the
    sample it predicts to), the outputs frozen at the last good values after a failure.
    Works under `jit`, `vmap` (over streams, noise seeds, models) and `grad`.
    """
    if isinstance(gate, (int, float)) and not (0.0 < gate < 1.0):
        raise ValueError(f"`gate` must be a probability strictly between 0 and 1; got {gate}.")
    filt = ExtendedKalmanFilter(
        model=model, x0=x0, P0=P0, substeps=substeps, gate=gate, gate_size=gate_size
    )
    stream = ekf_stream(ts, zs, us, present=present, throw=False)
    return run(filt, stream, dt=None, throw=throw)


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
