"""What a run and a comparison's records amount to: `verdict` (one run of one method: its
result code after the checks a returned code cannot make, its metrics and its quality
against the trivial estimate and its innovation) and `judge_records` (each successful
record of `compare` against the trivial estimate). What `visjax run` and `visjax compare`
report, as library functions."""

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import jax
import numpy as np

from .._results import result_names
from ._problem import AbstractProblem, as_json, quality, quality_line


@dataclass(frozen=True)
class Verdict:
    """One run's verdict: `method`, `result` (the result code's name; `nonfinite_output`
    for a run that reports success with a metric that is not finite), `failed_sample`
    (-1 if none), `metrics` (name -> array), `ok` (succeeded, every metric finite),
    `quality` (`studies.quality`, with the innovation where the problem has one; `None`
    for a failed run or a problem with neither check)."""

    method: str
    result: str
    failed_sample: int
    metrics: dict
    ok: bool
    quality: dict | None

    @property
    def worse_than_trivial(self) -> bool:
        return self.quality is not None and self.quality["flag"] == "worse_than_trivial"

    def metrics_json(self) -> dict:
        """The metrics as JSON numbers (`None` for a failed run)."""
        return as_json(self.metrics, self.ok)

    def outcome(self, dropped: Mapping | None = None) -> tuple[str, str | None]:
        """The run's result code and, when it is not a success, why (one phrase): a failed
        run's code and sample; a data file with too many frames missing (`dropped`, the
        data file's `visjax.io.dropped_report`); an estimate no better than the trivial
        one (`worse_than_trivial`)."""
        if self.result != "successful":
            at = f" at sample {self.failed_sample}" if self.failed_sample >= 0 else ""
            return self.result, f"the run failed: {self.result}{at}"
        if dropped is not None and dropped["over"]:
            return dropped["result"], f"the result is {dropped['result']}: {dropped['line']}"
        if self.worse_than_trivial:
            why = f"the result is worse_than_trivial: {quality_line(self.quality)}"
            return "worse_than_trivial", why
        return "successful", None


def verdict(problem: AbstractProblem, method: str, solution, inputs) -> Verdict:
    """The verdict on `solution`, one run of `method` of `problem` made with
    `outputs=True` on `inputs` (`problem.inputs(key)`; the innovation needs them) at the
    default parameters."""
    code = result_names(solution.result)
    failed_sample = int(np.asarray(getattr(solution, "failed_sample", -1)))
    values = jax.tree_util.tree_map(np.asarray, problem.metrics(method, solution))
    ok = code == "successful" and all(np.all(np.isfinite(v)) for v in values.values())
    if code == "successful" and not ok:  # a metric that is NaN: not a success
        code = "nonfinite_output"
    judged = None
    if ok:
        innovation = problem.innovation(method, problem.resolve({}), solution, inputs)
        judged = quality(problem, values, innovation=innovation)
    return Verdict(method, code, failed_sample, values, ok, judged)


def judge_records(
    problem: AbstractProblem, records: list[Mapping[str, Any]]
) -> tuple[dict | None, dict | None]:
    """Each successful record of `compare` (of `problem`) against the trivial estimate
    (`studies.quality`): its `ratio_to_trivial` is added to the record. **Returns:**
    `(counts, summary)`: per method the runs no better than the trivial estimate, and the
    comparison's `quality` (the trivial estimate, its metric, the threshold and the
    counts); `(None, None)` for a problem without a trivial estimate."""
    counts: dict[str, int] = {m: 0 for m in problem.methods}
    judged, trivial = None, problem.trivial() if problem.scored else {}
    for r in records:
        value = r.get(problem.metric)
        if r["result"] != "successful" or value is None:
            continue
        judged = quality(problem, {problem.metric: value}, trivial)
        if judged is None:
            return None, None
        r["ratio_to_trivial"] = judged["ratio_to_trivial"]
        counts[r["method"]] += judged["flag"] != "ok"
    if judged is None:
        return None, None
    summary = {
        "trivial_estimate": judged["trivial_estimate"],
        "metric": judged["metric"],
        "trivial": judged["trivial"],
        "threshold": judged["threshold"],
        "worse_than_trivial": counts,
    }
    return counts, summary
