"""`sweep`: any estimator or baseline over a batch of parameter points and noise seeds, in
chunks of `vmap`, optionally sharded over the devices of a `jax.sharding.Mesh` (also across
processes started with `jax.distributed`), as a tidy table: one row per run.

Helpers build the parameter points: `grid` (the Cartesian product of axes), `log_axis`
(log-spaced values, for gains), `parse_grid` (the command line's `"K=1e-2:1e1:8,rho=..."`)
and `random_points` (log-uniform samples).
"""

import math
import os
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import NamedSharding, PartitionSpec

from .._results import RESULTS, all_finite
from .._xla_workaround import warn_if_hang_prone
from ._parts import Parts
from ._problem import (
    AbstractProblem,
    FunctionProblem,
    check_values,
    component_names,
    run_identity,
    runner,
)
from ._study import Refused, Result, Study, study_of


def log_axis(low: float | int, high: float | int, num: int) -> np.ndarray:
    """`num` log-spaced values from `low` to `high` (both included, both positive)."""
    if not (low > 0 and high > 0):
        raise ValueError(f"a log axis needs positive ends; got {low} and {high}.")
    if num < 1:
        raise ValueError(f"a log axis needs at least one value; got num={num}.")
    return np.geomspace(low, high, num)


def grid(**axes: Any) -> dict[str, np.ndarray]:
    """The Cartesian product of the axes: `grid(K=[1, 2], rho=[3, 4, 5])` gives six points,
    `{"K": [1, 1, 1, 2, 2, 2], "rho": [3, 4, 5, 3, 4, 5]}` (the last axis fastest)."""
    if not axes:
        raise ValueError("`grid` needs at least one axis.")
    values = [np.asarray(v, float).ravel() for v in axes.values()]
    for name, v in zip(axes, values):
        if v.size == 0:
            raise ValueError(f"axis `{name}` of the grid is empty.")
    mesh = np.meshgrid(*values, indexing="ij")
    return {name: m.ravel() for name, m in zip(axes, mesh)}


def parse_grid(spec: str) -> dict[str, np.ndarray]:
    """The grid of a command-line spec: comma-separated `name=low:high:num` (a log axis,
    `log_axis(low, high, num)`) or `name=v1/v2/...` (listed values) or `name=v` (one value);
    the Cartesian product of all axes (`grid`).

    `parse_grid("K=1e-2:1e1:4,rho=0.1/1")` gives 8 points."""
    axes = {}
    for part in [p.strip() for p in spec.split(",") if p.strip()]:
        if "=" not in part:
            raise ValueError(f"grid axis {part!r} must read name=low:high:num or name=v1/v2.")
        name, body = (s.strip() for s in part.split("=", 1))
        if not name or name in axes:
            raise ValueError(f"grid axis name {name!r} is empty or repeated in {spec!r}.")
        if ":" in body:
            bits = body.split(":")
            if len(bits) != 3:
                raise ValueError(
                    f"grid axis {part!r}: a log axis reads name=low:high:num, three numbers "
                    f"(e.g. {name}=0.01:10:8); got {len(bits)}"
                )
            low, high = (_grid_number(b, part, float) for b in bits[:2])
            num = _grid_number(bits[2], part, int)
            try:
                axes[name] = log_axis(low, high, num)
            except ValueError as err:
                raise ValueError(f"grid axis {part!r}: {err}") from None
        else:
            axes[name] = np.array([_grid_number(v, part, float) for v in body.split("/")])
    if not axes:
        raise ValueError(f"the grid spec {spec!r} names no axis.")
    return grid(**axes)


def _grid_number(text: str, part: str, kind):
    """One number of a grid axis `part`, or a `ValueError` naming it."""
    try:
        return kind(text.strip())
    except ValueError:
        what = "a whole number of points" if kind is int else "a number"
        raise ValueError(f"grid axis {part!r}: {text.strip()!r} is not {what}") from None


def random_points(key, num: int, **ranges: Any) -> dict[str, np.ndarray]:
    """`num` points drawn log-uniformly: `random_points(key, 64, K=(1e-2, 10), rho=(0.1,
    10))` (a random search; better than a grid when few parameters matter)."""
    if num < 1:
        raise ValueError(f"`num` must be at least 1; got {num}.")
    out = {}
    for name, key_i in zip(ranges, jax.random.split(key, len(ranges))):
        low, high = ranges[name]
        if not (0 < low < high):
            raise ValueError(f"range of `{name}` must satisfy 0 < low < high; got {ranges[name]}.")
        u = np.asarray(jax.random.uniform(key_i, (num,), dtype=jnp.float64))
        out[name] = np.exp(np.log(low) + u * (np.log(high) - np.log(low)))
    return out


