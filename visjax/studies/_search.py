"""`tune_methods`: every method of a problem tuned with the same budget, so that a
comparison compares methods, not tuning effort (`compare_tuned`, the command line's
`visjax compare PROBLEM --tune`).

The search is derivative-free: a scrambled Halton sequence over each method's searched
parameters (`Parameter.search_span`, log-uniform: a gain spread over decades is searched
as evenly at 0.01 as at 100), its first point the defaults. It is blind to what makes a
gradient useless for a baseline (a sign-based law, RANSAC's consensus, a window's length,
a gate), and it gives every method the same number of objective evaluations, `budget`,
each one run of the method over every training seed. A structural parameter (a window's
frames, a fit's bandwidth: `AbstractProblem.structural_parameters`) is searched on a grid
of ratios of $\\sqrt 2$, so the search compiles at most a few programs for it.

A point's score is lexicographic: first the number of training seeds on which the method
failed (any result code but `successful`, or a metric that is not finite), then the median
of the headline metric over the others; the best point is the smallest.
"""

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._xla_workaround import warn_if_hang_prone
from ._compare import compare
from ._methods import WithMethods
from ._problem import AbstractProblem, evaluate
from ._study import Result, Study, study_of

BUDGET = 16
"""`tune_methods`' default budget: objective evaluations per method."""


@dataclass(frozen=True)
class MethodTuning:
    """One method's tuning (`tune_methods`).

    **Fields:** `method`; `searched` (name -> `(low, high)`: the parameters searched and
    their ranges; empty: nothing to tune, only the defaults evaluated); `params` (the best
    point met, name -> float); `defaults` (the searched parameters' defaults);
    `failed`, `median` (the best point's training failures and median metric; `median`
    `None` when every seed failed); `failed0`, `median0` (the same at the defaults);
    `evaluations` (objective evaluations spent); `history` (one dict per evaluation:
    `evaluation`, the parameters, `failed`, `median`)."""

    method: str
    searched: dict
    params: dict
    defaults: dict
    failed: int
    median: float | None
    failed0: int
    median0: float | None
    evaluations: int
    history: list = field(default_factory=list)

    def as_json(self) -> dict:
        """The summary's entry (`tuning.methods[method]`): everything but the history."""
        return {
            "searched": {k: list(v) for k, v in self.searched.items()},
            "params": self.params,
            "defaults": self.defaults,
            "train_failed": self.failed,
            "train_median": self.median,
            "train_failed_at_defaults": self.failed0,
            "train_median_at_defaults": self.median0,
            "evaluations": self.evaluations,
        }


class Tuning(Result, dict):
    """What `tune_methods` returns: method -> `MethodTuning`, with `budget`, `train_seeds`
    and `metric`; `to_pandas()`: every evaluation of every method, one row each
    (`method`, `evaluation`, the parameters, `failed`, `median`)."""

    budget: int = 0
    train_seeds: tuple = ()
    metric: str = ""

    def to_pandas(self):
        import pandas as pd

        return pd.DataFrame([{"method": m, **h} for m, t in self.items() for h in t.history])

    def lines(self) -> list[str]:
        """One printed line per method: the tuned point, and its training median and
        failures against the defaults'."""

        def said(failed, median):
            value = "-" if median is None else f"{median:.4g}"
            return f"{value} ({failed} failed)" if failed else value

        out = [
            f"tuned on {len(self.train_seeds)} training seed(s), {self.budget} evaluations each:"
        ]
        for m, t in self.items():
            point = ", ".join(f"{k} = {v:.4g}" for k, v in t.params.items()) or "nothing to tune"
            out.append(
                f"  {m:<14} {point:<40} training {self.metric} {said(t.failed, t.median)} "
                f"(defaults {said(t.failed0, t.median0)})"
            )
        return out

    def params(self) -> dict[str, dict]:
        """method -> its tuned point (`compare(..., method_params=)`)."""
        return {m: dict(t.params) for m, t in self.items()}

    def as_json(self) -> dict:
        """The summary's `tuning` entry."""
        return {
            "search": "scrambled Halton sequence, log-uniform; the first point the defaults",
            "budget": self.budget,
            "metric": self.metric,
            "train_seeds": [int(s) for s in self.train_seeds],
            "methods": {m: t.as_json() for m, t in self.items()},
        }


def searched_parameters(problem: AbstractProblem, method: str) -> dict[str, tuple]:
    """name -> `(low, high)` of the parameters `tune_methods` searches for `method`: those
    it uses (`method_parameters`) that have a search span (`Parameter.search_span`: a
    positive scalar, a decade either side of its default unless the problem states its
    span; not an array gain, nor one marked `tunable=False`)."""
    specs = problem.parameters()
    out = {}
    for name in problem.method_parameters(method):
        span = specs[name].search_span
        if span is not None:
            out[name] = span
    return out


