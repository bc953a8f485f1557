"""The estimator contract and the one runner that serves every estimator.

An estimator is a final `eqx.Module` whose fields are its gains and constants. It has
`init(y0)`, `vector_field(t, state, y)`, `output(t, state, y)` and optionally
`jump(state, y)`. `run` integrates each sample interval with a diffrax solver under a
zero-order hold of the measurement, applies the jumps at sample instants, and returns a
`Solution`.
"""

import abc
from collections.abc import Callable
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PyTree

from .._results import RESULTS, raise_or_keep


class AbstractEstimator(eqx.Module):
    """The contract every visjax estimator fulfils (see DESIGN.md).

    - `init(y0) -> state`: the initial state (a pytree) from the first measurement.
    - `vector_field(t, state, y) -> dstate`: the continuous-time law, `y` being the
      measurement held since the last sample.
    - `output(t, state, y) -> estimate`: what the user reads.
    - `jump(state, y) -> state`: discrete events at sample instants; identity by default.
    """

    @abc.abstractmethod
    def init(self, y0: PyTree) -> PyTree:
        """The initial state from the first measurement."""

    @abc.abstractmethod
    def vector_field(self, t: Float[Array, ""], state: PyTree, y: PyTree) -> PyTree:
        """The time derivative of the state under the held measurement `y`."""

    @abc.abstractmethod
    def output(self, t: Float[Array, ""], state: PyTree, y: PyTree) -> PyTree:
        """The estimate the user reads."""

    def jump(self, state: PyTree, y: PyTree) -> PyTree:
        """A discrete update applied when the sample `y` arrives (default: none)."""
        return state


class Stream(eqx.Module):
    """A sampled measurement stream: every leaf has the sample index first.

    **Fields:**

    - `ts`: sample times, shape (N,), increasing.
    - `ys`: the measurements the estimator sees, a pytree of arrays of leading size N.
    - `truth`: optional ground truth of leading size N, never shown to the estimator; a
        `reducer` of `run` receives it (to accumulate errors without saving outputs).
    """

    ts: Float[Array, " N"]
    ys: PyTree
    truth: PyTree = None


class Solution(eqx.Module):
    """What `run` returns.

    **Fields:**

    - `ts`: the saved sample times (every `save_every`-th), or `None`.
    - `outputs`: `estimator.output` at the saved samples (after that sample's jump), or `None`.
    - `states`: the states at the saved samples, if `save_states=True`, else `None`.
    - `final_state`: the state after the last sample.
    - `summary`: the reducer's accumulator, if a reducer was given, else `None`.
    - `result`: a `RESULTS` item, `successful` unless the state became non-finite.
    """

    ts: Float[Array, " M"] | None
    outputs: PyTree
    states: PyTree
    final_state: PyTree
    summary: PyTree
    result: RESULTS


class Reducer(eqx.Module):
    """Accumulates a summary over all samples without storing them.

    `init(output0, truth0) -> acc` and `update(acc, k, t, output, truth) -> acc` are plain
    callables (fields), so a reducer is a pytree and jits with the runner.
    """

    init: Callable[[PyTree, PyTree], PyTree]
    update: Callable[[PyTree, Array, Array, PyTree, PyTree], PyTree]


def _check_stream(stream: Stream, save_every, substeps):
    if not isinstance(stream, Stream):
        raise ValueError(f"`stream` must be a visjax Stream; got {type(stream).__name__}.")
    ts = stream.ts
    if jnp.ndim(ts) != 1 or ts.shape[0] < 2:
        raise ValueError(f"`stream.ts` must have shape (N,) with N >= 2; got {jnp.shape(ts)}.")
    n = ts.shape[0]
    for name, tree in (("ys", stream.ys), ("truth", stream.truth)):
        for leaf in jax.tree_util.tree_leaves(tree):
            if jnp.ndim(leaf) < 1 or jnp.shape(leaf)[0] != n:
                raise ValueError(
                    f"every leaf of `stream.{name}` must have the {n} samples of `stream.ts` "
                    f"first; got a leaf of shape {jnp.shape(leaf)}."
                )
    if not (isinstance(substeps, int) and substeps >= 1):
        raise ValueError(f"`substeps` must be a positive int; got {substeps!r}.")
    if save_every is not None:
        if not (isinstance(save_every, int) and save_every >= 1):
            raise ValueError(f"`save_every` must be a positive int or None; got {save_every!r}.")
        if n % save_every != 0:
            raise ValueError(
                f"`save_every` ({save_every}) must divide the number of samples ({n})."
            )
    return n


