"""`compare`: several methods (an estimator, its baselines) on identical inputs over noise
seeds, with accuracy, result code and timing per run, as tidy records."""

import statistics
import time
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import equinox as eqx
import jax
import numpy as np

from .._results import RESULTS, result_names
from ._problem import AbstractProblem, as_json, component_names, method_runs
from ._stats import bootstrap_interval, paired_comparison
from ._study import Result, Study, seed_keys, study_of
from ._verdict import judge_records


class StudyTooLong(ValueError):
    """A study whose measured first seed puts its whole run time past the limit it was
    given (`compare`'s `max_seconds`): refused after one seed, not found after hours."""


class Comparison(Result, list):
    """What `compare` returns: the records (a list of dicts, one per method and key) and
    `to_pandas()`, them as a tidy table; `medians(metric)`, one row per method. `columns`:
    the problem's names of the metrics' components (`AbstractProblem.columns`)."""

    columns: Mapping[str, Any] = {}

    def to_pandas(self):
        """One row per method and key, one column per number: a vector-valued metric's
        components as columns named by the problem (`rms_v_x`, ..., else `rms_0`, ...),
        a failed run's metrics NaN (never a list, never `None`)."""
        import pandas as pd

        shapes = {}  # a vector-valued entry's shape, from the records that have one
        for record in self:
            for k, v in record.items():
                if isinstance(v, list | tuple):
                    shapes.setdefault(k, np.shape(v))
        rows = []
        for record in self:
            row = {}
            for k, v in record.items():
                if k in shapes:  # `None` (a failed run): NaN components
                    a = np.full(shapes[k], np.nan) if v is None else np.asarray(v, object)
                    a = np.asarray([np.nan if x is None else x for x in a.ravel()], float)
                    names = component_names(k, shapes[k], self.columns.get(k))
                    row.update(zip(names, a, strict=True))
                else:
                    row[k] = v
            rows.append(row)
        table = pd.DataFrame(rows)
        for k in table.columns:  # a metric `None` in every failed record: NaN, a float column
            if table[k].dtype == object and table[k].map(_number_or_none).all():
                table[k] = table[k].astype(float)
        return table

    def medians(self, metric: str) -> list[dict]:
        """Per method, in the records' order: `method`, `failed` (runs that did not
        succeed), `metric` (the median of `metric` over the successful runs; `None` if
        none), `latency` (the median `latency_s_per_sample`), and where the records carry
        a predicted spread (a key `<name>_std`, `AbstractProblem.uncertainty`) `std_key`
        and `std`, the median over the runs of its largest finite entry (`None` if none)."""
        std_key = next((k for k in (self[0] if self else {}) if k.endswith("_std")), None)
        out = []
        for m in dict.fromkeys(r["method"] for r in self):
            rows = [r for r in self if r["method"] == m]
            good = [r[metric] for r in rows if r["result"] == "successful" and r[metric]]
            row = {
                "method": m,
                "failed": sum(r["result"] != "successful" for r in rows),
                "metric": float(np.median(good)) if good else None,
                "latency": float(np.median([r["latency_s_per_sample"] for r in rows])),
            }
            if std_key is not None:
                worst = [w for w in (_largest(r.get(std_key)) for r in rows) if w is not None]
                row.update(std_key=std_key, std=float(np.median(worst)) if worst else None)
            out.append(row)
        return out

    def medians_table(self, metric: str, worse: Mapping[str, int] | None = None):
        """`medians(metric)` as the table `visjax compare` prints (a pandas DataFrame, its
        columns named for a reader); `worse`: per method, the runs no better than the
        trivial estimate (`judge_records`), a column of its own."""
        import pandas as pd

        table = pd.DataFrame(self.medians(metric))
        std = table.pop("std_key").iloc[0] if "std_key" in table else None
        if worse is not None:
            table["worse than trivial"] = table["method"].map(worse)
        names = {"metric": f"{metric} (median)", "std": f"predicted {std}"}
        return table.rename(columns=names | {"latency": "latency/sample (s)"})

    def statistics(
        self, metric: str, *, level: float = 0.95, resamples: int = 2000, seed: int = 0
    ) -> dict:
        """The comparison's uncertainty over its keys (`visjax.studies._stats`): per method
        the median of `metric` over the successful runs with its percentile-bootstrap
        interval (`bootstrap_interval`), the runs, the failure rate and each result code's
        count; for each pair of methods (in the records' order) the paired comparison on
        the keys where both succeeded (`paired_comparison`: the median difference `a - b`,
        its interval, the Wilcoxon signed-rank p-value). Numbers as JSON (`None` for
        NaN); the resamples drawn from `seed`. Records over noise levels (a `noise_px`
        each): `noise_levels` and `by_noise`, the same per level."""
        levels = sorted({r["noise_px"] for r in self if "noise_px" in r})
        if levels:  # a comparison over noise levels (`compare(..., noise_levels=)`)
            by = [
                Comparison(
                    _without(r, "noise_px") for r in self if r.get("noise_px") == x
                ).statistics(metric, level=level, resamples=resamples, seed=seed)
                for x in levels
            ]
            opts = {"level": level, "resamples": resamples, "seed": seed}
            return {"metric": metric, **opts, "noise_levels": levels, "by_noise": by}
        names = list(dict.fromkeys(r["method"] for r in self))
        seeds = sorted({r["seed"] for r in self})
        value = {m: np.full(len(seeds), np.nan) for m in names}
        codes: dict[str, dict[str, int]] = {m: {} for m in names}
        for r in self:
            codes[r["method"]][r["result"]] = codes[r["method"]].get(r["result"], 0) + 1
            x = r.get(metric)
            if r["result"] == "successful" and x is not None and np.ndim(x) == 0:
                value[r["method"]][seeds.index(r["seed"])] = float(x)
        key = jax.random.key(seed)
        opts = {"level": level, "resamples": resamples}
        methods = {}
        for i, m in enumerate(names):
            ci = bootstrap_interval(jax.random.fold_in(key, i), value[m], **opts)
            runs = sum(codes[m].values())
            failed = runs - codes[m].get("successful", 0)
            methods[m] = {
                "median": _number(ci.value), "low": _number(ci.low), "high": _number(ci.high),
                "n": int(ci.n), "runs": runs, "failure_rate": failed / runs, "results": codes[m],
            }  # fmt: skip
        pairs = []
        for i, a in enumerate(names):
            for j, b in enumerate(names[i + 1 :], i + 1):
                k = jax.random.fold_in(key, 1000 + len(names) * i + j)
                c = paired_comparison(k, value[a], value[b], **opts)
                pairs.append(
                    {
                        "a": a,
                        "b": b,
                        "median_difference": _number(c.difference),
                        "low": _number(c.low),
                        "high": _number(c.high),
                        "pvalue": _number(c.pvalue),
                        "n": int(c.n),
                    }  # fmt: skip
                )
        return {"metric": metric, **opts, "seed": seed, "methods": methods, "pairs": pairs}


