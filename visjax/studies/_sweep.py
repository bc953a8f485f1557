"""`sweep`: any estimator or baseline over a batch of parameter points and noise seeds, in
chunks of `vmap`, optionally sharded over the devices of a `jax.sharding.Mesh` (also across
processes started with `jax.distributed`), as a tidy table: one row per run.

Helpers build the parameter points: `grid` (the Cartesian product of axes), `log_axis`
(log-spaced values, for gains), `parse_grid` (the command line's `"K=1e-2:1e1:8,rho=..."`)
and `random_points` (log-uniform samples).
"""

import functools
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import NamedSharding, PartitionSpec

from .._results import RESULTS, all_finite
from .._xla_workaround import warn_if_hang_prone


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
        try:
            if ":" in body:
                low, high, num = body.split(":")
                axes[name] = log_axis(float(low), float(high), int(num))
            else:
                axes[name] = np.array([float(v) for v in body.split("/")])
        except ValueError as err:
            raise ValueError(f"grid axis {part!r}: {err}") from None
    if not axes:
        raise ValueError(f"the grid spec {spec!r} names no axis.")
    return grid(**axes)


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


def _columns(name: str, values: np.ndarray) -> dict[str, np.ndarray]:
    """A (R, ...) array as table columns: `name` for scalars, `name[i]` (or `name[i,j]`)
    for the components of a vector (or matrix)."""
    values = np.asarray(values)
    if values.ndim == 1:
        return {name: values}
    flat = values.reshape(values.shape[0], -1)
    return {
        f"{name}[{','.join(map(str, ix))}]": flat[:, i]
        for i, ix in enumerate(np.ndindex(*values.shape[1:]))
    }


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


