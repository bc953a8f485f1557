"""`plan`: a study's runs and a lower bound of its memory, before it runs (what the command
line refuses at once rather than finding out after hours); `check_grid`: a grid's names
and values among a problem's parameters; and the two workflows the commands run:
`sweep_then_hold_out` (a sweep, its best point, it and the defaults on held-out keys)
and `sweep_then_tune` (the same, then gradient descent from the sweep's best)."""

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import jax
import numpy as np

from .._util import did_you_mean
from ._problem import AbstractProblem, check_values
from ._study import Refused, Result, Study
from ._sweep import SweepResult, available_memory, best, held_out, parse_grid, summarise, sweep
from ._tune import TuneResult, tune

MAX_RUNS = 10**9
"""The most runs one study makes (grid points x keys, the held-out runs, the tuning's):
far beyond any useful study, so that a count above it is a slip of the keyboard (refused
at once, not found after hours)."""

RECORD_BYTES = 1024
"""Memory per record of `compare` (a dict of a dozen numbers and names), bytes."""

KINDS = ("compare", "sweep", "tune")


@dataclass(frozen=True)
class Plan:
    """What `plan` found: `kind`, `runs` (every run the study makes), `memory` (a lower
    bound, bytes), `memory_of` (what it is made of), `available` (bytes this process may
    still take, `None` where the system does not say). `check(where)` raises `Refused`
    when the runs pass `MAX_RUNS` or the memory the available."""

    kind: str
    runs: int
    memory: int | float
    memory_of: str
    available: int | float | None

    def check(self, where: str) -> None:
        check_run_count(self.kind, self.runs, where)
        if self.available is not None and self.memory > self.available:
            raise Refused(
                f"{self.kind} {where}: needs at least {self.memory / 2**20:.0f} MiB "
                f"({self.memory_of}), more than the {self.available / 2**20:.0f} MiB available "
                "to it (80% of the memory available now): use a smaller --chunk, fewer --seeds "
                "or a coarser --grid"
            )


def study_runs(kind: str, points: int, seeds: int, steps: int = 0, methods: int = 1) -> int:
    """The runs of a study: compare, every method over the keys (tuned first, `--tune`:
    `steps` the budget, evaluations of each method over as many training keys); sweep,
    the grid over the keys and the held-out runs (the best point and the defaults); tune,
    also the tuned point and `steps` evaluations over the keys."""
    if kind == "compare":
        return seeds * methods * (1 + steps)
    if kind == "sweep":
        return points * seeds + 2 * seeds
    return points * seeds + steps * seeds + 3 * seeds


def check_run_count(kind: str, total: int, what: str) -> None:
    """`Refused` if `total` runs pass `MAX_RUNS`."""
    if total > MAX_RUNS:
        steps = ", fewer --steps" if kind == "tune" else ""
        grid = " or a coarser --grid" if kind != "compare" else ""
        raise Refused(
            f"{kind}: {what} make {total:.3g} runs, more than one study runs "
            f"({MAX_RUNS:.0e}): use fewer --seeds{steps}{grid}"
        )


def grid_size(spec: str) -> int | None:
    """The number of points of a `parse_grid` spec (the product of its axes' lengths), read
    from the text without building the grid; `None` for a spec `parse_grid` refuses."""
    size = 1
    for part in [p.strip() for p in spec.split(",") if p.strip()]:
        body = part.split("=", 1)[-1]
        try:
            n = int(body.split(":")[2]) if ":" in body else len(body.split("/"))
        except (ValueError, IndexError):
            return None
        size *= max(n, 0)
    return size


def check_grid_text(spec: str) -> str:
    """A `--grid` spec that parses (`parse_grid`), of at most `MAX_RUNS` points (counted
    from the text first: nothing that large is built), every value finite; its names and
    signs need the problem (`check_grid`). **Raises:** `Refused`, one line."""
    size = grid_size(spec)
    if size is not None and size > MAX_RUNS:
        raise Refused(
            f"the grid {spec!r} has {size:.3g} points, more than one command runs ({MAX_RUNS:.0e})"
        )
    try:
        points = parse_grid(spec)
    except ValueError as e:
        raise Refused(str(e)) from None
    for name, values in points.items():
        if not all(math.isfinite(v) for v in values):
            raise Refused(f"grid axis {name!r} has a value that is not finite in {spec!r}")
    return spec