@eqx.filter_jit
def run(
    estimator: AbstractEstimator,
    stream: Stream,
    *,
    solver: diffrax.AbstractSolver = diffrax.Euler(),
    substeps: int = 1,
    save_every: int | None = 1,
    save_states: bool = False,
    reducer: Reducer | None = None,
    state0: PyTree = None,
    throw: bool = True,
) -> Solution:
    """Run an estimator over a sampled measurement stream.

    At each sample $t_k$: apply `jump(state, y_k)`, read `output(t_k, state, y_k)`, then
    integrate `vector_field` from $t_k$ to $t_{k+1}$ with `y_k` held (zero-order hold), in
    `substeps` steps of `solver`. With the defaults (Euler, one step per sample) this is
    the papers' discretisation at the sample rate. The held sample is passed to the solver
    as its `args`, so the stages of a multi-stage solver never see the next sample, and the
    sample index is the scan counter, never `floor(t / dt)`.

    **Arguments:**

    - `estimator`: an `AbstractEstimator`. Its gains are array leaves: a new gain value
        reuses the compiled run, and `jax.vmap` over gains batches it.
    - `stream`: a `Stream` of N samples.
    - `solver`: a diffrax solver with fixed steps (no step-size controller is used: the
        sign-based laws have discontinuous right-hand sides).
    - `substeps`: solver steps per sample interval.
    - `save_every`: save the output (and state) at every `save_every`-th sample; it must
        divide N. `None` saves nothing per sample (use a `reducer`). Saving all of a batch
        costs B x N x d x 8 bytes.
    - `save_states`: also save the states.
    - `reducer`: a `Reducer` accumulating a summary over every sample.
    - `state0`: start from this state instead of `estimator.init(y_0)` (to continue a run).
    - `throw`: raise if the state becomes non-finite; else report it in `result`.

    **Returns:** a `Solution`.
    """
    n = _check_stream(stream, save_every, substeps)
    ts = stream.ts
    ys = stream.ys
    truth = stream.truth
    y0 = jax.tree_util.tree_map(lambda x: x[0], ys)
    state = estimator.init(y0) if state0 is None else state0
    term = diffrax.ODETerm(lambda t, s, y: estimator.vector_field(t, s, y))
    t_next = jnp.concatenate([ts[1:], ts[-1:]])  # the last sample is not integrated past
    ks = jnp.arange(n)

    truth0 = jax.tree_util.tree_map(lambda x: x[0], truth)
    acc = None if reducer is None else reducer.init(estimator.output(ts[0], state, y0), truth0)

    def integrate(state, t0, t1, y):
        h = (t1 - t0) / substeps

        def one(i, s):
            ta = t0 + i * h
            tb = jnp.where(i == substeps - 1, t1, ta + h)
            solver_state = solver.init(term, ta, tb, s, y)
            s, _, _, _, _ = solver.step(term, ta, tb, s, y, solver_state, made_jump=False)
            return s

        if substeps == 1:
            return one(0, state)
        return jax.lax.fori_loop(0, substeps, one, state)

    def make_step(save: bool):
        """One sample: jump, read the output (only if it is saved or reduced), integrate."""

        def sample_step(carry, inp):
            state, acc = carry
            k, t0, t1, y, tr = inp
            state = estimator.jump(state, y)
            saved = None
            if save or reducer is not None:
                out = estimator.output(t0, state, y)
                if reducer is not None:
                    acc = reducer.update(acc, k, t0, out, tr)
                if save:
                    saved = (out, state if save_states else None)
            return (integrate(state, t0, t1, y), acc), saved

        return sample_step

    inputs = (ks, ts, t_next, ys, truth)
    if save_every is None or save_every == 1:
        step = make_step(save_every is not None)
        (state, acc), saved = jax.lax.scan(step, (state, acc), inputs)
        saved_ts = None if save_every is None else ts
    else:
        # Nested scans: the first sample of each chunk of `save_every` is saved; the output
        # of the others is not computed at all (unless a reducer needs it).
        chunked = jax.tree_util.tree_map(
            lambda x: x.reshape((n // save_every, save_every) + x.shape[1:]), inputs
        )
        save_step, plain_step = make_step(True), make_step(False)

        def chunk_step(carry, chunk):
            first = jax.tree_util.tree_map(lambda x: x[0], chunk)
            rest = jax.tree_util.tree_map(lambda x: x[1:], chunk)
            carry, saved = save_step(carry, first)
            carry, _ = jax.lax.scan(plain_step, carry, rest)
            return carry, saved

        (state, acc), saved = jax.lax.scan(chunk_step, (state, acc), chunked)
        saved_ts = ts[::save_every]

    outputs, states = (None, None) if saved is None else saved
    finite = jnp.all(
        jnp.stack([jnp.all(jnp.isfinite(x)) for x in jax.tree_util.tree_leaves(state)])
    )
    result = RESULTS.where(finite, RESULTS.successful, RESULTS.nonfinite_state)
    sol = Solution(
        ts=saved_ts,
        outputs=outputs,
        states=states,
        final_state=state,
        summary=acc,
        result=result,
    )
    return raise_or_keep(result, sol, throw)


def window_rms_reducer(
    t_start: float, t_end: float, error: Callable[[PyTree, PyTree], Array] | None = None
) -> Reducer:
    """A `Reducer` of the RMS and max-abs of `error(output, truth)` over `t_start <= t < t_end`.

    Its summary is a dict with `rms` and `max` (per component) and `count`. By default the
    error is `output - truth`.
    """
    if error is None:
        error = _difference

    def init(out0, truth0):
        e = error(out0, truth0)
        z = jnp.zeros_like(e)
        return {"sumsq": z, "max": z, "count": jnp.zeros((), e.dtype)}

    def update(acc, k, t, out, truth):
        e = error(out, truth)
        inside = (t >= t_start) & (t < t_end)
        return {
            "sumsq": acc["sumsq"] + jnp.where(inside, e**2, 0.0),
            "max": jnp.where(inside, jnp.maximum(acc["max"], jnp.abs(e)), acc["max"]),
            "count": acc["count"] + jnp.where(inside, 1.0, 0.0),
        }

    return Reducer(init=init, update=update)


def _difference(out: Any, truth: Any):
    return out - truth


def summary_rms(summary) -> Array:
    """The RMS per component from a `window_rms_reducer` summary (batched or not)."""
    count = jnp.maximum(summary["count"], 1.0)
    return jnp.sqrt(summary["sumsq"] / count[..., None])
