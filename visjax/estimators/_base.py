"""The estimator contract and the one runner that serves every estimator.

An estimator is a final `eqx.Module` whose fields are its gains and constants (arrays, so
that a new value never recompiles). It has `init(y0)`, `vector_field(t, state, y)`,
`output(t, state, y)`, optionally `diagnostics`, `valid`, `checks`, `max_stable_dt` and
`step_bounds`, and a `jump` if it is an `AbstractJumpEstimator`. `run` integrates it on a
time grid of its own (`dt`), holds each measurement sample from its arrival to the next
(zero-order hold), fires `jump` when a new sample arrives, checks the state after every
step, and returns a `Solution` that always carries a result code.
"""

import abc
import math
from collections.abc import Callable
from typing import final

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int, PyTree

from .._results import RESULTS, all_finite, first_failure
from .._util import chunked_map

MAX_STEPS = 10**8
"""The most integration steps `run` (and `integration_step`) accept for one run: 1e8
steps are about a minute of the velocity estimator's loop on a CPU (~0.5 us per step) and
0.8 GB per saved float; more is a step far smaller than meant (a gain whose stability
bound needs it), refused with a `ValueError` before anything is compiled or allocated."""

MAX_SAVED_BYTES = 2**32
"""The most bytes of saved signals (`SaveAt`'s outputs, diagnostics, states and their
times) `run` accepts for one run (4 GiB; a `vmap`ped batch multiplies it): beyond it a
`ValueError` before anything is allocated (save every n-th step, or use a reducer).
Measured from the shapes (nothing is computed) for runs that save `2**16` steps or more:
below that count, reaching it would take 64 KiB per saved step."""

_SIZE_FROM = 2**16  # the saved steps from which `run` measures the saved bytes


class AbstractEstimator(eqx.Module):
    """The contract every visjax estimator fulfils.

    Required (`abc.abstractmethod`s: a subclass that lacks one cannot be instantiated):

    - `init(y0) -> State`: the initial state (a typed `eqx.Module`) from the first sample.
    - `vector_field(t, state, y) -> State`: the continuous-time law, `y` being the sample
        held since it arrived.
    - `output(t, state, y) -> Output`: what the user reads (a typed `eqx.Module`).

    Optional (the defaults say "nothing to add"):

    - `diagnostics(t, state, y)`: internal signals, saved only on request; default `None`.
    - `valid(state, y) -> bool`: the paper's standing assumptions on the state (bounded,
        positive depth estimate, ...). The runner checks it after every step and turns a
        violation into `RESULTS.diverged`. Default: always valid (finiteness is checked
        for every estimator anyway).
    - `checks() -> tuple[(bool array, message), ...]`: conditions on the gains and
        constants (positive gains, ordered bounds, a Hurwitz matrix). Checked by the
        runner under `jit` and `vmap` (`RESULTS.invalid_settings`, or an error naming the
        condition). Default: none.
    - `max_stable_dt(y) -> float array`: the largest Euler step that is stable for the
        gains (evaluated at the first sample); the runner refuses a larger step.
        Default: `inf`.
    - `step_bounds(y, sample_dt) -> tuple[(bound, what, why, result), ...]`: every bound
        on the Euler step, each with what sets it (a gain's name), what exceeding it does,
        and its result code; evaluated at the first sample `y` of a stream whose mean
        sample interval is `sample_dt`. The runner refuses a step above any of them (a
        `ValueError` naming the bound when concrete, the bound's result code under `jit`),
        and `integration_step` keeps below all of them. Default: `max_stable_dt(y)` alone,
        `RESULTS.unstable_step`. An estimator overrides it when another gain bounds the
        step too (the velocity estimator's sign gain `rho`: its chattering).

    Discrete updates when a new sample arrives (covariance resetting, a filter's
    measurement update) are a declared capability: subclass `AbstractJumpEstimator` and
    implement its `jump`.
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

    def diagnostics(self, t: Float[Array, ""], state: PyTree, y: PyTree) -> PyTree:
        """Internal signals for plots and studies (default: none)."""
        return None

    def valid(self, state: PyTree, y: PyTree) -> Bool[Array, ""]:
        """Whether `state` satisfies the estimator's standing assumptions (default: yes)."""
        return jnp.array(True)

    def checks(self) -> tuple[tuple[Bool[Array, ""], str], ...]:
        """Conditions on the gains and constants, each with the message of its violation."""
        return ()

    def max_stable_dt(self, y: PyTree) -> Float[Array, ""]:
        """The largest stable Euler step for these gains (default: no bound)."""
        return jnp.array(jnp.inf)

    def step_bounds(
        self, y: PyTree, sample_dt: Float[Array, ""]
    ) -> tuple[tuple[Float[Array, ""], str, str, RESULTS], ...]:
        """Every bound on the Euler step as `(bound, what, why, result)`: the largest step
        (s), what sets it ("the Euler stability bound", "the chattering bound of `rho`"),
        what a larger step does ("the run would diverge") and the result code of a run
        that exceeds it. Default: `max_stable_dt(y)` alone."""
        return (
            (
                self.max_stable_dt(y),
                "the Euler stability bound",
                "the run would diverge",
                RESULTS.unstable_step,
            ),
        )


class AbstractJumpEstimator(AbstractEstimator):
    """An estimator with a discrete update when a new sample arrives: `run` applies
    `jump(state, y)` at each new present sample (the first included, after `init`), before
    reading the output and integrating under that sample; not on a non-finite sample (the
    run stops there) nor after the run has failed. Covariance resetting and a
    filter's measurement update are jumps."""

    @abc.abstractmethod
    def jump(self, state: PyTree, y: PyTree) -> PyTree:
        """The state after the sample `y` arrives."""


def _as_flags(x):
    return None if x is None else jnp.asarray(x, dtype=bool)