def comparison_report(problem: AbstractProblem, records: "Comparison", seed: int = 0):
    """What `visjax compare` reports of `records` (of `problem`): `(body, tables,
    warning)`: the summary's `statistics` (`Comparison.statistics`, its resamples from
    `seed`) and `quality` (`judge_records`, where the problem has a trivial estimate);
    the printed tables (the medians per method, without noise levels, then the two of
    `statistics_tables`); a warning line when runs were no better than the trivial
    estimate (else `None`)."""
    body, warning = {}, None
    worse, judged = judge_records(problem, records)
    if judged is not None:
        body["quality"] = judged
    body["statistics"] = stats = records.statistics(problem.metric, seed=seed)
    by_noise = "by_noise" in stats
    medians = () if by_noise else (records.medians_table(problem.metric, worse),)
    if worse is not None and any(worse.values()):
        what = f"{judged['trivial_estimate']} ({problem.metric} {judged['trivial']:.4g})"
        warning = f"warning: {sum(worse.values())} run(s) no better than {what}"
    return body, (*medians, *statistics_tables(stats)), warning


def statistics_tables(stats: Mapping[str, Any]):
    """`Comparison.statistics` as two pandas tables, as `visjax compare` prints and exports
    them: per method (median, interval, successful runs, failure rate, the codes of the
    failures) and per pair (median difference, interval, p-value, pairs)."""
    import pandas as pd

    if "by_noise" in stats:  # one block per noise level, the level its first column
        parts = [statistics_tables(s) for s in stats["by_noise"]]
        return tuple(
            pd.concat([t[i].assign(noise_px=x) for t, x in zip(parts, stats["noise_levels"])])
            .pipe(lambda t: t[["noise_px", *t.columns[:-1]]])
            .reset_index(drop=True)
            for i in (0, 1)
        )
    pct = f"{100 * stats['level']:g}%"
    rows = []
    for m, x in stats["methods"].items():
        failures = {k: v for k, v in x["results"].items() if k != "successful"}
        rows.append(
            {
                "method": m,
                f"{stats['metric']} median": x["median"],
                f"{pct} CI low": x["low"],
                f"{pct} CI high": x["high"],
                "n": x["n"],
                "failure rate": x["failure_rate"],
                "failures": ", ".join(f"{k} {v}" for k, v in failures.items()) or "-",
            }  # fmt: skip
        )
    pairs = [
        {
            "a - b": f"{x['a']} - {x['b']}",
            "median difference": x["median_difference"],
            f"{pct} CI low": x["low"],
            f"{pct} CI high": x["high"],
            "Wilcoxon p": x["pvalue"],
            "pairs": x["n"],
        }  # fmt: skip
        for x in stats["pairs"]
    ]
    return pd.DataFrame(rows), pd.DataFrame(pairs)


