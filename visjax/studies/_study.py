"""`Study`: how a study runs (chunks, devices, job slices, durable parts, progress), one
Module that `evaluate`, `compare`, `sweep`, `tune` and `held_out` take as `study=`, so that
each of them has one short signature; `Result`, what every study returns (`.to_pandas()`);
`interruptible`, the one handler of SIGINT and SIGTERM for long studies."""

import abc
import contextlib
import sys
import threading
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh


class Refused(ValueError):
    """A study refused before it runs (an unknown or invalid grid parameter, more than
    `MAX_RUNS` runs, more memory than is available): one line."""


def parse_shard(text: str) -> tuple[int, int]:
    """`"i/N"` (a job array's slice, `Study.shard`) as `(i, N)`, 0 <= i < N. **Raises:**
    `ValueError`, one line."""
    try:
        i, n = (int(x) for x in str(text).split("/"))
    except ValueError:
        raise ValueError(f"expected i/N (e.g. 0/8), got {text!r}") from None
    if not (n >= 1 and 0 <= i < n):
        raise ValueError(f"expected i/N with 0 <= i < N, got {text!r}")
    return (i, n)


def device_mesh():
    """A one-axis `jax.sharding.Mesh` (`"runs"`) over every JAX device: `Study.mesh` for
    chunks sharded over the devices."""
    return Mesh(np.array(jax.devices()), ("runs",))


class Study(eqx.Module):
    """How a study runs; what it computes is the problem's, the points' and the keys'.

    **Fields** (every one optional; the defaults run in this process, in order, silent):

    - `chunk`: runs per compiled `vmap` call (`sweep`, `held_out`, `tune`'s sweep): the
        memory of a sweep is bounded by one chunk whatever its size (default 64).
    - `mesh`: a `jax.sharding.Mesh`: each chunk's runs sharded over its devices.
    - `shard`: `(i, n)`: only the i-th of n disjoint slices of a sweep's chunks (a job
        array's task; `merge_parts` assembles them).
    - `executor`: where a sweep's chunks run: `None` (this process) or e.g. a
        `RayExecutor`. Not with `mesh`.
    - `parts`: a folder where a sweep writes each chunk's rows as it finishes (an
        interrupted sweep keeps them); `resume=True` skips the chunks done.
    - `runs`: only these run indices of a sweep (not with `parts` or `shard`).
    - `max_memory`: bytes one chunk may need (XLA's analysis of its program), or
        `"available"`; a larger chunk is refused before any run. Default: not checked.
    - `progress`: progress bars (tqdm).
    - `log`: `line -> None` for what a study says as it goes (memory, time estimates).
    - `stop`: `() -> bool`, asked after each chunk or seed: `True` ends the study there
        with `KeyboardInterrupt`, every finished chunk written (`interruptible` gives one).
    - `repeats`: timed calls per method and key in `compare` (the median is reported;
        on the first key they follow the call that compiles).
    - `max_seconds`: `compare`'s limit on its whole run time, checked after the first key
        (`StudyTooLong`).
    """

    chunk: int = eqx.field(static=True, default=64)
    mesh: Any = eqx.field(static=True, default=None)
    shard: tuple[int, int] | None = eqx.field(static=True, default=None)
    executor: Any = eqx.field(static=True, default=None)
    parts: Any = eqx.field(static=True, default=None)
    resume: bool = eqx.field(static=True, default=False)
    runs: Sequence[int] | None = eqx.field(static=True, default=None)
    max_memory: int | float | str | None = eqx.field(static=True, default=None)
    progress: bool = eqx.field(static=True, default=False)
    log: Callable[[str], None] | None = eqx.field(static=True, default=None)
    stop: Callable[[], bool] | None = eqx.field(static=True, default=None)
    repeats: int = eqx.field(static=True, default=3)
    max_seconds: float | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        if isinstance(self.chunk, bool) or not isinstance(self.chunk, int | np.integer):
            raise ValueError(f"`Study.chunk` must be a positive int; got {self.chunk!r}.")
        if self.chunk < 1:
            raise ValueError(f"`Study.chunk` must be a positive int; got {self.chunk!r}.")
        if self.shard is not None:
            try:
                i, n = (int(x) for x in self.shard)
            except (TypeError, ValueError):
                i, n = -1, 0
            if not (n >= 1 and 0 <= i < n):
                raise ValueError(
                    f"`Study.shard` must be (i, n) with 0 <= i < n; got {self.shard!r}."
                )
        if self.executor is not None and self.mesh is not None:
            raise ValueError("`Study.executor` runs whole chunks on its workers: not with `mesh`.")
        if self.runs is not None and (self.parts is not None or self.shard is not None):
            raise ValueError("`Study.runs` (a subset of runs) is not for `parts` or `shard`.")
        if self.resume and self.parts is None:
            raise ValueError("`Study.resume=True` needs the `parts` folder of the sweep to resume.")
        if isinstance(self.repeats, bool) or not isinstance(self.repeats, int) or self.repeats < 1:
            raise ValueError(f"`Study.repeats` must be at least 1; got {self.repeats!r}.")
        if self.max_seconds is not None and not self.max_seconds > 0:
            raise ValueError(f"`Study.max_seconds` must be positive; got {self.max_seconds!r}.")