@final
class Stream(eqx.Module):
    """A sampled measurement stream: every leaf has the sample index first.

    **Fields:**

    - `ts`: sample times, shape (N,), increasing (any rate, not necessarily uniform).
    - `ys`: the measurements the estimator sees, a pytree of arrays of leading size N; or,
        with `measure`, the raw samples the measurements are computed from.
    - `truth`: optional ground truth of leading size N, never shown to the estimator; a
        `reducer` of `run` receives it (to accumulate errors without saving outputs).
    - `present`: optional boolean (N,): `False` marks a dropped sample (a frame lost, a
        tracked point occluded). `run` treats it as if it never arrived: the estimator goes
        on holding the latest present sample and no `jump` fires. Sample 0 must be
        present. `None`: every sample is present.
    - `measure`: optional per-sample preprocessing, a callable (an `eqx.Module`, so that
        its constants are leaves: gradients flow through them and a new value never
        recompiles) mapping one raw sample of `ys` to the estimator's measurement. `run`
        applies it in chunks fused with the time loop (`jax.vmap` over the samples of a
        chunk, then the steps of that chunk), so the prepared measurements of the whole
        trajectory never exist at once: peak memory does not grow with the trajectory's
        length beyond what is saved. `None`: `ys` are the measurements.
    - `chunk`: the number of integration steps per chunk when `measure` is given (static;
        with `CheckpointAdjoint` the chunks are its checkpointed blocks instead). Larger
        chunks amortise the loop's per-chunk overhead; under `vmap` over B streams a chunk
        holds B x `chunk` prepared samples.
    """

    ts: Float[Array, " N"]
    ys: PyTree
    truth: PyTree = None
    present: Bool[Array, " N"] | None = eqx.field(default=None, converter=_as_flags)
    measure: Callable | None = None
    chunk: int = eqx.field(default=256, static=True)

    def __check_init__(self):
        if not (isinstance(self.chunk, int) and self.chunk >= 1):
            raise ValueError(f"`Stream.chunk` must be a positive int; got {self.chunk!r}.")
        if self.measure is not None and not callable(self.measure):
            raise ValueError(
                f"`Stream.measure` must be callable; got {type(self.measure).__name__}."
            )

    def measurement(self, k) -> PyTree:
        """The measurement of sample `k` (`measure` applied to the raw sample, if any)."""
        raw = jax.tree_util.tree_map(lambda x: x[k], self.ys)
        return raw if self.measure is None else self.measure(raw)

    def measured(self, batch_size: int | None = None) -> "Stream":
        """The same stream with every measurement prepared (`measure` applied to every
        sample, `batch_size` at a time), e.g. to inspect them or to feed a
        batch method; the identity without `measure`. Memory: N prepared samples."""
        if self.measure is None:
            return self
        ys = chunked_map(self.measure, self.ys, batch_size or self.chunk)
        return Stream(ts=self.ts, ys=ys, truth=self.truth, present=self.present)


def reject_mask(reject, n: int, per: int | None = None, name: str = "reject"):
    """A stream builder's `reject` argument checked: `None`, a bool array (n,) (whole
    samples), or, where the builder has `per` features, (n, per) (single features).

    **Returns:** the flags as a bool array, or `None`."""
    if reject is None:
        return None
    reject = jnp.asarray(reject)
    if reject.dtype != jnp.bool_:
        raise ValueError(
            f"`{name}` must be a boolean mask (True: rejected); got dtype {reject.dtype}."
        )
    shapes = [(n,)] + ([] if per is None else [(n, per)])
    if reject.shape not in shapes:
        want = " or ".join(str(s) for s in shapes)
        raise ValueError(f"`{name}` must have shape {want}; got {reject.shape}.")
    return reject


def rejected_samples(stream: Stream, reject) -> Stream:
    """`stream` with the samples flagged in `reject` (n,) marked absent: `run` holds the
    latest present sample over them, as over a dropped one. Sample 0 starts the run and
    cannot be rejected (an error when the flags are concrete; under `jit` the run stops
    at sample 0 with `nonfinite_measurement`)."""
    if reject is None:
        return stream
    first = _concrete(reject[0])
    if first is not None and bool(first):
        raise ValueError("`reject[0]` is True: the first sample starts the run and must be kept.")
    present = ~reject if stream.present is None else stream.present & ~reject
    return eqx.tree_at(lambda s: s.present, stream, present, is_leaf=lambda x: x is None)


def checked_samples(stream: Stream, builder: str, throw: bool) -> Stream:
    """A stream builder's `throw=True`: raise if a present sample of `stream.ys` is not
    finite (naming the first such sample when the samples are concrete), else return the
    stream unchanged. With `throw=False` nothing is checked here and `run` stops at that
    sample with `RESULTS.nonfinite_measurement`. (A missing value a builder fills or masks,
    e.g. a NaN pixel of a feature out of view, is finite by the time it is checked.)"""
    if not throw:
        return stream
    ok = jax.vmap(all_finite)(stream.ys)
    if stream.present is not None:
        ok = ok | ~stream.present
    bad = ~ok
    if isinstance(bad, jax.core.Tracer):
        where = "a sample"
    else:
        flagged = np.flatnonzero(np.asarray(bad))
        if flagged.size == 0:
            return stream
        k = int(flagged[0])
        where = f"sample {k} (t = {float(stream.ts[k]):g} s)"
    # the check rides on a measurement (the times stay concrete for `run`'s step)
    first = jax.tree_util.tree_leaves(stream.ys)[0]
    checked = eqx.error_if(
        first,
        jnp.any(bad),
        f"{builder}: {where} is not finite (a NaN or inf measurement); "
        "with throw=False the run stops there with `nonfinite_measurement`.",
    )
    return eqx.tree_at(lambda s: jax.tree_util.tree_leaves(s.ys)[0], stream, checked)


@final
class SaveAt(eqx.Module):
    """What `run` saves, and how often (a Module: a new value of a window never recompiles).

    **Fields:**

    - `every`: save at every `every`-th integration step (from the first). Static: a new
        value changes the saved shapes.
    - `outputs`, `diagnostics`, `states`: which signals to save. With none of them, only
        the final state (and a reducer's summary) come back. Saving a batch costs
        B x (saved steps) x d x 8 bytes.
    """

    every: int = eqx.field(default=1, static=True)
    outputs: bool = eqx.field(default=True, static=True)
    diagnostics: bool = eqx.field(default=False, static=True)
    states: bool = eqx.field(default=False, static=True)

    def __check_init__(self):
        if not (isinstance(self.every, int) and self.every >= 1):
            raise ValueError(f"`SaveAt.every` must be a positive int; got {self.every!r}.")

    @property
    def any(self) -> bool:
        return self.outputs or self.diagnostics or self.states


class AbstractReducer(eqx.Module):
    """Accumulates a summary over every integration step without storing the steps.

    `init(output0, truth0) -> acc` and `update(acc, t, output, truth) -> acc`; `truth` is
    the stream's ground truth of the sample held at that step.
    """

    @abc.abstractmethod
    def init(self, output0: PyTree, truth0: PyTree) -> PyTree:
        """The accumulator at the first step."""

    @abc.abstractmethod
    def update(self, acc: PyTree, t: Float[Array, ""], output: PyTree, truth: PyTree) -> PyTree:
        """The accumulator after one more step."""