def table_text(table, form: str) -> str:
    """A table as Markdown (`"md"`) or LaTeX (`"tex"`, a `tabular` for a paper), numbers
    to 4 significant digits, `-` for a missing one."""
    if form not in ("md", "tex"):
        raise ValueError(f"a table's format must be 'md' or 'tex'; got {form!r}.")

    def cell(v):
        if v is None or (isinstance(v, float) and not np.isfinite(v)):
            return "-"
        return f"{v:.4g}" if isinstance(v, float) else str(v)

    head = [str(c) for c in table.columns]
    body = [[cell(v) for v in row] for row in table.itertuples(index=False)]
    if form == "md":
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in body]) + "\n"

    def tex(text):
        for a, b in (("\\", r"\textbackslash{}"), ("&", r"\&"), ("%", r"\%"), ("_", r"\_")):
            text = text.replace(a, b)
        return text

    lines = [r"\begin{tabular}{" + "l" + "r" * (len(head) - 1) + "}", r"\hline"]
    lines += [" & ".join(tex(h) for h in head) + r" \\", r"\hline"]
    lines += [" & ".join(tex(c) for c in r) + r" \\" for r in body]
    return "\n".join(lines + [r"\hline", r"\end{tabular}"]) + "\n"


def _without(record: Mapping, key: str) -> dict:
    return {k: v for k, v in record.items() if k != key}