def check_study(
    kind: str, name: str, build, *, spec=None, seeds: int = 1, study=None, steps=0, variants=1,
    methods=None,
) -> list:  # fmt: skip
    """A study's size before any compile, what the command line checks: the run count (at
    most `MAX_RUNS`; first from the grid's text `spec` and the `variants` count, before
    anything is built), then on the problems `build()` returns (`[(tag, problem)]`, built
    once) the grid (`check_grid`: `spec`, or each problem's default) and `plan` (the runs
    again, a lower bound of the memory against `available_memory()`, of the job's slice
    with `study.shard`); `methods` (the selected methods: each checked, and a grid axis
    none of them uses refused; default: every method for compare, the estimator for a
    sweep or a tuning); `kind="run"`: only the method (`methods=[name or None]`) checked.
    **Raises:** `Refused`, one line. **Returns:** the built problems."""
    if kind == "run":  # one run of one method: the method checked on the built problems
        built = build()
        for tag, p in built:
            try:
                p.check_methods(methods)
            except ValueError as e:
                raise Refused(str(e) if tag is None else f"[{tag}] {e}") from None
        return built
    count = 1 if spec is None else grid_size(spec)
    if count is not None:
        what = f"{count} grid points x {seeds} seeds" if spec else f"{seeds} seeds"
        what += f" and {steps} steps" if kind == "tune" else ""
        what += f" and a tuning budget of {steps}" if kind == "compare" and steps else ""
        check_run_count(kind, variants * study_runs(kind, count, seeds, steps), what)
    built, total = build(), 0
    for tag, p in built:
        where = name if tag is None else f"{name} [{tag}]"
        try:
            chosen = p.check_methods(methods if methods or kind == "compare" else [None])
            points = None if kind == "compare" else check_grid(p, spec or p.grid, where)
            if points is not None:
                p.check_axes(list(points), chosen)
        except ValueError as e:  # the problem's message names it; a variant's tag added
            raise Refused(str(e) if tag is None else f"[{tag}] {e}") from None
        found = plan(p, points, seeds, study, kind=kind, steps=steps, methods=len(chosen))
        found.check(where)
        total += found.runs
    check_run_count(kind, total, f"{len(built)} problem(s), their grids and {seeds} seeds")
    return built


def input_bytes(problem: AbstractProblem) -> int:
    """Bytes of one run's noisy inputs (`problem.inputs`, traced, not run): the least one
    run holds."""
    shapes = jax.eval_shape(problem.inputs, jax.random.key(0))
    leaves = jax.tree_util.tree_leaves(shapes)
    return int(sum(math.prod(x.shape) * np.dtype(x.dtype).itemsize for x in leaves))


def plan(
    problem: AbstractProblem,
    points: Mapping[str, Any] | None,
    keys: Any,
    study: Study | None = None,
    *,
    kind: str = "sweep",
    steps: int = 0,
    methods: int | None = None,
) -> Plan:
    """The runs and a lower bound of the memory of a study of `problem`, before any
    compile: the noisy inputs of a chunk of runs (sweep; tune: of every key at once, its
    gradient step is one call) and the table of every run (8 bytes a cell; a job's slice
    with `study.shard`), or `compare`'s records.

    **Arguments:** `problem`; `points` (name -> values, the grid; `None` for compare);
    `keys` (the keys, or their number); `study` (its `chunk` and `shard`); `kind`
    (`"compare"`, `"sweep"` or `"tune"`); `steps` (tune's); `methods` (compare's count
    of methods, default every one)."""
    if kind not in KINDS:
        raise ValueError(f"`kind` must be one of {KINDS}; got {kind!r}.")
    study = Study() if study is None else study
    seeds = int(keys) if np.ndim(keys) == 0 else len(keys)
    per_run = input_bytes(problem)
    methods = len(problem.methods) if methods is None else methods
    if kind == "compare" or not points:
        records = seeds * methods * RECORD_BYTES
        runs = study_runs("compare", 1, seeds, methods=methods)
        what = f"{seeds * methods} records of {RECORD_BYTES} bytes"
        return Plan(kind, runs, per_run + records, what, available_memory())
    n_points = len(next(iter(points.values())))
    runs = n_points * seeds
    batch = min(study.chunk, 1 << max(0, math.ceil(math.log2(runs))))
    specs = problem.parameters()
    columns = 6 + sum(int(np.size(specs[k].value)) if k in specs else 1 for k in points)
    slices = study.shard[1] if study.shard is not None else 1
    need = batch * per_run + math.ceil(runs / slices) * columns * 8
    what = f"{batch} runs' inputs of {per_run / 2**20:.3g} MiB and a table of {runs} runs"
    if kind == "tune" and seeds * per_run > need:
        need, what = seeds * per_run, f"{seeds} seeds' inputs of {per_run / 2**20:.3g} MiB"
    total = study_runs(kind, n_points, seeds, steps)
    return Plan(kind, total, need, what, available_memory())