@final
class WindowSummary(eqx.Module):
    """The sum of squares, the max-abs and the count of an error over a time window, per
    component."""

    sumsq: Array
    max: Array
    count: Array

    @property
    def rms(self) -> Array:
        """The RMS per component (batched or not); NaN for an empty window."""
        count = jnp.where(self.count > 0, self.count, jnp.nan)
        return jnp.sqrt(self.sumsq / count)


@final
class Innovation(eqx.Module):
    """An observer's output error (innovation) against the noise level the data imply: a
    check of an estimate without the truth (`innovation`).

    **Fields:** `output_rms` (m,): per measured output, the RMS of the observer's output
    error $y - \\hat y$; `noise_rms` (m,): the level that error would have if it were the
    measurement noise alone, the RMS of the change between consecutive samples over
    $\\sqrt2$ (for white noise $\\sigma$ it is $\\sigma$; the motion between two samples only
    adds to it), or the observer's own stated floor where larger (e.g. the chatter of a
    sign term); `ratio`: the largest `output_rms / noise_rms` (NaN without a pair of
    samples); `samples`: the samples counted. An observer tracking its measurements has
    `ratio` about 1 or below; one that lags them or has lost them, far above.
    """

    output_rms: Float[Array, " m"]
    noise_rms: Float[Array, " m"]
    ratio: Float[Array, ""]
    samples: Int[Array, ""]


def innovation(y, output_error, used=None, floor=0.0) -> Innovation:
    """The `Innovation` of an observer from its measured outputs `y` (N, m) and its output
    error `output_error` (N, m), $y - \\hat y$ at the same samples; `used` (N,) bool marks
    the samples that count (default all; a sample with a non-finite value never counts;
    the noise level is taken over pairs of consecutive counted samples); `floor` (m,) or
    scalar: the observer's own floor of the output error, the least `noise_rms`. Pure JAX
    (`jit`, `vmap`, `grad`)."""
    y = jnp.asarray(y)
    output_error = jnp.asarray(output_error)
    if y.ndim != 2 or output_error.shape != y.shape:
        raise ValueError(
            f"`y` and `output_error` must both be (N, m); got {tuple(y.shape)} and "
            f"{tuple(output_error.shape)}."
        )
    used = jnp.ones(y.shape[:1], bool) if used is None else jnp.asarray(used, bool)
    used = used & jnp.all(jnp.isfinite(y), axis=1) & jnp.all(jnp.isfinite(output_error), axis=1)
    pair = used[1:] & used[:-1]

    def rms(d, ok):
        n = jnp.maximum(jnp.sum(ok), 1).astype(d.dtype)
        return jnp.sqrt(jnp.sum(jnp.where(ok[:, None], d, 0.0) ** 2, axis=0) / n)

    output = rms(output_error, used)
    noise = jnp.maximum(rms(y[1:] - y[:-1], pair) / jnp.sqrt(2.0), floor)
    some = (jnp.sum(pair) > 0) & jnp.all(noise > 0)
    ratio = jnp.where(some, jnp.max(output / jnp.where(noise > 0, noise, 1.0)), jnp.nan)
    return Innovation(output, noise, ratio, jnp.sum(used))


@final
class WindowRMS(AbstractReducer):
    """RMS and max-abs of `output.<field> - truth` over `t_start <= t < t_end`.

    **Fields:** `t_start`, `t_end` (arrays: a new window reuses the compiled run); `field`
    the name of the output's field to compare (`None`: the output itself is an array).
    """

    t_start: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    t_end: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    field: str | None = eqx.field(default=None, static=True)

    def _error(self, output, truth):
        value = output if self.field is None else getattr(output, self.field)
        return value - truth

    def init(self, output0, truth0) -> WindowSummary:
        e = self._error(output0, truth0)
        z = jnp.zeros_like(e)
        return WindowSummary(sumsq=z, max=z, count=z)

    def over(self, ts, outputs, truth, *, skip_nan: bool = False) -> WindowSummary:
        """The same summary of saved outputs at the times `ts` (M,) against `truth` (M,
        ...): the window applied to a trajectory already computed (a baseline's, a data
        file's), so that every method is scored by one windowed RMS. `skip_nan`: leave out
        the NaN components of the error (a frame not seen in a data file) instead of
        letting them make the summary NaN (the default: a failed run is never scored)."""
        e = self._error(outputs, truth)
        inside = (ts >= self.t_start) & (ts < self.t_end)
        mask = jnp.reshape(inside, inside.shape + (1,) * (e.ndim - 1))
        mask = jnp.broadcast_to(mask, e.shape)
        if skip_nan:
            mask = mask & ~jnp.isnan(e)
        return WindowSummary(
            sumsq=jnp.sum(jnp.where(mask, e**2, 0.0), axis=0),
            max=jnp.max(jnp.where(mask, jnp.abs(e), 0.0), axis=0),
            count=jnp.sum(mask, axis=0).astype(e.dtype),
        )

    def update(self, acc: WindowSummary, t, output, truth) -> WindowSummary:
        e = self._error(output, truth)
        inside = (t >= self.t_start) & (t < self.t_end)
        return WindowSummary(
            sumsq=acc.sumsq + jnp.where(inside, e**2, 0.0),
            max=jnp.where(inside, jnp.maximum(acc.max, jnp.abs(e)), acc.max),
            count=acc.count + jnp.where(inside, 1.0, 0.0).astype(e.dtype),
        )


class AbstractAdjoint(eqx.Module):
    """How reverse-mode differentiation through `run` stores the trajectory."""


@final
class DirectAdjoint(AbstractAdjoint):
    """Store every step's residuals: fastest; reverse-mode memory grows with the steps."""


@final
class CheckpointAdjoint(AbstractAdjoint):
    """Checkpoint every `steps` integration steps (default: about the square root of the
    number of steps): reverse mode stores one state per checkpoint and recomputes one
    segment at a time, so its memory grows like the square root of the trajectory's
    length, for about one extra forward pass. Forward mode (`jax.jacfwd`) needs neither
    and is the fast path for a handful of gains."""

    steps: int | None = eqx.field(default=None, static=True)

    def __check_init__(self):
        if self.steps is not None and not (isinstance(self.steps, int) and self.steps >= 1):
            raise ValueError(
                f"`CheckpointAdjoint.steps` must be a positive int; got {self.steps!r}."
            )