def sweep(
    factory,
    params: Any,
    keys: Any,
    *,
    metrics: Callable[[Any], Mapping[str, jax.Array]] | None = None,
    method: str | None = None,
    fixed: Mapping[str, Any] | None = None,
    chunk: int = 64,
    mesh: jax.sharding.Mesh | None = None,
    progress: bool = False,
):
    """Run `factory` at every parameter point for every noise seed, batched, as a table.

    `sweep(problem, params, keys, method=..., fixed=...)`: one method (default: the
    estimator) of an `AbstractProblem`; `params` names some of its parameters (the
    points), `fixed` others (one value for every run), the rest keep their defaults. Every
    value is checked (finite; positive where the parameter must be) before any run. A
    compiled chunk is reused by a rebuilt problem with equal fields.

    **Arguments:**

    - `factory`: an `AbstractProblem`, or `(params, key) -> solution`, a pure JAX function
        of one parameter point (the pytree `params` with the leading axis removed) and one
        PRNG key: it builds the estimator (or baseline) from the parameters, the noisy
        measurements from the key, and runs it (`throw=False`). The solution must have a
        `result` (a visjax `RESULTS` item); its `failed_sample`, if it has one, goes into
        the table.
    - `params`: a pytree of arrays with a common leading axis P (the points; `grid`,
        `parse_grid` or `random_points` build one).
    - `keys`: S noise seeds: a 1-D array of ints (`jax.random.key(seed)` each) or of typed
        PRNG keys (the table's `seed` column is then the index).
    - `metrics`: `solution -> {name: array}`, computed inside the batch (floating scalars
        or small arrays; an array becomes one column per component, `name[i]`).
    - `chunk`: runs per compiled `vmap` call (rounded up to a multiple of the mesh's device
        count): memory is bounded by one chunk whatever P x S is. The last chunk is padded
        with repeats of the last run (discarded), so one compilation serves every chunk; a
        sweep smaller than `chunk` runs as one chunk of the next power of two. The compiled
        chunk is cached per (`factory`, `metrics`, structure of `params`, `mesh`): a second
        sweep of the same problem and chunk size does not compile again.
    - `mesh`: a `jax.sharding.Mesh`: each chunk's runs are sharded over all its devices (all
        mesh axes flattened) and the results gathered to every process. With
        `jax.distributed.initialize` before the call and a mesh over `jax.devices()`, the
        same call spreads a sweep over several processes or hosts (each process builds the
        same table; write it from `jax.process_index() == 0`). Each device runs the `vmap`
        of its own runs (`jax.shard_map`). On a CPU, several host devices in one process
        (`--xla_force_host_platform_device_count`) were seen to hang on the full
        estimators' programs: use one process per device there.
    - `progress`: a progress bar (tqdm) over the chunks.

    **Returns:** a `pandas.DataFrame`, one row per run (point-major, the seed fastest):
    `run`, `point` (the parameter point's index), the parameters (leaf names joined by `.`,
    components as `name[i]`), `seed`, `result` (the result code's name), `failed_sample`
    (-1 if none) and the metrics. A failed run keeps its row and its code; its metrics are
    NaN, never its frozen state's numbers. A run that reports success but whose metric is
    not finite is marked `nonfinite_output`.
    """
    import pandas as pd

    from ._problem import AbstractProblem, check_values, runner

    if isinstance(factory, AbstractProblem):
        if metrics is not None:
            raise ValueError("with a problem, `sweep` takes its metrics from the problem.")
        if not isinstance(params, Mapping):
            raise ValueError("`params` of a problem's sweep must be a dict name -> values.")
        check_values(factory, params, "sweep")
        factory, metrics = runner(factory, method, fixed)
    elif metrics is None:
        raise ValueError("`sweep(factory, params, keys, metrics=...)`: `metrics` is needed.")
    elif method is not None or fixed is not None:
        raise ValueError("`method` and `fixed` are for `sweep(problem, ...)`.")
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
    if chunk < 1:
        raise ValueError(f"`chunk` must be at least 1; got {chunk}.")
    devices = 1 if mesh is None else mesh.devices.size
    # a small sweep runs in one chunk of the next power of two (so that sweeps of similar
    # sizes share one compilation), a large one in chunks of `chunk`
    small = 1 << max(0, math.ceil(math.log2(n_points * n_seeds)))
    chunk = devices * math.ceil(min(chunk, small) / devices)
    n_runs = n_points * n_seeds
    n_chunks = math.ceil(n_runs / chunk)

    if chunk > 1:
        warn_if_hang_prone()
    compiled = _compiled(factory, metrics, treedef, mesh)
    if mesh is None:

        def place(x):
            return x
    else:
        split = _sharding(mesh)

        def place(x):  # each process supplies its own devices' shards (multi-process safe)
            return jax.make_array_from_callback(x.shape, split, lambda index: x[index])

    from tqdm import tqdm

    collected = []
    show = progress and jax.process_index() == 0
    for c in tqdm(range(n_chunks), desc="sweep", unit="chunk", disable=not show):
        runs = np.minimum(np.arange(c * chunk, (c + 1) * chunk), n_runs - 1)
        point_leaves = [place(leaf[runs // n_seeds]) for leaf in leaves]
        kd = place(key_data[runs % n_seeds])
        out = compiled(point_leaves, kd)
        collected.append(_gather(out, mesh is not None))
    values, codes, failed = jax.tree_util.tree_map(
        lambda *xs: np.concatenate(xs)[:n_runs], *collected
    )
    runs = np.arange(n_runs)
    table = {"run": runs, "point": runs // n_seeds}
    for (path, _), leaf in zip(leaves_with_path, leaves):
        table.update(_columns(_leaf_name(path) or "param", leaf[runs // n_seeds]))
    seed_values = np.asarray(keys) if not _is_key_array(keys) else np.arange(n_seeds)
    table["seed"] = seed_values[runs % n_seeds]
    names = {int(item._value): name for name, item in RESULTS._name_to_item.items()}
    table["result"] = [names[int(v)] for v in codes]
    table["failed_sample"] = failed
    for name, v in values.items():
        table.update(_columns(name, v))
    return pd.DataFrame(table)


def _sharding(mesh):
    return NamedSharding(mesh, PartitionSpec(mesh.axis_names))


@functools.lru_cache(maxsize=8)
def _compiled(factory, metrics, treedef, mesh):
    """The jitted, vmapped run of one chunk; cached per (factory, metrics, parameter
    structure, mesh), so that repeated sweeps of one problem compile once per chunk shape."""

    def one(point_leaves, kd):
        point = jax.tree_util.tree_unflatten(treedef, point_leaves)
        sol = factory(point, jax.random.wrap_key_data(kd))
        values = {name: jnp.asarray(v) for name, v in dict(metrics(sol)).items()}
        result = sol.result
        fresh = (result == RESULTS.successful) & ~all_finite(values)
        result = RESULTS.where(fresh, RESULTS.nonfinite_output, result)
        ok = result == RESULTS.successful
        values = {k: jnp.where(ok, v, jnp.nan) for k, v in values.items()}
        failed = jnp.asarray(getattr(sol, "failed_sample", -1), jnp.int32)
        return values, result._value, failed

    batched = jax.vmap(one)
    if mesh is None:
        return jax.jit(batched)
    # `shard_map`: every device runs the vmap of its own runs, with no communication (under
    # `jit` with sharding annotations alone, a loop whose predicate is batched may be
    # reduced across devices at every iteration: a collective per step)
    spec = PartitionSpec(mesh.axis_names)
    return jax.jit(
        jax.shard_map(batched, mesh=mesh, in_specs=spec, out_specs=spec, check_vma=False)
    )


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


def save_table(table, out_dir) -> dict:
    """Write a sweep table as `runs.parquet` and `runs.csv` in `out_dir` (created).

    **Returns:** `{"parquet": path, "csv": path}`."""
    from pathlib import Path

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    table.to_parquet(out / "runs.parquet", index=False)
    table.to_csv(out / "runs.csv", index=False)
    return {"parquet": out / "runs.parquet", "csv": out / "runs.csv"}


__all__ = [
    "best",
    "grid",
    "log_axis",
    "parse_grid",
    "random_points",
    "save_table",
    "summarise",
    "sweep",
]