def check_grid(problem: AbstractProblem, spec: str, where: str) -> dict:
    """The grid of a `parse_grid` spec: its parameter names among the problem's (the
    closest suggested) and its values valid for them (finite; positive where the
    parameter must be). **Raises:** `Refused`, one line."""
    if not spec:
        raise Refused(f"{problem.title} has no default grid: give --grid")
    params = parse_grid(spec)
    specs = problem.parameters()
    for axis in params:
        if axis not in specs:
            hint = did_you_mean(axis, specs, ignore_case=True)
            raise Refused(
                f"--grid: {where} has no parameter {axis!r}{hint}; its parameters: "
                f"{', '.join(sorted(specs))}"
            )
    try:
        check_values(problem, params, f"--grid ({where})")
    except ValueError as e:
        raise Refused(" ".join(str(e).split())) from None
    return params


@dataclass(frozen=True)
class Selection(Result):
    """What `sweep_then_hold_out` and `sweep_then_tune` return: `sweep` (the
    `SweepResult`), `summary` (per point, `summarise`), `best` (the sweep's best point and
    its training metric), `tuned` (the `TuneResult`, or `None`), `held` (name -> `{"params",
    "metric", "failed"}` on the held-out keys: `"best"` or `"tuned"` and `"sweep best"`,
    and `"paper"`, the defaults). `to_pandas()`: the held-out points, one row each."""

    sweep: SweepResult
    summary: Any
    best: dict
    held: dict
    tuned: TuneResult | None = field(default=None)

    def to_pandas(self):
        import pandas as pd

        rows = [
            {"point": name, "metric": r["metric"], "failed": r["failed"], **r["params"]}
            for name, r in self.held.items()
        ]
        return pd.DataFrame(rows)

    def lines(self, problem: AbstractProblem) -> list[str]:
        """The held-out points as `visjax sweep` and `visjax tune` print them, one line
        each (the defaults under the problem's `defaults_label`)."""
        out = []
        for name, x in self.held.items():  # `paper` keeps its JSON key, printed as the label
            values = ", ".join(f"{k} = {np.round(v, 4).tolist()}" for k, v in x["params"].items())
            failed = f" ({x['failed']} held-out run(s) failed)" if x["failed"] else ""
            name = problem.defaults_label if name == "paper" else name
            out.append(
                f"{name:<11} {values:<40} held-out {problem.metric} = {x['metric']:.4g}{failed}"
            )
        return out

    def report(self, problem: AbstractProblem) -> dict:
        """What the selection found, as JSON (the summaries of `visjax sweep` and `visjax
        tune`): the metric; the held-out points (`best`: the tuned one after a tuning;
        `paper`: the defaults; `sweep_best` after a tuning), each `{"params", "metric"}`;
        the gains; a sweep's run counts or a tuning's training loss and held-out failures;
        the problem's checks of the chosen point (`AbstractProblem.checks`)."""
        point = {k: {"params": v["params"], "metric": v["metric"]} for k, v in self.held.items()}
        out = {
            "metric": problem.metric, "paper": point["paper"], "problem": problem.title,
            "problem_settings": problem.settings(), "paper_gains": problem.gains({}),
        }  # fmt: skip
        if self.tuned is None:
            chosen = self.best["params"]
            failed = int((self.sweep["result"] != "successful").sum())
            return out | {
                "best": point["best"], "best_training_metric": self.best["metric"],
                "best_gains": problem.gains(chosen), "failed_runs": failed,
                "runs": len(self.sweep), **problem.checks(chosen),
            }  # fmt: skip
        chosen = self.tuned.params
        return out | {
            "best": point["tuned"], "sweep_best": point["sweep best"],
            "improvement_over_paper": point["paper"]["metric"] / point["tuned"]["metric"],
            "training_loss": {"sweep_best": self.tuned.loss0, "tuned": self.tuned.loss},
            "tuning_improved": self.tuned.improved, "tuned_step": self.tuned.best_step,
            "tuned_gains": problem.gains(chosen),
            "held_out_failed_runs": {k: v["failed"] for k, v in self.held.items()},
            **problem.checks(chosen),
        }  # fmt: skip