@final
class Solution(eqx.Module):
    """What `run` returns (whatever `throw` says).

    **Fields:**

    - `ts`: the saved step times, or `None` if nothing is saved.
    - `outputs`, `diagnostics`, `states`: `estimator.output`, `.diagnostics` and the state
        at the saved steps (after that step's jump), each `None` unless asked for.
    - `final_state`: the state at the end (the last valid state if the run failed).
    - `summary`: the reducer's accumulator, if a reducer was given, else `None`.
    - `result`: a `RESULTS` item: `successful`, or why the run failed.
    - `failed_sample`: the index of the stream sample held when the run failed, -1 if it
        did not. After a failure the state is frozen at its last valid value.
    """

    ts: Float[Array, " M"] | None
    outputs: PyTree
    diagnostics: PyTree
    states: PyTree
    final_state: PyTree
    summary: PyTree
    result: RESULTS
    failed_sample: Int[Array, ""]


class _Carry(eqx.Module):
    """What the runner's loop carries from one integration step to the next."""

    state: PyTree  # the estimator's state (frozen at its last valid value after a failure)
    acc: PyTree  # the reducer's accumulator, or None
    result: RESULTS  # the first failure's code, or successful
    failed: Int[Array, ""]  # the sample held at the first failure, -1 if none
    count: Int[Array, ""]  # the grid step about to be taken
    k_prev: Int[Array, ""]  # the sample held at the previous step (a new one fires `jump`)
    y_held: PyTree  # the latest present measurement (with dropped samples), else None


def _check_stream(stream: Stream) -> int:
    if not isinstance(stream, Stream):
        raise ValueError(f"`stream` must be a visjax Stream; got {type(stream).__name__}.")
    ts = stream.ts
    if jnp.ndim(ts) != 1 or jnp.shape(ts)[0] < 2:
        raise ValueError(f"`stream.ts` must have shape (N,) with N >= 2; got {jnp.shape(ts)}.")
    n = jnp.shape(ts)[0]
    if stream.present is not None and jnp.shape(stream.present) != (n,):
        raise ValueError(
            f"`stream.present` must have shape ({n},), one flag per sample; got "
            f"{jnp.shape(stream.present)}."
        )
    for name, tree in (("ys", stream.ys), ("truth", stream.truth)):
        for leaf in jax.tree_util.tree_leaves(tree):
            if jnp.ndim(leaf) < 1 or jnp.shape(leaf)[0] != n:
                raise ValueError(
                    f"every leaf of `stream.{name}` must have the {n} samples of `stream.ts` "
                    f"first; got a leaf of shape {jnp.shape(leaf)}."
                )
    return n


def _concrete(x):
    """`x` as a NumPy value if it is concrete (not traced), else `None`."""
    try:
        return np.asarray(x)
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
        return None


def _n_steps(ts, dt) -> int:
    """The number of grid points t_0 + j dt up to the last sample (static)."""
    if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
        raise ValueError(f"`dt` must be a positive finite number or None; got {dt!r}.")
    ends = _concrete(ts)
    if ends is None:
        raise ValueError(
            "with `dt`, the stream's times must be concrete (not traced) to fix the number "
            "of steps: build the stream outside `jit`, or close over its times."
        )
    ends = ends[[0, -1]]
    span = float(ends[1] - ends[0])
    if not span > 0:
        raise ValueError(f"`stream.ts` must increase; got t_0 = {ends[0]}, t_N = {ends[1]}.")
    return int(math.floor(span / dt * (1 + 1e-12) + 1e-9)) + 1


def _sample_interval(ts):
    """The mean sample interval $(t_{N-1} - t_0)/(N - 1)$ (what `step_bounds` is told)."""
    return (ts[-1] - ts[0]) / (ts.shape[0] - 1)


def _first_bounds(estimator, stream):
    """`estimator.step_bounds` at the first sample, compiled on that sample alone (not the
    whole stream: one program per sample shape, whatever the stream's length): a bound
    that does not depend on the sample does not compute it (one program, not an eager op
    per line). The texts and result codes pass through as they are."""
    raw = jax.tree_util.tree_map(lambda x: x[0], stream.ys)
    return _bounds_at(estimator, raw, stream.measure, _sample_interval(stream.ts))


@eqx.filter_jit
def _bounds_at(estimator, raw, measure, interval):
    return estimator.step_bounds(raw if measure is None else measure(raw), interval)


def _step_message(estimator, h, bound, what, why) -> str:
    return (
        f"the integration step {float(h):.4g} s exceeds {what}, {float(bound):.4g} s for "
        f"{type(estimator).__name__}'s gains: {why}. Pass a smaller `dt` (the measurements "
        "are held between samples)."
    )


def _saved_bytes(estimator, stream, saveat, state0, n_saved: int) -> int:
    """The bytes `run` would allocate for `n_saved` saved steps (shapes only: nothing is
    computed). Per run: under `vmap` each element's."""

    def one(estimator, stream, state0):
        y0 = stream.measurement(0)
        state = estimator.init(y0) if state0 is None else state0
        t0 = stream.ts[0]
        return (
            estimator.output(t0, state, y0) if saveat.outputs else None,
            estimator.diagnostics(t0, state, y0) if saveat.diagnostics else None,
            state if saveat.states else None,
            t0,
        )

    shapes = eqx.filter_eval_shape(one, estimator, stream, state0)
    per_step = sum(
        math.prod(x.shape) * np.dtype(x.dtype).itemsize for x in jax.tree_util.tree_leaves(shapes)
    )
    return n_saved * per_step