def study_of(study: Study | None, where: str, **old) -> Study:
    """The study's `Study`: `study`, or one made of the keyword arguments of the version-3
    signature (`chunk=`, `progress=`, ...; given ones only) with a `FutureWarning`."""
    given = {k: v for k, v in old.items() if v is not None}
    if study is not None and not isinstance(study, Study):
        raise ValueError(f"`study` must be a visjax.studies.Study; got {study!r}.")
    if not given:
        return Study() if study is None else study
    if study is not None:
        raise ValueError(
            f"{where}: give the options in `study=Study(...)` only; got also {sorted(given)}."
        )
    warnings.warn(
        f"{where}: the keyword argument(s) {sorted(given)} are deprecated: pass "
        f"`study=visjax.studies.Study({', '.join(f'{k}=...' for k in sorted(given))})`.",
        FutureWarning,
        stacklevel=3,
    )
    return Study(**given)


def seed_keys(keys, where: str):
    """`(typed keys, seed values)` of a study's `keys`: a 1-D array of int seeds
    (`jax.random.key(seed)` each; the seed values are the ints) or of typed PRNG keys (the
    seed values are their indices). **Raises:** `ValueError` for anything else."""
    if isinstance(keys, jax.Array) and jnp.issubdtype(keys.dtype, jax.dtypes.prng_key):
        if keys.ndim != 1 or keys.shape[0] < 1:
            raise ValueError(
                f"{where}: `keys` must be a non-empty 1-D array; got shape {keys.shape}."
            )
        return keys, np.arange(keys.shape[0])
    seeds = np.asarray(keys)
    if seeds.ndim != 1 or seeds.size < 1 or not np.issubdtype(seeds.dtype, np.integer):
        raise ValueError(
            f"{where}: `keys` must be a non-empty 1-D array of integer seeds or of typed PRNG "
            f"keys (jax.random.key); got {keys!r}."
        )
    if np.any(seeds < 0):
        raise ValueError(f"{where}: seeds must not be negative; got {seeds.tolist()}.")
    return jax.vmap(jax.random.key)(jnp.asarray(seeds)), seeds


class Result(abc.ABC):
    """What every study returns (`Evaluation`, `Comparison`, `SweepResult`, `TuneResult`):
    its rows as one `pandas.DataFrame` with `.to_pandas()`, one row per run (per key, per
    method and key, per run of a sweep, per tuning step)."""

    @abc.abstractmethod
    def to_pandas(self):
        """The rows as a `pandas.DataFrame`."""


class Interrupted(BaseException):
    """SIGINT or SIGTERM, raised where the program was (so that every `finally` runs), by
    `handling_signals`: `signum`, `name`."""

    def __init__(self, signum: int):
        import signal

        super().__init__(signum)
        self.signum = int(signum)
        self.name = signal.Signals(signum).name


class _Listener:
    """A study's `stop`: true once a signal asked it to stop."""

    def __init__(self):
        self.requested = False

    def __call__(self) -> bool:
        return self.requested


class _Handler:
    """The one handler of SIGINT and SIGTERM: while a study listens (`interruptible`), the
    first signal asks it to stop after the chunk in flight, so that no chunk is cut in the
    middle of a compiled call; otherwise (or at a second signal) it raises `interrupt` where
    the program was."""

    def __init__(self, interrupt):
        self.interrupt, self.listeners = interrupt, []

    def __call__(self, signum, frame):
        if self.listeners and not self.listeners[-1].requested:
            self.listeners[-1].requested = True
            sys.stderr.write("visjax: stopping after the chunk in flight (again: at once)\n")
            return
        if _in_gc_callback(frame):  # an exception there is printed and dropped: send again
            import os

            threading.Timer(0.05, os.kill, (os.getpid(), signum)).start()
            return
        raise self.interrupt(signum)


def _in_gc_callback(frame) -> bool:
    """Whether `frame` runs inside a garbage collector's callback (JAX registers one),
    where Python prints an exception with its traceback and drops it."""
    import gc

    codes = {getattr(cb, "__code__", None) for cb in gc.callbacks} - {None}
    while frame is not None:
        if frame.f_code in codes:
            return True
        frame = frame.f_back
    return False


@contextlib.contextmanager
def handling_signals(interrupt=Interrupted):
    """SIGINT and SIGTERM handled by the one handler inside the block: they raise
    `interrupt(signum)` where the program was (default `Interrupted`; a `KeyboardInterrupt`
    inside becomes one too), except while a study listens (`interruptible`). The previous
    handlers come back after the block; outside the main thread nothing changes."""
    import signal

    if threading.current_thread() is not threading.main_thread():
        yield None
        return
    handler = _Handler(interrupt)
    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield handler
    except KeyboardInterrupt:
        if interrupt is Interrupted:
            raise Interrupted(signal.SIGINT) from None
        raise
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


@contextlib.contextmanager
def interruptible():
    """A study that a signal stops cleanly: yields `stop` (`() -> bool`, for
    `Study(stop=stop)`), true after the first SIGINT or SIGTERM inside the block (the study
    ends after its chunk in flight with `KeyboardInterrupt`, its finished chunks written);
    a second signal interrupts at once. Under `handling_signals` (the command line) it
    listens through that handler; otherwise it installs it for the block, a signal outside
    a listening study raising `KeyboardInterrupt`. Outside the main thread nothing changes
    (the `stop` never asks)."""
    import signal

    listener = _Listener()
    if threading.current_thread() is not threading.main_thread():
        yield listener
        return
    current = signal.getsignal(signal.SIGINT)
    context = (
        contextlib.nullcontext(current)
        if isinstance(current, _Handler)
        else handling_signals(lambda signum: KeyboardInterrupt())
    )
    with context as handler:
        handler.listeners.append(listener)
        try:
            yield listener
        finally:
            handler.listeners.remove(listener)