def _leaf_name(path) -> str:
    parts = []
    for entry in path:
        for attr in ("key", "name", "idx"):
            if hasattr(entry, attr):
                parts.append(str(getattr(entry, attr)))
                break
    return ".".join(parts)


def _columns(name: str, values: np.ndarray, names=None) -> dict[str, np.ndarray]:
    """A (R, ...) array as table columns, one per component, never list-valued: `name`
    for scalars; for a vector or matrix the names `names` gives (a problem's `columns`
    entry for `name`, `component_names`), else `name_i` (`name_i_j`)."""
    values = np.asarray(values)
    if values.ndim == 1:
        return {name: values}
    flat = values.reshape(values.shape[0], -1)
    return dict(zip(component_names(name, values.shape[1:], names), flat.T, strict=True))


def solution_outputs(solution) -> dict:
    """A solution's saved outputs by field name: a `Solution`'s `outputs`, or for a
    method whose solution is its own Module (a per-frame baseline's: `ts`, its estimates,
    `result`), its fields but `ts` and `result`."""
    if hasattr(solution, "outputs"):
        outputs = solution.outputs
        return dict(outputs) if isinstance(outputs, dict) else vars(outputs)
    return {k: v for k, v in vars(solution).items() if k not in ("ts", "result")}


def solution_table(solution, problem=None, method: str | None = None) -> dict[str, np.ndarray]:
    """The saved outputs of one solution (`studies.solution`) as table columns: `t`, then
    each output field's components (the problem's `columns` names: `v_x`, ..., else
    `name_i`), and where the problem knows it (`AbstractProblem.truth_outputs`) the truth
    beside each as `<column>_true`; for a pandas `DataFrame`. Fields not saved at every
    time are left out. A method whose solution is its own Module (a per-frame baseline's,
    without `outputs`) gives its fields (`solution_outputs`)."""
    table = {"t": np.asarray(solution.ts)}
    columns = {} if problem is None else problem.columns
    truth = {} if problem is None else problem.truth_outputs(method, solution)
    for name, v in solution_outputs(solution).items():
        if v is None or np.ndim(v) < 1:
            continue
        v = np.asarray(v)
        if v.shape[0] == table["t"].shape[0]:
            table.update(_columns(name, v, columns.get(name)))
            if truth.get(name) is not None:
                true = np.broadcast_to(np.asarray(truth[name]), v.shape)
                named = _columns(name, true, columns.get(name))
                table.update({f"{k}_true": x for k, x in named.items()})
    return table


def _key_data(keys) -> np.ndarray:
    """Seeds (ints) or typed PRNG keys -> their raw key data, one row per seed."""
    keys = jnp.asarray(keys) if not isinstance(keys, jax.Array) else keys
    if jnp.issubdtype(keys.dtype, jax.dtypes.prng_key):
        return np.asarray(jax.random.key_data(keys))
    if not jnp.issubdtype(keys.dtype, jnp.integer) or keys.ndim != 1:
        raise ValueError(
            "`keys` must be a 1-D array of integer seeds or of typed PRNG keys "
            f"(jax.random.key); got dtype {keys.dtype} and shape {keys.shape}."
        )
    return np.asarray(jax.random.key_data(jax.vmap(jax.random.key)(keys)))


_STUDY_OPTIONS = (
    "chunk", "mesh", "progress", "runs", "parts", "resume", "shard", "executor", "max_memory",
    "log", "stop",
)  # fmt: skip