def _size_message(estimator, stream, dt, n_steps: int, saved) -> str:
    """Why a run is refused for its size, with the step bound that sets the step, if any."""
    ts = _concrete(stream.ts)
    span = "the stream" if ts is None else f"{float(ts[-1] - ts[0]):.4g} s"
    grid = "the sample times" if dt is None else f"dt = {dt:.4g} s"
    size = "" if saved is None else f" and about {saved / 1e9:.3g} GB for the saved outputs"
    count = f"{n_steps:,}" if n_steps < 10**12 else f"{n_steps:.3g}"
    text = (
        f"the run would take {count} integration steps ({grid} over {span}){size}, more "
        f"than the limits (`MAX_STEPS` = {MAX_STEPS:.0e} steps, `MAX_SAVED_BYTES` = "
        f"{MAX_SAVED_BYTES / 1e9:.3g} GB of saved outputs per run)."
    )
    bounds = []
    if estimator is not None and dt is not None:
        for b, what, _, _ in _first_bounds(estimator, stream):
            b = _concrete(b)
            if b is not None and math.isfinite(float(b)):
                bounds.append((float(b), what))
    # a step between a quarter of the smallest bound and the bound follows from it
    # (`integration_step` takes half); one far below it was chosen by the caller
    if bounds and 0.25 * min(bounds)[0] <= dt <= min(bounds)[0] * (1 + 1e-9):
        b, what = min(bounds)
        return (
            f"{text} The step follows from {what} of {type(estimator).__name__}, "
            f"{b:.4g} s at these gains (`integration_step` takes half of it): a gain so "
            "large that its bound needs this step? Check the gains (a `K` or `rho` far "
            "larger than intended)."
        )
    if n_steps > MAX_STEPS:
        return f"{text} Check `dt` (is it in seconds?), or split the stream."
    return f"{text} Save every n-th step (`SaveAt(every=...)`) or use a reducer."


def _check_size(estimator, stream, dt, n_steps: int, saveat, state0):
    """Refuse, before anything is compiled or allocated, a run of more than `MAX_STEPS`
    steps or more than `MAX_SAVED_BYTES` of saved signals."""
    saved = None
    n_saved = len(range(0, n_steps, saveat.every)) if saveat.any else 0
    if n_saved >= _SIZE_FROM:  # (tracing the shapes costs ~0.1 s: not for short runs)
        saved = _saved_bytes(estimator, stream, saveat, state0, n_saved)
    if n_steps > MAX_STEPS or (saved is not None and saved > MAX_SAVED_BYTES):
        raise ValueError(_size_message(estimator, stream, dt, n_steps, saved))


@eqx.filter_jit
def _first_finite(stream):
    """Whether the first sample is finite, compiled."""
    return all_finite(stream.measurement(0))


@eqx.filter_jit
def _checked(estimator):
    """`estimator.checks()` with each condition reduced, compiled: one program instead of
    an eager operation per line (an eigendecomposition and a dozen reductions for the
    unknown input observer took seconds eagerly). The messages pass through as static."""
    return tuple((jnp.all(ok), message) for ok, message in estimator.checks())


def _precheck(estimator, stream, h_max, solver):
    """Refuse, before running, settings and steps that are concretely wrong."""
    for ok, message in _checked(estimator):
        ok = _concrete(ok)
        if ok is not None and not ok:
            raise ValueError(f"{type(estimator).__name__}: {message}")
    if isinstance(solver, diffrax.Euler):
        h = _concrete(h_max)
        if h is None:
            return
        for bound, what, why, _ in _first_bounds(estimator, stream):
            bound = _concrete(bound)
            if bound is None or h <= bound:
                continue
            # a non-finite first sample is reported by the run's result, not as a step error
            if _concrete(_first_finite(stream)):
                raise ValueError(_step_message(estimator, h, bound, what, why))
            return


def integration_step(
    stream: Stream, estimator: AbstractEstimator | None = None, *, max_step: float | None = None
) -> float | None:
    """The integration step `dt` for `run`: the one rule visjax uses when a step is not given.

    `None` (integrate at the sample times) when every sample interval is within both
    `max_step` and the step bounds of the estimator's gains (`estimator.step_bounds` at the
    first sample: the Euler stability bound `max_stable_dt`, and any other the estimator
    declares); otherwise a fixed step of `min(max_step, bound / 2)`, the samples held
    between steps. Half the bound keeps a margin where the bound is a worst case met at its
    edge. A step that would need more than `MAX_STEPS` integration steps over the stream
    raises a `ValueError` naming the bound that sets it (a gain far larger than intended),
    before anything is allocated.

    **Arguments:**

    - `stream`: the `Stream` to be run (concrete times).
    - `estimator`: the estimator whose bound applies, or `None` (no bound: e.g. when the
        estimator's gains are derived from the step itself).
    - `max_step`: the largest step the law may take (e.g. `1e-3`: the papers' 1 kHz laws
        on slower data), or `None` (no cap: the samples' own rate when stable).

    **Returns:** a Python float, or `None` for the sample times.
    """
    _check_stream(stream)
    ts = _concrete(stream.ts)
    if ts is None:
        raise ValueError("`integration_step` needs the stream's times concrete (not traced).")
    longest = float(np.max(np.diff(ts)))
    bound = math.inf
    if estimator is not None:
        for b, what, _, _ in _first_bounds(estimator, stream):
            b = float(_concrete(b))
            if not (b > 0):
                raise ValueError(
                    f"{type(estimator).__name__}: {what} is {b!r} s, no stable step exists "
                    "for these gains."
                )
            bound = min(bound, b)
    cap = math.inf if max_step is None else float(max_step)
    if not cap > 0:
        raise ValueError(f"`max_step` must be positive or None; got {max_step!r}.")
    if longest <= min(cap, bound):
        return None
    dt = min(cap, 0.5 * bound)
    n_steps = _n_steps(ts, dt)
    if n_steps > MAX_STEPS:
        raise ValueError(_size_message(estimator, stream, dt, n_steps, None))
    return dt


def _auto_step(stream: Stream, estimator: AbstractEstimator) -> float | None:
    """`run`'s `dt="auto"`: `integration_step` where the times and the gains' bounds are
    concrete, else the sample times."""
    if _concrete(stream.ts) is None:
        return None
    if any(_concrete(b) is None for b, *_ in _first_bounds(estimator, stream)):
        return None
    return integration_step(stream, estimator)


def _unroll(unroll: int, length: int) -> int:
    """`lax.scan`'s `unroll` for a loop of `length` steps (1 to `length`)."""
    return max(1, min(unroll, length))


def _scan(f, carry, length: int, adjoint: AbstractAdjoint, unroll: int = 1):
    """`lax.scan(f, carry, None, length, unroll=unroll)`, checkpointed in blocks for
    `CheckpointAdjoint`."""
    if isinstance(adjoint, DirectAdjoint) or length < 4:
        return jax.lax.scan(f, carry, None, length=length, unroll=_unroll(unroll, length))
    block = min(adjoint.steps or max(1, math.isqrt(length)), length)
    nb, rest = divmod(length, block)

    @jax.checkpoint
    def one_block(c, _):
        return jax.lax.scan(f, c, None, length=block, unroll=_unroll(unroll, block))

    carry, ys = jax.lax.scan(one_block, carry, None, length=nb)
    ys = jax.tree_util.tree_map(lambda y: y.reshape((nb * block,) + y.shape[2:]), ys)
    if rest:
        carry, ys_tail = jax.lax.scan(f, carry, None, length=rest, unroll=_unroll(unroll, rest))
        ys = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), ys, ys_tail)
    return carry, ys