def defaults_of(problem: AbstractProblem, names) -> dict:
    """The defaults (the paper's values) of the named parameters."""
    return {k: problem.parameters()[k].value for k in names}


def sweep_then_hold_out(
    problem: AbstractProblem,
    points,
    keys,
    held_keys,
    *,
    method: str | None = None,
    study: Study | None = None,
) -> Selection | SweepResult:
    """A sweep of `method` (default the estimator) at `points` over `keys`, its best point
    by the mean headline metric, and
    the best point and the defaults re-measured on `held_keys` (`held_out`): the honest
    figure of a chosen point; `points` may be a `parse_grid` spec (checked: `check_grid`).
    With `study.shard` (a job's slice), only the slice's `SweepResult` (the best point
    needs every run)."""
    study, method = Study() if study is None else study, problem.check_method(method)
    points = _points(problem, points, method)
    table = sweep(problem, points, keys, method=method, study=study)
    if study.shard is not None:
        return table
    chosen = best(table, problem.metric)
    named = {"best": chosen["params"], "paper": defaults_of(problem, chosen["params"])}
    held = held_out(problem, named, held_keys, method=method, study=study)
    return Selection(table, summarise(table, problem.metric), chosen, held)


def sweep_then_tune(
    problem: AbstractProblem,
    points,
    keys,
    held_keys,
    *,
    method: str | None = None,
    optimiser: Any = None,
    steps: int = 30,
    study: Study | None = None,
) -> Selection:
    """A sweep of `points` over `keys`, then `tune` (gradient descent on the log
    parameters, `optimiser` for `steps` steps) from its best point on the same keys; the
    tuned point, the sweep's best and the defaults re-measured on `held_keys`. A gradient
    refines the basin a global sweep found (the sign-based and resetting laws make the
    loss piecewise smooth); it does not replace the sweep. `points` as in
    `sweep_then_hold_out`."""
    study, method = Study() if study is None else study, problem.check_method(method)
    if study.shard is not None:
        raise ValueError("a tuning follows one path: it needs every run of its sweep, not a shard")
    points = _points(problem, points, method)
    table = sweep(problem, points, keys, method=method, study=study)
    chosen = best(table, problem.metric)
    tuned = tune(
        problem, chosen["params"], keys, method=method, optimiser=optimiser, steps=steps,
        study=Study(progress=study.progress),
    )  # fmt: skip
    named = {
        "tuned": tuned.params,
        "sweep best": chosen["params"],
        "paper": defaults_of(problem, chosen["params"]),
    }
    held = held_out(problem, named, held_keys, method=method, study=study)
    return Selection(table, summarise(table, problem.metric), chosen, held, tuned)


def _points(problem: AbstractProblem, points, method: str) -> dict:
    """A study's points of `method`: a `parse_grid` spec checked (`check_grid`), and every
    axis one the method uses (`AbstractProblem.check_axes`)."""
    if isinstance(points, str):
        points = check_grid(problem, points, problem.title)
    try:
        problem.check_axes(list(points), [method])
    except ValueError as e:
        raise Refused(str(e)) from None
    return points


def merge_summary(table, manifest: Mapping, members) -> dict:
    """What `visjax merge` says of one merged sweep (`merge_sweeps`' `(table, manifest,
    members)`): its runs, chunks, source folders and failed runs, its metric (when the
    manifest names it) and, when any run succeeded, its best point by the mean metric
    (`best`; `None` where no point has a finite mean)."""
    metric = manifest.get("info", {}).get("metric")
    ok = table["result"] == "successful"
    body = {
        "runs": len(table), "chunks": manifest["n_chunks"], "sources": [str(m) for m in members],
        "failed_runs": int((~ok).sum()), "metric": metric,
    }  # fmt: skip
    if metric in table.columns and ok.any():
        try:
            body["best"] = best(table, metric)
        except ValueError:
            body["best"] = None
    return body