def _number(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def _largest(value):
    """The largest finite number of a JSON value (a number, a nested list, `None`)."""
    flat = np.asarray(value if value is not None else np.nan, dtype=object).ravel()
    finite = [float(v) for v in flat if v is not None and np.isfinite(float(v))]
    return max(finite) if finite else None


def compare(
    problem,
    keys: Any = None,
    *old: Any,
    params: Mapping[str, Any] | None = None,
    methods: Sequence[str] | None = None,
    noise_levels: Sequence[float] | None = None,
    method_params: Mapping[str, Mapping[str, Any]] | None = None,
    study: Study | None = None,
    **legacy: Any,
) -> Comparison:
    """Every method of `problem` (its estimator, its baselines and the methods added to
    it), or those named in `methods`, on identical inputs for each noise key, and how each
    did.

    `compare(problem, keys, params=..., study=Study(...))`: the problem's noisy inputs of
    each key (every method sees the same draw), each method's solution with `params`
    overriding the defaults, scored by the problem's `metrics` (as JSON numbers; `None`
    for a failed run), with the problem's `uncertainty` beside them (`None` where a
    method predicts none) and its `updates` for the latency. A plain function joins as a
    `FunctionProblem` (several methods: a dict of functions).

    **Arguments:**

    - `problem`: an `AbstractProblem`.
    - `keys`: the noise seeds: a 1-D array of ints (`jax.random.key(seed)` each) or of
        typed PRNG keys (the records' `seed` is then the index).
    - `params`: name -> value, overriding the defaults for every method.
    - `method_params`: method -> (name -> value) of that method alone, over `params` (a
        tuned point per method, `tune_methods`); not a data parameter (every method sees
        the same draw).
    - `methods`: the methods to run, in this order (default: every one).
    - `noise_levels`: pixel noise levels (px): the comparison at each (the problem's data
        parameter `noise_px`, the same keys), each record tagged with its `noise_px`.
    - `study`: a `Study`: its `repeats` (timed calls per method and key, the median
        reported: on the first key after the call that compiles, on the others the first
        call is one of them), `progress` and `max_seconds` (a limit on
        the whole comparison's run time: after the first key the rest is estimated from
        it, compilation excluded; past the limit, `StudyTooLong` is raised, naming the
        estimate).

    The version-3 forms (`compare(problem, seeds=, first_seed=, ...)`, the functional
    `compare(methods, inputs, score, ...)`) still work, with a `FutureWarning`.

    **Returns:** a `Comparison`: one record per (method, key): `method`, `seed`, `result`
    (the result code's name), `latency_s_per_sample` (median call time / updates: the
    samples for a recursive method, the window fits for a sliding-window fit, 1 for a
    batch fit, whose latency is then a whole re-fit), `total_s` (median call time),
    `compile_s` (the first call, compilation included: the first key only, else `None`)
    and the metrics.
    """
    if noise_levels is not None:
        if "noise_px" not in getattr(problem, "data_parameters", ()):
            what = getattr(problem, "title", type(problem).__name__)
            raise ValueError(f"{what}: noise levels need `noise_px` among its data parameters")
        levels = [float(x) for x in noise_levels]
        if not levels or not all(np.isfinite(x) and x >= 0 for x in levels):
            raise ValueError(f"`noise_levels` must be finite levels >= 0; got {noise_levels!r}.")
        out = Comparison()
        out.columns = problem.columns
        for x in levels:
            at = {**dict(params or {}), "noise_px": x}
            for r in compare(
                problem, keys, params=at, methods=methods, method_params=method_params,
                study=study,
            ):  # fmt: skip
                out.append({**r, "noise_px": x})
        return out
    version3 = {"seeds", "first_seed", "updates"} & set(legacy)
    if not isinstance(problem, AbstractProblem) or old or version3 or keys is None:
        if methods is not None or method_params is not None:
            raise ValueError("`methods` is for `compare(problem, keys, ...)`.")
        return _version3(problem, keys, *old, params=params, study=study, **legacy)
    study = study_of(study, "compare", **legacy)
    typed, seed_values = seed_keys(keys, "compare")
    for m, given in dict(method_params or {}).items():
        data = sorted(set(given) & set(problem.data_parameters))
        if data:
            raise ValueError(
                f"`method_params[{m!r}]` sets data parameter(s) {data}: every method sees "
                "the same draw; set them in `params`."
            )
    resolved = problem.structured(params or {})
    resolved = resolved.at(resolved.resolve(params))  # its data parameters set

    def problem_inputs(key):
        return resolved.inputs(key), None

    def problem_score(name, sol, truth):
        ok = bool(sol.result == RESULTS.successful)
        values = jax.tree_util.tree_map(np.asarray, resolved.metrics(name, sol))
        ok = ok and all(np.all(np.isfinite(v)) for v in values.values())
        spread = jax.tree_util.tree_map(np.asarray, resolved.uncertainty(name, sol))
        return {**as_json(values, ok), **as_json(spread, ok, nullable=True)}

    runs = method_runs(resolved, params, methods, method_params)
    updates = {m: own.updates(m) for m, (_, own) in runs.items()}
    records = _compare(
        {m: solve for m, (solve, _) in runs.items()}, problem_inputs, problem_score, typed,
        seed_values, updates, study,
    )  # fmt: skip
    records.columns = problem.columns
    return records


def _version3(methods, inputs=None, score=None, *, params=None, study=None, **legacy):
    """`compare`'s version-3 forms, with a `FutureWarning`: `compare(problem, seeds=,
    first_seed=, repeats=, progress=, max_seconds=)` and `compare(methods, inputs, score,
    seeds=, first_seed=, updates=, ...)`."""
    allowed = {"seeds", "first_seed", "updates", "repeats", "progress", "max_seconds"}
    unknown = sorted(set(legacy) - allowed)
    if unknown:
        raise TypeError(f"compare() got unexpected keyword argument(s) {unknown}.")
    seeds, first_seed = legacy.pop("seeds", 4), legacy.pop("first_seed", 0)
    updates = legacy.pop("updates", None)
    if seeds < 1:
        raise ValueError(f"`seeds` must be at least 1; got {seeds}.")
    if not (isinstance(first_seed, int) and first_seed >= 0):
        raise ValueError(f"`first_seed` must be a non-negative int; got {first_seed!r}.")
    warnings.warn(
        "`compare(..., seeds=, first_seed=)` and `compare(methods, inputs, score)` are "
        "deprecated: pass `compare(problem, keys, study=Study(...))` (a plain function: "
        "`FunctionProblem`).",
        FutureWarning,
        stacklevel=3,
    )
    keys = np.arange(first_seed, first_seed + seeds)
    if isinstance(methods, AbstractProblem):
        if inputs is not None or score is not None or updates is not None:
            raise ValueError("with a problem, `compare` takes no `inputs`, `score` or `updates`.")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)
            study = study_of(study, "compare", **legacy)
        return compare(methods, keys, params=params, study=study)
    if inputs is None or score is None:
        raise ValueError("`compare(methods, inputs, score)`: `inputs` and `score` are needed.")
    if params is not None:
        raise ValueError("`params` is for `compare(problem, ...)`.")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        study = study_of(study, "compare", **legacy)
    updates = dict(updates or {})
    unknown = set(updates) - set(methods)
    if unknown:
        raise ValueError(f"`updates` names methods not in `methods`: {sorted(unknown)}.")
    typed, seed_values = seed_keys(keys, "compare")
    return _compare(methods, inputs, score, typed, seed_values, updates, study)