def run(
    estimator: AbstractEstimator,
    stream: Stream,
    *,
    dt: float | str | None = None,
    solver: diffrax.AbstractSolver = diffrax.Euler(),
    saveat: SaveAt = SaveAt(),
    reducer: AbstractReducer | None = None,
    adjoint: AbstractAdjoint = DirectAdjoint(),
    state0: PyTree = None,
    throw: bool = True,
    unroll: int = 1,
) -> Solution:
    """Run an estimator over a sampled measurement stream.

    The time grid: with `dt=None`, the sample times themselves (one step per sample
    interval, the papers' discretisation when they sample at the estimator's rate); with a
    `dt`, the grid $t_j = t_0 + j\\,dt$ up to the last sample, whatever the stream's rate
    (30 Hz camera data under a 1 kHz law). At grid time $t_j$ the estimator holds the
    latest sample $y_k$ with $t_k \\le t_j$ (zero-order hold); when a new sample has
    arrived, `jump(state, y_k)` fires; then `output(t_j, state, y_k)` is read and the state
    is integrated to $t_{j+1}$ with one step of `solver` under the held sample (passed to
    the solver as its `args`, so the stages of a multi-stage solver never see the next
    sample; the sample index is exact, never `floor(t / dt)`).

    After every step the runner checks the held sample (finite), the new state (finite,
    `estimator.valid`) and the solver's own result; the first failure sets
    `Solution.result` and `Solution.failed_sample` and freezes the state. Before the loop,
    `estimator.checks()` (gains and constants) and, for Euler, the step against every
    bound of `estimator.step_bounds(y_0, mean sample interval)` (the Euler stability bound
    `max_stable_dt`, and e.g. the velocity estimator's chattering bound of `rho`); when
    these are concrete they raise `ValueError` before anything runs, else the run's result
    is the bound's code (`unstable_step`, `chattering_step`). Before anything is compiled
    or allocated, a run of more than `MAX_STEPS` integration steps, or whose saved signals
    would take more than `MAX_SAVED_BYTES`, raises a `ValueError` that gives the count, the
    size and the step bound that set the step, if one did.

    **Arguments:**

    - `estimator`: an `AbstractEstimator`. Its gains are array leaves: a new gain value
        reuses the compiled run, and `jax.vmap` over gains batches it.
    - `stream`: a `Stream` of N samples.
    - `dt`: the integration step (a Python float), `None` for the sample times, or
        `"auto"`: `integration_step(stream, estimator)` (the stream's own rate where the
        gains' step bounds allow it, else a held step of half the tightest bound), the one
        rule visjax uses. It needs the sample times and the gains concrete; where either
        is traced (a run inside `jit` or `vmap` over gains) it is the sample times, and a
        gain past its bound is reported by the result code (`unstable_step`). A problem
        whose data are traced chooses its step once, when it is built, by the same rule
        at its default gains.
    - `solver`: a diffrax solver with fixed steps (the sign-based laws have
        discontinuous right-hand sides: no step-size controller is used).
    - `saveat`: a `SaveAt`: which signals to save, every how many steps.
    - `reducer`: an `AbstractReducer` (e.g. `WindowRMS`) accumulated over every step.
    - `adjoint`: `DirectAdjoint()` or `CheckpointAdjoint()` (bounded reverse-mode memory).
    - `state0`: start from this state instead of `estimator.init(y_0)`.
    - `throw`: raise on failure (a runtime error with the result's message); else only
        report it in `result`.
    - `unroll`: integration steps per iteration of the compiled loop (`lax.scan`'s
        `unroll`; the results are the same). On a CPU each iteration launches a dozen small
        kernels, so for one trajectory `unroll=8` runs the loop ~1.5x faster (the
        velocity estimator: 0.8 -> 0.45 us per step); under `vmap` over hundreds of runs
        each kernel is already large and 1 (the default) is fastest; compile time grows
        with it.

    **Returns:** a `Solution`.
    """
    if not (isinstance(unroll, int) and not isinstance(unroll, bool) and unroll >= 1):
        raise ValueError(f"`unroll` must be a positive int; got {unroll!r}.")
    n = _check_stream(stream)
    if not isinstance(estimator, AbstractEstimator):
        raise ValueError(
            f"`estimator` must be a visjax AbstractEstimator; got {type(estimator).__name__}."
        )
    if isinstance(dt, str):
        if dt != "auto":
            raise ValueError(f'`dt` must be a float, None or "auto"; got {dt!r}.')
        dt = _auto_step(stream, estimator)
    if not isinstance(saveat, SaveAt):
        raise ValueError(f"`saveat` must be a visjax SaveAt; got {type(saveat).__name__}.")
    if reducer is not None and not isinstance(reducer, AbstractReducer):
        raise ValueError(f"`reducer` must be an AbstractReducer; got {type(reducer).__name__}.")
    if not isinstance(adjoint, AbstractAdjoint):
        raise ValueError(f"`adjoint` must be an AbstractAdjoint; got {type(adjoint).__name__}.")
    n_steps = n if dt is None else _n_steps(stream.ts, dt)
    present0 = None if stream.present is None else _concrete(stream.present[0])
    if present0 is not None and not present0:
        raise ValueError("`stream.present[0]` is False: the first sample must be present.")
    h_max = jnp.max(jnp.diff(stream.ts)) if dt is None else jnp.asarray(dt)
    _precheck(estimator, stream, h_max, solver)
    _check_size(estimator, stream, dt, n_steps, saveat, state0)
    plan = None if stream.measure is None else _chunk_plan(stream, dt, n_steps, saveat, adjoint)
    return _run(
        estimator, stream, dt, n_steps, plan, solver, saveat, reducer, adjoint, state0, throw,
        unroll,
    )  # fmt: skip


