"""`compare`: several methods (an estimator, its baselines) on identical inputs over noise
seeds, with accuracy, result code and timing per run, as tidy records."""

import statistics
import time
from collections.abc import Callable, Mapping
from typing import Any

import equinox as eqx
import jax
import numpy as np

from .._results import RESULTS, result_names
from ._problem import AbstractProblem, as_json, method_runs


class StudyTooLong(ValueError):
    """A study whose measured first seed puts its whole run time past the limit it was
    given (`compare`'s `max_seconds`): refused after one seed, not found after hours."""


def compare(
    methods,
    inputs: Callable[[jax.Array], tuple[Any, Any]] | None = None,
    score: Callable[[str, Any, Any], dict] | None = None,
    *,
    seeds: int = 4,
    first_seed: int = 0,
    updates: Mapping[str, int] | None = None,
    repeats: int = 3,
    progress: bool = False,
    params: Mapping[str, Any] | None = None,
    max_seconds: float | None = None,
) -> list[dict]:
    """Run every method on the same inputs for each noise seed and record how it did.

    `compare(problem, seeds=..., params=...)`: every method of an `AbstractProblem`
    (its estimator and baselines, `params` overriding the defaults) on the problem's
    noisy inputs, scored by its `metrics` (as JSON numbers; `None` for a failed run), with
    the problem's `uncertainty` beside them (`None` where a method predicts none) and its
    `updates`. Or, without a problem, the functional form below.

    **Arguments:**

    - `methods`: an `AbstractProblem`, or name -> `method(inputs) -> solution`, a pure
        function of the inputs (it is compiled once with `equinox.filter_jit`, on the first
        seed). The solution must have a `result` (a visjax `RESULTS` item).
    - `inputs`: `key -> (inputs, truth)`, the noisy measurements of one seed (every method
        sees the same ones) and the ground truth for `score`.
    - `score`: `(name, solution, truth) -> dict` of accuracy numbers (JSON-able).
    - `seeds`: how many noise seeds: `first_seed, ..., first_seed + seeds - 1`
        (`jax.random.key(seed)`).
    - `first_seed`: the first of them (default 0).
    - `updates`: per method, how many estimate updates one call makes, for the latency:
        the number of samples for a recursive method (an observer, a filter: constant cost
        per new sample), the number of window fits for a sliding-window fit, 1 for a batch
        fit over all frames (whose latency is then a whole re-fit: what a new sample costs
        if the batch answer is to stay current). Default: 1.
    - `repeats`: timed calls per method and seed, after the compiling one; the median is
        reported.
    - `max_seconds`: a limit on the whole comparison's run time. After the first seed,
        the rest is estimated from it (its inputs and calls, compilation excluded); past
        the limit, `StudyTooLong` is raised, naming the estimate. Default: no limit.

    **Returns:** one record per (method, seed): `method`, `seed`, `result` (the result
    code's name), `latency_s_per_sample` (median call time / updates), `total_s` (median
    call time), `compile_s` (the first call, compilation included: `first_seed` only, else
    `None`) and the keys of `score`.
    """

    if isinstance(methods, AbstractProblem):
        problem = methods.at(methods.resolve(params))  # its data parameters set
        if inputs is not None or score is not None or updates is not None:
            raise ValueError("with a problem, `compare` takes no `inputs`, `score` or `updates`.")

        def problem_inputs(key):
            return problem.inputs(key), None

        def problem_score(name, sol, truth):
            ok = bool(sol.result == RESULTS.successful)
            values = jax.tree_util.tree_map(np.asarray, problem.metrics(name, sol))
            ok = ok and all(np.all(np.isfinite(v)) for v in values.values())
            spread = jax.tree_util.tree_map(np.asarray, problem.uncertainty(name, sol))
            return {**as_json(values, ok), **as_json(spread, ok, nullable=True)}

        return compare(
            method_runs(problem, params),
            problem_inputs,
            problem_score,
            seeds=seeds,
            first_seed=first_seed,
            updates={m: problem.updates(m) for m in problem.methods},
            repeats=repeats,
            progress=progress,
            max_seconds=max_seconds,
        )
    if inputs is None or score is None:
        raise ValueError("`compare(methods, inputs, score)`: `inputs` and `score` are needed.")
    if params is not None:
        raise ValueError("`params` is for `compare(problem, ...)`.")
    if seeds < 1:
        raise ValueError(f"`seeds` must be at least 1; got {seeds}.")
    if repeats < 1:
        raise ValueError(f"`repeats` must be at least 1; got {repeats}.")
    if max_seconds is not None and not max_seconds > 0:
        raise ValueError(f"`max_seconds` must be positive; got {max_seconds!r}.")
    if not (isinstance(first_seed, int) and first_seed >= 0):
        raise ValueError(f"`first_seed` must be a non-negative int; got {first_seed!r}.")
    updates = dict(updates or {})
    unknown = set(updates) - set(methods)
    if unknown:
        raise ValueError(f"`updates` names methods not in `methods`: {sorted(unknown)}.")
    compiled = {name: eqx.filter_jit(fn) for name, fn in methods.items()}
    records = []
    from tqdm import tqdm

    bar = tqdm(total=seeds * len(methods), desc="compare", unit="run", disable=not progress)
    for seed in range(first_seed, first_seed + seeds):
        started = time.perf_counter()
        data, truth = inputs(jax.random.key(seed))
        seed_s = time.perf_counter() - started  # the inputs, then every call but compiles
        for name, fn in compiled.items():
            t0 = time.perf_counter()
            sol = jax.block_until_ready(fn(data))
            first = time.perf_counter() - t0
            times = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                jax.block_until_ready(fn(data))
                times.append(time.perf_counter() - t0)
            total = statistics.median(times)
            seed_s += sum(times) + (total if seed == first_seed else first)
            records.append(
                {
                    "method": name,
                    "seed": seed,
                    "result": result_names(sol.result),
                    "latency_s_per_sample": total / updates.get(name, 1),
                    "total_s": total,
                    "compile_s": first if seed == first_seed else None,
                    **score(name, sol, truth),
                }
            )
            bar.update()
        if seed == first_seed and max_seconds is not None and seeds > 1:
            rest = seed_s * (seeds - 1)
            if rest > max_seconds:
                bar.close()
                raise StudyTooLong(
                    f"{seeds} seeds would take about {_duration(rest)} more ({seed_s:.3g} s a "
                    f"seed, measured on the first), past the limit of {_duration(max_seconds)}"
                )
    bar.close()
    return records


def _duration(seconds: float) -> str:
    if seconds >= 3600:
        return f"{seconds / 3600:.3g} h"
    return f"{seconds / 60:.3g} min" if seconds >= 60 else f"{seconds:.3g} s"