def _candidates(problem, searched: Mapping[str, tuple], budget: int, seed: int) -> list[dict]:
    """`budget` points: the defaults, then a scrambled Halton sequence mapped log-uniformly
    onto each span (a structural parameter onto its default times powers of sqrt 2)."""
    from scipy.stats import qmc

    specs = problem.parameters()
    names = list(searched)
    default = {n: float(specs[n].value) for n in names}
    own = problem
    while isinstance(own, WithMethods):  # the static fields are the problem's own
        own = own.base
    points = [dict(default)]
    if budget > 1:
        u = qmc.Halton(d=len(names), scramble=True, seed=seed).random(budget - 1)
        for row in u:
            point = {}
            for n, x in zip(names, row):
                lo, hi = np.log(searched[n])
                value = float(np.exp(lo + x * (hi - lo)))
                if n in problem.structural_parameters:
                    step = np.log(2.0) / 2  # a grid of ratios sqrt 2 from the default
                    k = np.round((np.log(value) - np.log(default[n])) / step)
                    value = default[n] * float(np.exp(k * step))
                    if isinstance(getattr(own, n, None), int):
                        value = float(max(1, round(value)))
                point[n] = value
            points.append(point)
    return points


def _score(values) -> tuple[int, float | None]:
    v = np.asarray(values, float)
    good = v[np.isfinite(v)]
    return int(v.size - good.size), (float(np.median(good)) if good.size else None)


def _key(score) -> tuple:
    failed, median = score
    return (failed, np.inf if median is None else median)


def tune_methods(
    problem: AbstractProblem,
    keys: Any,
    *,
    methods: Sequence[str] | None = None,
    budget: int = BUDGET,
    seed: int = 0,
    study: Study | None = None,
) -> Tuning:
    """Tune every method of `problem` (or `methods`) on the training seeds `keys` with the
    same number of objective evaluations (module docstring).

    **Arguments:** `problem`; `keys` (a 1-D array of int training seeds: keep them apart
    from the seeds the methods are then compared on); `methods` (default every one);
    `budget` (objective evaluations per method with something to search, the defaults
    included; a method with none is evaluated once, at its defaults); `seed` (the
    sequence's scrambling); `study` (its `progress`: a progress bar over the evaluations).

    **Returns:** a `Tuning`.
    """
    if not (isinstance(budget, int | np.integer) and budget >= 1):
        raise ValueError(f"`budget` must be an int >= 1; got {budget!r}.")
    if not problem.metric:
        raise ValueError(f"{problem.title}: tuning needs its headline metric (`metric`).")
    keys = np.asarray(keys)
    if keys.ndim != 1 or not keys.size or not np.issubdtype(keys.dtype, np.integer):
        raise ValueError(f"`keys` must be a non-empty 1-D array of int seeds; got {keys!r}.")
    study = study_of(study, "tune")
    chosen = problem.check_methods(methods)
    if keys.size > 1:  # each evaluation is a vmap over the training seeds
        warn_if_hang_prone()
    plans = {}
    for m in chosen:
        searched = searched_parameters(problem, m)
        plans[m] = (searched, _candidates(problem, searched, budget if searched else 1, seed))
    from tqdm import tqdm

    total = sum(len(c) for _, c in plans.values())
    bar = tqdm(total=total, desc="tune", unit="evaluation", disable=not study.progress)
    out = Tuning()
    for m, (searched, points) in plans.items():
        history, best, best_score, seen = [], points[0], None, {}
        for i, point in enumerate(points):
            # a structural parameter's grid repeats points: each is run once (the budget
            # counts it every time, as the sequence drew it)
            at = tuple(point.items())
            if at not in seen:
                ev = evaluate(problem, point, keys, method=m)
                seen[at] = _score(ev.metrics[problem.metric])
            score = seen[at]
            history.append({"evaluation": i, **point, "failed": score[0], "median": score[1]})
            if best_score is None or _key(score) < _key(best_score):
                best, best_score = point, score
            bar.update()
        first = (history[0]["failed"], history[0]["median"])
        out[m] = MethodTuning(
            m, dict(searched), dict(best), dict(points[0]), *best_score, *first,
            evaluations=len(points), history=history,
        )  # fmt: skip
    bar.close()
    out.budget, out.train_seeds, out.metric = int(budget), tuple(keys.tolist()), problem.metric
    return out


def compare_tuned(
    problem: AbstractProblem,
    keys: Any,
    train_keys: Any,
    budget: int = BUDGET,
    *,
    methods: Sequence[str] | None = None,
    noise_levels: Sequence[float] | None = None,
    study: Study | None = None,
):
    """`tune_methods` on `train_keys`, then `compare` of the tuned methods on `keys`
    (refused when the two share a seed; `budget` 0: no tuning, every method at its
    defaults). **Returns:** `(Comparison, Tuning)` (`Tuning` `None` for budget 0)."""
    if budget == 0:
        kw = {"methods": methods, "noise_levels": noise_levels, "study": study}
        return compare(problem, keys, **kw), None
    shared = sorted(set(np.asarray(keys).tolist()) & set(np.asarray(train_keys).tolist()))
    if shared:
        raise ValueError(
            f"the training and the test seeds must be disjoint; both have {shared[:5]}."
        )
    tuning = tune_methods(problem, train_keys, methods=methods, budget=budget, study=study)
    records = compare(
        problem, keys, methods=methods, noise_levels=noise_levels,
        method_params=tuning.params(), study=study,
    )  # fmt: skip
    return records, tuning