def _grid_arrivals(ts, dt, steps):
    """The index of the latest sample at or before each grid time `t_0 + j dt` (NumPy)."""
    ts = np.asarray(ts, dtype=np.float64)
    grid = ts[0] + np.asarray(steps, dtype=np.float64) * dt
    arrived = np.searchsorted(ts, grid + 1e-6 * dt, side="right") - 1
    return np.clip(arrived, 0, ts.shape[0] - 1)


def _chunk_plan(stream, dt, n_steps, saveat, adjoint):
    """`(steps per chunk, number of full chunks, steps left, samples per chunk)` for a
    stream with `measure`: static sizes, so that every chunk (the padded last one too)
    prepares the same number of samples. With `CheckpointAdjoint` the chunks are its
    checkpointed blocks."""
    n = jnp.shape(stream.ts)[0]
    if isinstance(adjoint, CheckpointAdjoint):
        size = adjoint.steps or max(1, math.isqrt(n_steps))
    else:
        size = stream.chunk
    if saveat.any and saveat.every > 1:
        # whole saving periods per chunk, so that every chunk saves the same steps
        size = saveat.every * max(1, round(size / saveat.every))
    size = min(size, n_steps)
    nc, rest = divmod(n_steps, size)
    if dt is None:
        return size, nc, rest, min(size, n)
    ts = _concrete(stream.ts)  # concrete: `_n_steps` has checked
    arrived = _grid_arrivals(ts, dt, np.arange(n_steps))
    # the samples a chunk needs; 2 spare for rounding between NumPy and the traced grid
    full = arrived[: nc * size].reshape(nc, size) if nc else np.zeros((0, 1), int)
    span = int((full[:, -1] - full[:, 0]).max()) + 3 if nc else 1
    tail = arrived[nc * size :]
    span_tail = int(tail[-1] - tail[0]) + 3 if rest else 1
    # (the padded last chunk is sliced with the full chunks' span, so it must cover its own)
    return size, nc, rest, min(max(span, span_tail), n)