def _compare(methods, inputs, score, typed, seed_values, updates, study) -> Comparison:
    """The comparison: `methods` (name -> `inputs -> solution`), compiled once each with
    `equinox.filter_jit` on the first key; `inputs` (`key -> (inputs, truth)`); `score`
    (`(name, solution, truth) -> dict`)."""
    compiled = {name: eqx.filter_jit(fn) for name, fn in methods.items()}
    records = Comparison()
    from tqdm import tqdm

    n = len(seed_values)
    bar = tqdm(total=n * len(methods), desc="compare", unit="run", disable=not study.progress)
    for i in range(n):
        seed = int(seed_values[i])
        started = time.perf_counter()
        data, truth = inputs(typed[i])
        seed_s = time.perf_counter() - started  # the inputs, then every call but compiles
        for name, fn in compiled.items():
            t0 = time.perf_counter()
            sol = jax.block_until_ready(fn(data))
            first = time.perf_counter() - t0
            times = [] if i == 0 else [first]  # past the first key, no call compiles
            for _ in range(study.repeats - len(times)):
                t0 = time.perf_counter()
                jax.block_until_ready(fn(data))
                times.append(time.perf_counter() - t0)
            total = statistics.median(times)
            seed_s += sum(times)  # what each later key costs: `repeats` calls
            records.append(
                {
                    "method": name,
                    "seed": seed,
                    "result": result_names(sol.result),
                    "latency_s_per_sample": total / updates.get(name, 1),
                    "total_s": total,
                    "compile_s": first if i == 0 else None,
                    **score(name, sol, truth),
                }
            )
            bar.update()
        if i == 0 and study.max_seconds is not None and n > 1:
            rest = seed_s * (n - 1)
            if rest > study.max_seconds:
                bar.close()
                raise StudyTooLong(
                    f"{n} seeds would take about {_duration(rest)} more ({seed_s:.3g} s a "
                    f"seed, measured on the first), past the limit of "
                    f"{_duration(study.max_seconds)}"
                )
        if study.stop is not None and study.stop():
            bar.close()
            raise KeyboardInterrupt("the comparison was asked to stop")
    bar.close()
    return records


def _number_or_none(x) -> bool:
    return x is None or (isinstance(x, int | float | np.number) and not isinstance(x, bool))


def _duration(seconds: float) -> str:
    if seconds >= 3600:
        return f"{seconds / 3600:.3g} h"
    return f"{seconds / 60:.3g} min" if seconds >= 60 else f"{seconds:.3g} s"