def sweep(
    problem,
    points: Any,
    keys: Any,
    *,
    method: str | None = None,
    fixed: Mapping[str, Any] | None = None,
    study: Study | None = None,
    metrics: Callable[[Any], Mapping[str, jax.Array]] | None = None,
    **old: Any,
) -> "SweepResult":
    """One method of `problem` at every parameter point for every noise key, batched, as a
    table.

    `sweep(problem, points, keys, method=..., fixed=..., study=Study(...))`: one method
    (default: the estimator) of an `AbstractProblem`; `points` names some of its
    parameters (a dict name -> values with a common leading axis), `fixed` others (one
    value for every run), the rest keep their defaults. Every value is checked (finite;
    positive where the parameter must be) before any run. A compiled chunk is reused by a
    rebuilt problem with equal shapes and settings (its arrays are traced). A plain
    function joins as a `FunctionProblem` (its points any pytree).

    **Runs and their noise.** Run `i` is parameter point `i // S` with noise seed
    `i % S` (S seeds; the seed fastest), and its noise is drawn from that seed's key alone
    (`jax.random.key(seed)`, or the typed key given): every point sees the same noise at a
    given seed (common random numbers, so that gains are compared on identical draws), and
    a run's row depends on nothing but its index, whatever chunk, order, process or
    machine computes it (`runs`, `shard`, `executor`).

    **Arguments:**

    - `problem`: an `AbstractProblem`; its `metrics` are computed inside the batch
        (floating scalars or small arrays; an array becomes one column per component,
        named by the problem's `columns`, else `name_i`); a solution's `failed_sample`,
        if it has one, goes into the table.
    - `points`: name -> values with a common leading axis P (the points; `grid`,
        `parse_grid` or `random_points` build one; a `FunctionProblem`'s: any pytree).
    - `keys`: S noise seeds: a 1-D array of ints (`jax.random.key(seed)` each) or of typed
        PRNG keys (the table's `seed` column is then the index).
    - `study`: a `Study`, how the sweep runs; its fields:
    - `chunk`: runs per compiled `vmap` call (rounded up to a multiple of the mesh's device
        count): memory is bounded by one chunk whatever P x S is. Chunk `c` holds runs
        `c * chunk` to `(c + 1) * chunk - 1`; the last is padded with repeats of the last
        run (discarded), so one compilation serves every chunk; a sweep smaller than
        `chunk` runs as one chunk of the next power of two. The compiled chunk is cached
        per (`factory`, `metrics`, structure of `params`, `mesh`).
    - `mesh`: a `jax.sharding.Mesh`: each chunk's runs are sharded over all its devices (all
        mesh axes flattened) and the results gathered to every process. With
        `jax.distributed.initialize` before the call and a mesh over `jax.devices()`, the
        same call spreads a sweep over several processes or hosts in lockstep (each
        process builds the same table; write it from `jax.process_index() == 0`): one
        program across the GPUs of a node. On a CPU, several host devices in one process
        (`--xla_force_host_platform_device_count`) were seen to hang on the full
        estimators' programs: use one process per device there.
    - `progress`: a progress bar (tqdm) over the chunks.
    - `runs`: only these run indices (any subset, any order; the table holds their rows,
        sorted by run), in chunks of `chunk`.
    - `parts`: a folder where each chunk's rows are written as one Parquet part as soon
        as the chunk finishes, with a manifest of the chunks done (`visjax.studies`'s parts
        format): an interrupted sweep keeps every finished chunk. A folder that already
        holds parts of this sweep is refused unless `resume=True`, which skips the chunks
        done; one holding another sweep's parts is refused.
    - `shard`: `(i, n)`: only the chunks `c` with `c % n == i`, one of `n` disjoint slices
        (a job array's task); the parts of all slices merge into the whole table
        (`merge_parts`, `visjax merge`).
    - `executor`: where the chunks run: `None` (this process, in order) or an executor
        such as `RayExecutor` (chunks as tasks on a Ray cluster, retried if lost; the
        parts are written here as results arrive). Not with `mesh`.
    - `max_memory`: bytes one chunk may need (its compiled program's arguments, outputs
        and temporaries, from XLA's memory analysis: one more lowering of the chunk), or
        `"available"` for 80% of the memory available now; a larger chunk is refused
        before any run, naming a chunk that fits. Default `None`: not checked.
    - `log`: `line -> None` for what the sweep says as it goes (the memory of a chunk,
        the time estimate after the first chunks); default silent.
    - `stop`: `() -> bool`, asked after every chunk: `True` ends the sweep there by raising
        `KeyboardInterrupt`, every finished chunk written (a time limit, a signal handler
        that asks for a clean stop).

    The version-3 forms (`sweep(factory, params, keys, metrics=...)`, the options as
    keyword arguments) still work, with a `FutureWarning`.

    **Returns:** a `SweepResult`; its `to_pandas()` (the table) has one row per run
    (point-major, the seed fastest):
    `run`, `point` (the parameter point's index), the parameters (leaf names joined by `.`,
    components named as the metrics'), `seed`, `result` (the result code's name), `failed_sample`
    (-1 if none) and the metrics. A failed run keeps its row and its code; its metrics are
    NaN, never its frozen state's numbers. A run that reports success but whose metric is
    not finite is marked `nonfinite_output`. With `shard`, the rows of the shard's runs.
    """

    unknown = sorted(set(old) - set(_STUDY_OPTIONS))
    if unknown:
        raise TypeError(f"sweep() got unexpected keyword argument(s) {unknown}.")
    study = study_of(study, "sweep", **old)
    if not isinstance(problem, AbstractProblem):  # version 3: sweep(fn, ...)
        if metrics is None:
            raise ValueError(
                "`sweep(problem, points, keys)`: `problem` must be an AbstractProblem."
            )
        warnings.warn(
            "`sweep(factory, params, keys, metrics=...)` is deprecated: pass "
            "`sweep(FunctionProblem(factory, metrics), points, keys)`.",
            FutureWarning,
            stacklevel=2,
        )
        problem = FunctionProblem(problem, metrics)
    elif metrics is not None:
        raise ValueError("with a problem, `sweep` takes its metrics from the problem.")
    info = {"metric": problem.metric, "method": problem.check_method(method)}
    if isinstance(problem, FunctionProblem):
        if fixed is not None:
            raise ValueError("`fixed` is for a problem with named parameters.")
        factory = runner(problem, method)
        identity_source = _qualname(problem._solve[info["method"]])
    else:
        if not isinstance(points, Mapping):
            raise ValueError("`points` of a problem's sweep must be a dict name -> values.")
        check_values(problem, points, "sweep")
        factory = runner(problem, method, fixed)
        identity_source = run_identity(factory)
    metrics = None
    params = points
    chunk, mesh, shard, runs = study.chunk, study.mesh, study.shard, study.runs
    parts, resume, executor, log = study.parts, study.resume, study.executor, study.log
    leaves_with_path, treedef = jax.tree_util.tree_flatten_with_path(params)
    if not leaves_with_path:
        raise ValueError("`params` has no array leaves.")
    leaves = [np.asarray(leaf) for _, leaf in leaves_with_path]
    sizes = {leaf.shape[0] if leaf.ndim else None for leaf in leaves}
    if None in sizes or len(sizes) != 1:
        raise ValueError(
            "every leaf of `params` needs the same leading axis (the parameter points); got "
            f"shapes {[leaf.shape for leaf in leaves]}."
        )
    n_points = sizes.pop()
    key_data = _key_data(keys)
    n_seeds = key_data.shape[0]
    if n_points < 1 or n_seeds < 1:
        raise ValueError(f"nothing to run: {n_points} parameter points and {n_seeds} seeds.")
    devices = 1 if mesh is None else mesh.devices.size
    n_runs = n_points * n_seeds
    # a small sweep runs in one chunk of the next power of two (so that sweeps of similar
    # sizes share one compilation), a large one in chunks of `chunk`
    small = 1 << max(0, math.ceil(math.log2(n_runs)))
    chunk = devices * math.ceil(min(int(chunk), small) / devices)

    if runs is not None:
        wanted = np.unique(np.asarray(runs, dtype=np.int64).ravel())
        if wanted.size == 0 or wanted[0] < 0 or wanted[-1] >= n_runs:
            raise ValueError(f"`runs` must be run indices in [0, {n_runs}); got {runs!r}.")
        plan = [(c, wanted[c * chunk : (c + 1) * chunk]) for c in range(-(-wanted.size // chunk))]
    else:
        if shard is not None:
            shard = tuple(int(x) for x in shard)
        n_chunks = math.ceil(n_runs / chunk)
        ids = range(n_chunks) if shard is None else range(shard[0], n_chunks, shard[1])
        plan = [(c, np.arange(c * chunk, min((c + 1) * chunk, n_runs))) for c in ids]

    store = None
    done: set[int] = set()
    if parts is not None:
        identity = _identity(identity_source or _qualname(factory), leaves, key_data, chunk)
        info.update(n_points=int(n_points), n_seeds=int(n_seeds))
        store = Parts(parts, identity, n_runs, chunk, shard=shard, info=info)
        done = store.open(resume=resume, log=log)

    if chunk > 1:
        warn_if_hang_prone()
    compiled = _compiled(factory, metrics, treedef, mesh)
    seed_values = np.asarray(keys) if not _is_key_array(keys) else np.arange(n_seeds)
    todo = [(c, idx) for c, idx in plan if c not in done]
    if todo and executor is None and study.max_memory is not None:
        _check_memory(compiled, leaves, key_data, chunk, study.max_memory, log)

    def frame(idx, out):
        values, codes, failed = jax.tree_util.tree_map(lambda x: np.asarray(x)[: idx.size], out)
        return _frame(
            idx, leaves_with_path, leaves, n_seeds, seed_values, values, codes, failed,
            problem.columns,
        )  # fmt: skip

    frames = {c: store.read(c) for c, _ in plan if c in done}
    from tqdm import tqdm

    show = study.progress and jax.process_index() == 0
    bar = tqdm(total=len(plan), initial=len(frames), desc="sweep", unit="chunk", disable=not show)
    timer = _Timer(len(todo), chunk, log)
    if executor is None:
        place = _placer(mesh)

        def finished():  # this process, in order
            for c, idx in todo:
                padded = np.concatenate([idx, np.full(chunk - idx.size, idx[-1])])
                point_leaves = [place(leaf[padded // n_seeds]) for leaf in leaves]
                out = compiled(point_leaves, place(key_data[padded % n_seeds]))
                yield c, _gather(out, mesh is not None)
    else:
        task = _ChunkTask(factory, metrics, treedef, leaves, key_data, chunk)

        def finished():  # the executor's workers, as they finish
            return executor.map_chunks(task, todo)

    indices = dict(todo)
    try:
        for c, out in finished():
            frames[c] = frame(indices[c], out)
            if store is not None:
                store.write(c, frames[c])
            bar.update(1)
            timer.tick()
            if study.stop is not None and study.stop():
                raise KeyboardInterrupt("the sweep was asked to stop")
    finally:
        bar.close()
    import pandas as pd

    table = pd.concat([frames[c] for c, _ in plan], ignore_index=True)
    table = table.sort_values("run", kind="stable").reset_index(drop=True)
    return SweepResult(table, problem.metric, int(n_points), int(n_seeds))


class SweepResult(Result):
    """What `sweep` returns: `to_pandas()` (its table, one row per run), `metric` (the
    problem's headline metric), `n_points`, `n_seeds`. It reads like its table
    (`result["rmse"]`, `len(result)`, `result.columns`, ...); `summarise`, `best` and
    `save_table` take either."""

    def __init__(self, table, metric: str, n_points: int, n_seeds: int):
        self._table, self.metric = table, metric
        self.n_points, self.n_seeds = n_points, n_seeds

    def to_pandas(self):
        return self._table

    def __getitem__(self, item):
        return self._table[item]

    def __len__(self) -> int:
        return len(self._table)

    def equals(self, other) -> bool:
        """Whether the tables are equal (`other` a `SweepResult` or a DataFrame)."""
        return self._table.equals(_as_frame(other))

    def __getattr__(self, name):
        if name.startswith("__") or name == "_table":
            raise AttributeError(name)
        return getattr(self._table, name)

    def __repr__(self) -> str:
        return f"SweepResult({self.n_points} points x {self.n_seeds} seeds)\n{self._table!r}"


def _as_frame(table):
    """A sweep's table as a `pandas.DataFrame` (a `SweepResult`'s, or the frame itself)."""
    return table.to_pandas() if isinstance(table, Result) else table


def _qualname(factory) -> str:
    f = getattr(factory, "__wrapped__", factory)
    return f"{getattr(f, '__module__', '')}.{getattr(f, '__qualname__', type(f).__name__)}"


def _identity(source: str, leaves, key_data, chunk) -> str:
    """A digest of what a sweep computes: its problem (or function), the parameter
    points, the seeds and the chunk size (the parts of two sweeps with equal digests are
    interchangeable)."""
    import hashlib

    h = hashlib.sha256(source.encode())
    for a in [*leaves, key_data]:
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype}{a.shape}".encode())
        h.update(a.tobytes())
    h.update(f"chunk={chunk}".encode())
    return h.hexdigest()


def _frame(idx, leaves_with_path, leaves, n_seeds, seed_values, values, codes, failed, names):
    """The table rows of the runs `idx` from their computed values (`names`: the
    problem's `columns`)."""
    import pandas as pd

    table = {"run": idx.astype(np.int64), "point": (idx // n_seeds).astype(np.int64)}
    for (path, _), leaf in zip(leaves_with_path, leaves):
        name = _leaf_name(path) or "param"
        table.update(_columns(name, leaf[idx // n_seeds], names.get(name)))
    table["seed"] = seed_values[idx % n_seeds]
    codes_named = {int(item._value): name for name, item in RESULTS._name_to_item.items()}
    table["result"] = [codes_named[int(v)] for v in codes]
    table["failed_sample"] = failed
    for name, v in values.items():
        table.update(_columns(name, v, names.get(name)))
    return pd.DataFrame(table)


def _placer(mesh):
    if mesh is None:
        return lambda x: x
    split = _sharding(mesh)
    # each process supplies its own devices' shards (multi-process safe)
    return lambda x: jax.make_array_from_callback(x.shape, split, lambda index: x[index])


class _ChunkTask:
    """One chunk of a sweep as a picklable task for an executor's workers: `task(idx)`
    computes the runs `idx` (padded to the chunk) in the worker's own process, compiling
    once per worker."""

    def __init__(self, factory, metrics, treedef, leaves, key_data, chunk):
        self.factory, self.metrics, self.treedef = factory, metrics, treedef
        self.leaves, self.key_data, self.chunk = leaves, key_data, chunk
        self.x64 = bool(jax.config.jax_enable_x64)  # the worker computes as the caller

    def __call__(self, idx):
        n_seeds = self.key_data.shape[0]
        padded = np.concatenate([idx, np.full(self.chunk - idx.size, idx[-1])])
        compiled = _compiled(self.factory, self.metrics, self.treedef, None)
        out = compiled(
            [leaf[padded // n_seeds] for leaf in self.leaves], self.key_data[padded % n_seeds]
        )
        return jax.tree_util.tree_map(np.asarray, out)


def available_memory(device=None) -> float | None:
    """Bytes a chunk may still take: 80% of the memory available now on `device` (default
    JAX's first device), as `sweep`'s `max_memory="available"` and the command line's
    study checks take it; `None` where neither the device nor the system says.

    On an accelerator (a GPU: its programs' buffers live in its own memory) this is the
    device's `memory_stats()`, `bytes_limit - bytes_in_use`; on a CPU the host's
    (`MemAvailable` of /proc/meminfo, else the free pages)."""
    device = device if device is not None else jax.devices()[0]
    if getattr(device, "platform", "cpu") != "cpu":
        try:
            stats = device.memory_stats() or {}
        except Exception:  # a backend without memory statistics
            stats = {}
        if "bytes_limit" in stats:
            return 0.8 * float(stats["bytes_limit"] - stats.get("bytes_in_use", 0))
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return 0.8 * float(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return 0.8 * float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def chunk_memory(compiled, leaves, key_data, chunk) -> int | None:
    """Bytes one chunk's compiled program needs (arguments, outputs, temporaries), from
    XLA's memory analysis; `None` where the backend does not report it."""
    n_seeds = key_data.shape[0]
    idx = np.zeros(chunk, dtype=np.int64)
    args = ([leaf[idx // n_seeds] for leaf in leaves], key_data[idx % n_seeds])
    try:
        stats = compiled.lower(*args).compile().memory_analysis()
    except Exception:  # a backend without the analysis: no estimate, no refusal
        return None
    if stats is None:
        return None
    return int(
        stats.argument_size_in_bytes
        + stats.output_size_in_bytes
        + stats.temp_size_in_bytes
        - getattr(stats, "alias_size_in_bytes", 0)
    )


def _check_memory(compiled, leaves, key_data, chunk, max_memory, log):
    need = chunk_memory(compiled, leaves, key_data, chunk)
    if need is None:
        return
    limit = max_memory
    if isinstance(limit, str):
        if limit != "available":
            raise ValueError(f'`max_memory` must be bytes or "available"; got {limit!r}.')
        limit = available_memory()
    if log is not None:
        log(f"memory per chunk of {chunk} runs: {need / 2**20:.1f} MiB")
    if limit is not None and need > limit:
        fits = max(1, int(chunk * limit / need))
        raise MemoryLimitError(
            f"a chunk of {chunk} runs needs {need / 2**20:.0f} MiB, more than the "
            f"{limit / 2**20:.0f} MiB available to it: use a chunk of at most {fits} runs "
            "(`--chunk`)."
        )


class MemoryLimitError(Refused):
    """A chunk of a sweep that would need more memory than it may use (the message says
    how large a chunk fits): a `Refused` study."""


class _Timer:
    """The time estimate, said after the first two chunks (the first one compiles)."""

    def __init__(self, n_chunks, chunk, log):
        self.n, self.chunk, self.log = n_chunks, chunk, log
        self.count, self.start = 0, time.perf_counter()
        self.first = None

    def tick(self):
        self.count += 1
        if self.log is None:
            return
        now = time.perf_counter()
        if self.count == 1:
            self.first = now
            self.log(f"first chunk (with compilation): {now - self.start:.1f} s")
        elif self.count == 2 and self.n > 2:
            per = now - self.first
            self.log(
                f"{per:.2f} s per chunk of {self.chunk} runs: about {per * (self.n - 2):.0f} s "
                f"for the other {self.n - 2} chunks"
            )
        self.last = now


def _sharding(mesh):
    return NamedSharding(mesh, PartitionSpec(mesh.axis_names))


def _compiled(factory, metrics, treedef, mesh):
    """The jitted, vmapped run of one chunk, `(point_leaves, key_data) -> out`. A problem's
    run (a Module) passes its arrays as arguments (traced), so that a rebuilt problem of
    equal shapes and settings, or a new data file, reuses the compiled chunk; the program
    is cached per (the run's static part or the factory, metrics, parameter structure,
    mesh)."""
    if isinstance(factory, eqx.Module):
        dynamic, static = eqx.partition(factory, eqx.is_array)
    else:
        dynamic, static = None, factory
    leaves, structure = jax.tree_util.tree_flatten(static)
    key = (structure, tuple(leaves), metrics, treedef, mesh)
    if key not in _JITTED:
        if len(_JITTED) >= 8:  # the oldest goes
            _JITTED.pop(next(iter(_JITTED)))
        _JITTED[key] = _jitted(static, metrics, treedef, mesh)
    return _Chunk(_JITTED[key], dynamic)


_JITTED: dict = {}


class _Chunk:
    """A compiled chunk with its run's arrays bound."""

    def __init__(self, jitted, dynamic):
        self.jitted, self.dynamic = jitted, dynamic

    def __call__(self, point_leaves, kd):
        return self.jitted(self.dynamic, point_leaves, kd)

    def lower(self, point_leaves, kd):
        return self.jitted.lower(self.dynamic, point_leaves, kd)


def _jitted(static, metrics, treedef, mesh):
    def one(dynamic, point_leaves, kd):
        factory = static if dynamic is None else eqx.combine(dynamic, static)
        point = jax.tree_util.tree_unflatten(treedef, point_leaves)
        sol = factory(point, jax.random.wrap_key_data(kd))
        found = factory.metrics(sol) if metrics is None else metrics(sol)
        values = {name: jnp.asarray(v) for name, v in dict(found).items()}
        result = sol.result
        fresh = (result == RESULTS.successful) & ~all_finite(values)
        result = RESULTS.where(fresh, RESULTS.nonfinite_output, result)
        ok = result == RESULTS.successful
        values = {k: jnp.where(ok, v, jnp.nan) for k, v in values.items()}
        failed = jnp.asarray(getattr(sol, "failed_sample", -1), jnp.int32)
        return values, result._value, failed

    batched = jax.vmap(one, in_axes=(None, 0, 0))
    if mesh is None:
        return jax.jit(batched)
    # `shard_map`: every device runs the vmap of its own runs, with no communication (under
    # `jit` with sharding annotations alone, a loop whose predicate is batched may be
    # reduced across devices at every iteration: a collective per step); the run's arrays
    # are replicated
    spec = PartitionSpec(mesh.axis_names)
    return jax.jit(
        jax.shard_map(
            batched, mesh=mesh, in_specs=(PartitionSpec(), spec, spec), out_specs=spec,
            check_vma=False,
        )
    )  # fmt: skip


def _gather(tree, sharded: bool):
    """A result on the host: a sharded one from every process (an all-gather across
    processes); an unsharded one is this process's own."""
    if not sharded or jax.process_count() == 1:
        return jax.tree_util.tree_map(np.asarray, tree)
    from jax.experimental import multihost_utils

    return jax.tree_util.tree_map(np.asarray, multihost_utils.process_allgather(tree, tiled=True))


def _is_key_array(keys) -> bool:
    return isinstance(keys, jax.Array) and jnp.issubdtype(keys.dtype, jax.dtypes.prng_key)


def summarise(table, metric: str, params: Sequence[str] | None = None):
    """Per parameter point of a `sweep` table: the metric's mean, standard deviation, min
    and max over the successful seeds, `n_runs` and `n_failed`. A point with a failed seed
    keeps its row (its statistics over the others) and is never `best`.

    **Returns:** a `pandas.DataFrame`, one row per point, sorted by `point`."""
    table = _as_frame(table)
    if metric not in table.columns:
        raise ValueError(f"no metric column {metric!r}; the table has {list(table.columns)}.")
    if params is None:
        params = _param_columns(table)
    groups = table.groupby("point", sort=True)
    ok = table["result"] == "successful"
    out = groups[list(params)].first()
    stats = table[ok].groupby("point")[metric].agg(["mean", "std", "min", "max"])
    out = out.join(stats.add_prefix(f"{metric}_"))
    out["n_runs"] = groups.size()
    out["n_failed"] = (~ok).groupby(table["point"]).sum()
    return out.reset_index()


def _param_columns(table) -> list[str]:
    """The parameter columns of a sweep table: those between `point` and `seed`."""
    cols = list(table.columns)
    return cols[cols.index("point") + 1 : cols.index("seed")]


def best(table, metric: str) -> dict:
    """The best parameter point of a `sweep` table: the lowest mean of `metric` over seeds
    among the points with no failed run.

    **Returns:** `{"point": int, "params": {column: value}, "metric": mean, "std": float}`.
    **Raises:** `ValueError` if every point has a failed run."""
    table = _as_frame(table)
    s = summarise(table, metric)
    usable = s[(s["n_failed"] == 0) & np.isfinite(s[f"{metric}_mean"])]
    if usable.empty:
        raise ValueError(
            f"every parameter point has a failed run; results: {table['result'].value_counts()}"
        )
    row = usable.loc[usable[f"{metric}_mean"].idxmin()]
    return {
        "point": int(row["point"]),
        "params": {c: float(row[c]) for c in _param_columns(table)},
        "metric": float(row[f"{metric}_mean"]),
        "std": float(row[f"{metric}_std"]) if np.isfinite(row[f"{metric}_std"]) else 0.0,
    }


def save_table(table, out_dir, name: str = "runs") -> dict:
    """Write a sweep table (or any table: a comparison's records) as `<name>.parquet` and
    `<name>.csv` in `out_dir` (created).

    **Returns:** `{"parquet": path, "csv": path}`."""
    from pathlib import Path

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    table = _as_frame(table)
    table.to_parquet(out / f"{name}.parquet", index=False)
    table.to_csv(out / f"{name}.csv", index=False)
    return {"parquet": out / f"{name}.parquet", "csv": out / f"{name}.csv"}


def held_out(
    problem: AbstractProblem,
    points: Mapping[str, Mapping[str, Any]],
    keys,
    *,
    method: str | None = None,
    study: Study | None = None,
) -> dict[str, dict]:
    """Named parameter points of `problem` (of its `method`, default the estimator)
    measured on noise keys no study has seen: the
    honest figure once a sweep or a tuning chose a point on keys of its own (what `visjax
    sweep` and `visjax tune` report, on the seeds after theirs).

    **Arguments:** `problem`; `points` (name -> {parameter: value}; a vector parameter may
    be named by one value, broadcast to its shape); `keys` (as `sweep`'s: 1-D int seeds or
    typed PRNG keys, the same for every point); `study` (a `Study`: its `chunk` and
    `mesh`, as `sweep`'s).

    **Returns:** name -> `{"params", "metric", "failed"}`: the point as given (Python
    numbers), the mean of the problem's headline metric over the keys whose run succeeded
    (NaN if none did) and how many did not."""
    if not isinstance(problem, AbstractProblem):
        raise TypeError(f"`problem` must be a visjax.studies.AbstractProblem; got {problem!r}.")
    names = list(points)
    if not names:
        raise ValueError("`points` is empty: name at least one parameter point.")
    specs = problem.parameters()
    full = []
    for n in names:
        unknown = sorted(set(points[n]) - set(specs))
        if unknown:
            raise ValueError(f"point {n!r}: {problem.title} has no parameter {unknown}.")
        full.append(
            {
                k: np.broadcast_to(np.asarray(v, float), specs[k].value.shape)
                for k, v in points[n].items()
            }
        )
    if any(set(f) != set(full[0]) for f in full):
        raise ValueError("every point must name the same parameters (the others: defaults).")
    params = {k: np.stack([f[k] for f in full]) for k in full[0]}
    study = Study() if study is None else study
    study = Study(chunk=study.chunk, mesh=study.mesh)
    table = sweep(problem, params, keys, method=method, study=study)
    out = {}
    for i, n in enumerate(names):
        rows = table[table["point"] == i]
        ok = rows["result"] == "successful"
        out[n] = {
            "params": {k: _python(v) for k, v in points[n].items()},
            "metric": float(rows[ok][problem.metric].mean()) if ok.any() else float("nan"),
            "failed": int((~ok).sum()),
        }
    return out


def _python(x):
    """A number or an array as a Python float or a (nested) list of floats."""
    x = np.asarray(x, float)
    return float(x) if x.ndim == 0 else x.tolist()


__all__ = [
    "best",
    "grid",
    "held_out",
    "log_axis",
    "parse_grid",
    "random_points",
    "save_table",
    "summarise",
    "sweep",
]