@eqx.filter_jit
def _run(
    estimator, stream, dt, n_steps, plan, solver, saveat, reducer, adjoint, state0, throw, unroll
):
    ts, ys, truth = stream.ts, stream.ys, stream.truth
    n = ts.shape[0]
    last = n_steps - 1
    if stream.present is None:
        latest = None
    else:
        # the latest present sample at or before each sample (a dropped sample is held over)
        idx = jnp.where(stream.present, jnp.arange(n, dtype=jnp.int32), -1)
        latest = jnp.maximum(jax.lax.cummax(idx), 0).astype(jnp.int32)
    # The grid, the held sample and its arrival are computed per step from a counter, so
    # the loop carries no per-step arrays (reverse-mode memory is what `adjoint` stores).
    if dt is None:

        def grid_time(j):
            return ts[j]

        def arrived_sample(j):
            return j

        h_max = jnp.max(jnp.diff(ts))
    else:
        dt_ = jnp.asarray(dt, ts.dtype)

        def grid_time(j):
            return ts[0] + j.astype(ts.dtype) * dt_

        def arrived_sample(j):
            arrived = jnp.searchsorted(ts, grid_time(j) + 1e-6 * dt_, side="right") - 1
            return jnp.clip(jax.lax.stop_gradient(arrived), 0, n - 1).astype(jnp.int32)

        h_max = dt_

    def held_sample(j):
        """The sample the estimator holds at grid step j: the latest arrived and present."""
        k = arrived_sample(j)
        return k if latest is None else latest[k]

    def at(tree, k):
        return jax.tree_util.tree_map(lambda x: x[k], tree)

    lazy = stream.measure is not None
    if lazy:
        size, nc, rest, span = plan

        def prepare(j0, span):
            """The measurements of the `span` samples from the one held at step `j0`."""
            start = jnp.clip(arrived_sample(j0), 0, n - span)
            raw = jax.tree_util.tree_map(lambda x: jax.lax.dynamic_slice_in_dim(x, start, span), ys)
            local = jax.vmap(stream.measure)(raw)
            # each sample's finiteness, batched over the chunk (not tested again per step)
            return start, local, jax.vmap(all_finite)(local)

    # gains and constants, and the step against the declared stability bound
    checks = estimator.checks()
    settings_ok = jnp.all(jnp.stack([jnp.all(ok) for ok, _ in checks] + [jnp.array(True)]))

    def begin(y0, y0_finite):
        """The initial state, reducer and result code from the first sample `y0`."""
        state = estimator.init(y0) if state0 is None else state0
        r = RESULTS.successful
        r = RESULTS.where(~(all_finite(state) & estimator.valid(state, y0)), RESULTS.diverged, r)
        r = RESULTS.where(~all_finite(state), RESULTS.nonfinite_state, r)
        if isinstance(solver, diffrax.Euler):
            # every step bound the estimator declares (the first listed wins: the Euler
            # stability bound of the default); NaN is not within a bound
            for bound, _, _, code in reversed(estimator.step_bounds(y0, _sample_interval(ts))):
                stable = h_max <= jax.lax.stop_gradient(bound)
                r = RESULTS.where(stable, r, code)
        # a bad first sample is named as such, not by the step bound computed from it
        r = RESULTS.where(~y0_finite, RESULTS.nonfinite_measurement, r)
        if stream.present is not None:
            r = RESULTS.where(stream.present[0], r, RESULTS.nonfinite_measurement)
        r = RESULTS.where(~settings_ok, RESULTS.invalid_settings, r)
        failed = jnp.where(r == RESULTS.successful, -1, 0).astype(jnp.int32)
        acc = None
        if reducer is not None:
            acc = reducer.init(estimator.output(ts[0], state, y0), at(truth, 0))
        y_held0 = y0 if (lazy and stream.present is not None) else None
        return _Carry(
            state=state,
            acc=acc,
            result=r,
            failed=failed,
            count=jnp.zeros((), jnp.int32),
            k_prev=jnp.full((), -1, jnp.int32),
            y_held=y_held0,
        )

    term = diffrax.ODETerm(lambda t, s, y: estimator.vector_field(t, s, y))

    has_jump = isinstance(estimator, AbstractJumpEstimator)

    def eager_sample(j, y_held):
        y = at(ys, held_sample(j))
        return y, all_finite(y)

    def step(carry, save: bool, sample):
        """One integration step; `sample(j, y_held)` is the measurement held at step j
        and whether it is finite."""
        state_in, acc, j_count, y_held = carry.state, carry.acc, carry.count, carry.y_held
        # past the end (the padding of the last chunk) the last step is repeated with a
        # zero step: the state does not move, the reducer skips it, its saves are dropped
        active = j_count <= last
        j = jnp.minimum(j_count, last)
        t0 = grid_time(j)
        t1 = grid_time(jnp.minimum(j + 1, last))  # the last point is not integrated past
        k = held_sample(j)
        y, y_finite = sample(j, y_held)
        if has_jump:
            # only on a new, finite sample of a run that has not failed (after a failure
            # the state and the outputs stay frozen at their last good values)
            fresh = (k != carry.k_prev) & y_finite & (carry.failed < 0)
            state = jax.lax.cond(
                fresh, lambda s, y: estimator.jump(s, y), lambda s, y: s, state_in, y
            )
        else:
            state = state_in
        saved = None
        if save or reducer is not None:
            out = estimator.output(t0, state, y)
            if reducer is not None:
                new_acc = reducer.update(acc, t0, out, at(truth, arrived_sample(j)))
                acc = jax.tree_util.tree_map(lambda a, b: jnp.where(active, a, b), new_acc, acc)
            if save:
                saved = (
                    out if saveat.outputs else None,
                    estimator.diagnostics(t0, state, y) if saveat.diagnostics else None,
                    state if saveat.states else None,
                )
        solver_state = solver.init(term, t0, t1, state, y)
        s_new, _, _, _, solver_r = solver.step(term, t0, t1, state, y, solver_state, False)
        code = RESULTS.successful
        code = RESULTS.where(~estimator.valid(s_new, y), RESULTS.diverged, code)
        code = RESULTS.where(~all_finite(s_new), RESULTS.nonfinite_state, code)
        code = RESULTS.where(
            solver_r == diffrax.RESULTS.successful, code, RESULTS.promote(solver_r)
        )
        code = RESULTS.where(y_finite, code, RESULTS.nonfinite_measurement)
        r, failed = first_failure(carry.result, carry.failed, code, k)
        keep = failed >= 0
        state = jax.tree_util.tree_map(lambda a, b: jnp.where(keep, a, b), state_in, s_new)
        new = _Carry(
            state=state,
            acc=acc,
            result=r,
            failed=failed,
            count=j_count + 1,
            k_prev=k,
            y_held=None if y_held is None else y,
        )
        return new, saved

    def steps(carry, length: int, sample, adjoint):
        """`length` steps with the saving of `saveat`, the first at the carry's counter."""

        def plain(c, _):
            return step(c, False, sample)[0], None

        def saving_step(c, _):
            return step(c, True, sample)

        if not saveat.any:
            carry, _ = _scan(plain, carry, length, adjoint, unroll)
            return carry, None
        every = saveat.every
        if every == 1:
            return _scan(saving_step, carry, length, adjoint, unroll)

        # chunks of `every` steps: the first of each is saved; the others' outputs are not
        # computed at all (unless a reducer needs them)
        def chunk(size):
            def chunk_step(c, _):
                c, out = step(c, True, sample)
                c, _ = jax.lax.scan(
                    plain, c, None, length=size - 1, unroll=_unroll(unroll, size - 1)
                )
                return c, out

            return chunk_step

        nc, rest = divmod(length, every)
        saved = None
        if nc:
            carry, saved = _scan(chunk(every), carry, nc, adjoint)
        if rest:
            carry, tail = chunk(rest)(carry, None)
            tail = jax.tree_util.tree_map(lambda b: b[None], tail)
            saved = tail if saved is None else _concat(saved, tail)
        return carry, saved

    if not lazy:
        y0 = at(ys, 0)
        carry, saved = steps(begin(y0, all_finite(y0)), n_steps, eager_sample, adjoint)
    else:

        def held_from(prepared):
            start, local, finite = prepared

            def sample(j, y_held):
                ka = arrived_sample(j)
                y, y_finite = at((local, finite), ka - start)
                if y_held is None:
                    return y, y_finite
                # a dropped sample: the latest present one goes on being held (it was
                # tested when it arrived: a non-finite one has stopped the run there)
                here = stream.present[ka]
                y = jax.tree_util.tree_map(lambda a, b: jnp.where(here, a, b), y, y_held)
                return y, y_finite | ~here

            return sample

        def one_chunk(c, first):
            prepared = prepare(c.count, span)
            # the first chunk starts the run from its first sample (the value the loop
            # holds, to the last bit: the sign-based laws start from e - e_hat = 0
            # exactly); one chunk body, so the measurement and the step are compiled once
            fresh = begin(at(prepared[1], 0), prepared[2][0])
            c = jax.tree_util.tree_map(lambda a, b: jnp.where(first, a, b), fresh, c)
            return steps(c, size, held_from(prepared), DirectAdjoint())

        if isinstance(adjoint, CheckpointAdjoint):
            one_chunk = jax.checkpoint(one_chunk)
        # the last chunk padded to `size` steps; the carry's first value is a placeholder
        # of the right structure, replaced in the first chunk
        n_chunks = nc + (1 if rest else 0)
        like = jax.eval_shape(lambda: begin(*at(prepare(jnp.zeros((), jnp.int32), span)[1:], 0)))
        placeholder = jax.tree_util.tree_map(lambda x: jnp.zeros(x.shape, x.dtype), like)
        firsts = jnp.arange(n_chunks) == 0
        carry, saved = jax.lax.scan(one_chunk, placeholder, firsts)
        if saved is not None:
            n_saved = len(range(0, n_steps, saveat.every))
            saved = jax.tree_util.tree_map(
                lambda y: y.reshape((y.shape[0] * y.shape[1],) + y.shape[2:])[:n_saved], saved
            )
    state, acc, r, failed = carry.state, carry.acc, carry.result, carry.failed
    outputs, diagnostics, states = (None, None, None) if saved is None else saved
    saved_ts = None
    if saveat.any:
        saved_ts = jax.vmap(grid_time)(jnp.arange(0, n_steps, saveat.every, dtype=jnp.int32))
    sol = Solution(
        ts=saved_ts,
        outputs=outputs,
        diagnostics=diagnostics,
        states=states,
        final_state=state,
        summary=acc,
        result=r,
        failed_sample=failed,
    )
    if throw:
        for ok, message in checks:
            sol = eqx.error_if(sol, ~jnp.all(ok), f"{type(estimator).__name__}: {message}")
        sol = r.error_if(sol, r != RESULTS.successful)
    return sol


def _concat(a, b):
    return jax.tree_util.tree_map(lambda x, y: jnp.concatenate([x, y]), a, b)
