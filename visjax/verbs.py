"""The commands `run|compare|sweep|tune PROBLEM` over any registered problem, and `merge`:
each takes a `Request` (the command line's options), calls `visjax.studies`, prints, and
writes `summary.json` (its schema in `visjax.io.SUMMARIES`), tables (Parquet and CSV) and
figures into `out` when given (and a Rerun recording, `rerun`, for `run` and `compare`). A
problem with variants (the thesis' sets) runs variant by variant, a folder each, under a
summary of kind `sets`; with a paper's data file, every summary reports `dropped_fraction`.
"""

import contextlib
import dataclasses
import json
import shutil
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from . import recording, studies
from .io import command_summary, dropped_report, output_name, user_path
from .plots import plot_comparison, plot_noise_study, plot_sweep, plot_tune_history, save_figure
from .report import RunFailed
from .studies import Refused, Study, innovation_line, quality_line, registered

MAX_HOURS = 24.0
"""`compare`'s default limit on its whole run time, hours (`--max-hours`, after one seed)."""


@dataclasses.dataclass(frozen=True)
class Request:
    """A command's options, named as the command line's (`--set`: `variants`): `shard` is
    `True` (each chunk over every JAX device) or `(i, N)` (the i-th of N slices of a
    sweep); `options`: more of the problem builder's arguments; `paths`: `merge`'s."""

    command: str
    problem: str = ""
    method: str | None = None
    methods: Sequence[str] | None = None
    data: str | Path | None = None
    noise: float | Sequence[float] | None = None  # None: the problem's; compare: levels
    seed: int = 0
    seeds: int = 1
    duration: float | None = None
    rate: float | None = None
    variants: Sequence[str] | None = None
    robust: bool = False
    grid: str | None = None
    chunk: int = 64
    shard: bool | tuple[int, int] = False
    steps: int = 30
    learning_rate: float = 0.1
    resume: bool = False
    force: bool = False
    ray: str | None = None
    max_hours: float = MAX_HOURS
    paths: Sequence[str] = ()
    out: str | None = None
    quiet: bool = False
    formats: Sequence[str] = ("png",)
    tables: Sequence[str] = ()
    tune: bool = False  # compare: every method tuned first (`studies.compare_tuned`)
    budget: int = studies.BUDGET
    options: dict | None = None
    rerun: str | None = None  # run, compare: a Rerun recording (`visjax.recording`)

    def __post_init__(self):
        if self.command == "sweep" and self.out is None and (self.resume or self.force or self.job):
            raise ValueError("--resume, --force and --shard i/N need --out (where the parts are)")
        if self.resume and self.force:
            raise ValueError("--resume and --force exclude each other")
        if self.command == "tune" and self.job is not None:
            raise ValueError("--shard i/N is for sweep (tune follows one path: it needs every run)")

    @property
    def job(self) -> tuple[int, int] | None:
        """`shard` when it is a job's slice `(i, N)`, else `None`."""
        return tuple(self.shard) if isinstance(self.shard, tuple | list) else None

    def settings(self) -> dict:
        """The options as JSON (a summary's `settings`)."""
        return json.loads(json.dumps(dataclasses.asdict(self), default=str))

    def problems(self) -> list:
        """The problems the command runs, each variant's (`studies.build_problems`)."""
        return studies.build_problems(
            self.problem, data=self.data, noise_px=self.noise, duration=self.duration,
            rate_hz=self.rate, variants=self.variants, every=self.command in ("sweep", "tune"),
            robust=self.robust, options=self.options,
        )  # fmt: skip

    def keys(self, held: bool = False):
        """The seeds `seed, ..., seed + seeds - 1`; `held`: the next `seeds` (held out)."""
        return np.arange(first := self.seed + (self.seeds if held else 0), first + self.seeds)


def check_study(r: Request) -> list:
    """The problems, built once, for the command (`built=`), its methods checked on them,
    and a study's size before any work (`studies.check_study`: runs, grid, memory);
    `Refused`, one line."""
    return studies.check_study(
        r.command, registered(r.problem).name, r.problems, spec=r.grid, seeds=r.seeds,
        study=Study(chunk=r.chunk, shard=r.job), variants=len(r.variants) if r.variants else 1,
        steps={"tune": r.steps, "compare": r.budget * r.tune}.get(r.command, 0),
        methods=[r.method] if r.command == "run" else r.methods,
    )  # fmt: skip


def _each(r: Request, items, one) -> dict:
    """`one(item, head, folder) -> (kind, body, folder)` for each `(tag, item)` (variants),
    its summary written; the one summary, or those by variant under one of kind `sets`."""
    started, settings, results = time.perf_counter(), r.settings(), {}
    with recording.request_log(r) as log:  # --rerun: each method's run of the first seed
        for tag, item in items:
            folder = None if r.out is None else Path(r.out) / (output_name(tag) if tag else "")
            kind, body, folder = one(item, f"[{tag}] " if tag else "", folder)
            log(tag, item)
            results[tag] = command_summary(
                kind, body, settings=settings, seed=r.seed, started=started, out=folder
            )
    summary = results.get(None) if list(results) == [None] else command_summary(
        "sets", {"sets": results}, settings=settings, seed=r.seed, started=started, out=r.out
    )  # fmt: skip
    none = "nothing written (no --out DIR: the summary, tables and figures were not kept)"
    print(none if r.out is None else f"wrote {user_path(str(r.out))}")
    return summary


def _dropped(r: Request) -> dict | None:
    """`io.dropped_report` of the request's data file (`None`: none, or not a paper's)."""
    return None if r.data is None else dropped_report(registered(r.problem).name, r.data)


def _say_dropped(body: dict, dropped, head: str) -> None:
    if dropped is not None:
        body["dropped_fraction"] = dropped["fraction"]
        print(f"{head}{dropped['line']}")


def run_command(r: Request, built=None) -> dict:
    """`visjax run PROBLEM`: one method (default the estimator) once, `noise` px of noise
    (seed `seed`): prints its result and metrics, writes `summary.json` (kind `run`),
    `estimates.parquet` (the outputs over time) and `run.<format>` (the problem's figure).
    A run that does not succeed (`studies.Verdict.outcome`: a failed run, a data file with
    too many frames missing, an estimate worse than the trivial one) is written as well,
    then raises `RunFailed`."""
    import jax
    import pandas as pd

    failures, dropped = [], _dropped(r)

    def one(p, head, folder):
        m = p.check_method(r.method)
        sol = jax.block_until_ready(studies.solution(p, None, r.seed, method=m))
        v = studies.verdict(p, m, sol, p.inputs(jax.random.key(r.seed)))
        code, why = v.outcome(dropped)
        if why is not None:
            failures.append(f"run {r.problem}: {head}{why}")
        body = {
            "problem": p.title, "method": m, "result": code, "failed_sample": v.failed_sample,
            "metrics": v.metrics_json(), "gains": p.gains({}), "problem_settings": p.settings(),
        }  # fmt: skip
        print(f"{head}{p.title}: {m}, {code}")
        if v.quality is not None:
            body["quality"] = v.quality
            print(f"{head}  quality: {quality_line(v.quality)}")
            if why is None and v.quality.get("innovation", {}).get("flag", "ok") != "ok":
                warn = innovation_line(v.quality["innovation"])
                print(f"warning: run {r.problem}: {head}{warn}", file=sys.stderr)
        _say_dropped(body, dropped, f"{head}  ")
        for k, x in body["metrics"].items():
            print(f"{head}  {k} = {'-' if x is None else x}")
        if folder is not None:
            folder.mkdir(parents=True, exist_ok=True)
            table = pd.DataFrame(studies.solution_table(sol, p, m))
            table.to_parquet(folder / "estimates.parquet", index=False)
            save_figure(p.figure(m, sol), folder / "run.png", r.formats)
        return "run", body, folder

    summary = _each(r, built or r.problems(), one)
    if failures:
        more = f" (and {len(failures) - 1} more)" if len(failures) > 1 else ""
        raise RunFailed(failures[0] + more)
    return summary


def compare_command(r: Request, built=None) -> dict:
    """`visjax compare PROBLEM`: every method of the problem (or `methods`) on identical
    noisy inputs (`studies.compare`, `seeds` seeds), refused after the first seed when the
    whole would pass `max_hours`. Prints the medians per method, their intervals and the
    paired comparisons (`Comparison.statistics`); writes `summary.json` (kind `compare`: a
    record per method and seed, `statistics`), `records.parquet`, `records.csv`,
    `comparison.<format>` and `comparison.md|tex` (`tables`). `tune`: each method first
    tuned with `budget` evaluations on as many other seeds (`studies.compare_tuned`; the
    summary's `tuning`, `tuning.parquet`)."""
    dropped = _dropped(r)

    def one(p, head, folder):
        try:
            hours, levels = r.max_hours * 3600, r.noise if np.ndim(r.noise) else None
            study = Study(progress=not r.quiet, max_seconds=hours, repeats=1)  # 1 timed call
            kw = {"methods": r.methods, "noise_levels": levels, "study": study}
            kw["budget"] = r.budget if r.tune else 0  # 0: the defaults, untuned
            records, tuning = studies.compare_tuned(p, r.keys(), r.keys(True), **kw)
        except studies.StudyTooLong as e:
            where = f"compare {r.problem} {head}".strip()
            raise Refused(f"{where}: {e}: use fewer --seeds or raise --max-hours") from None
        body = {
            "problem": r.problem, "data": None if r.data is None else str(r.data),
            "noise_px": studies.noise_level(p, r.noise), "seeds": r.seeds,
            "problem_settings": p.settings(), "records": records,
        }  # fmt: skip
        label = p.label or p.metric
        print(f"{head}{p.title}: {r.seeds} noise seed(s); {p.metric}: {label}")
        if tuning is not None:
            body["tuning"] = tuning.as_json()
            print("\n".join(head + line for line in tuning.lines()))
        _say_dropped(body, dropped, head)
        more, tables, warning = studies.comparison_report(p, records, r.seed)
        body |= more
        for t in tables:
            print(t.to_string(index=False, na_rep="-", float_format="{:.4g}".format))
        if warning is not None:
            print(f"{head}{warning}")
        if folder is not None:
            folder.mkdir(parents=True, exist_ok=True)
            for form in r.tables:  # the statistics' two tables, for a paper
                text = "\n".join(studies.table_text(t, form) for t in tables[-2:])
                (folder / f"comparison.{form}").write_text(text)
            studies.save_table(records.to_pandas(), folder, "records")
            if tuning is not None:
                studies.save_table(tuning.to_pandas(), folder, "tuning")
            fig = {"label": label, "title": p.title, "formats": r.formats}
            if levels:  # the error against the noise level, with its interval, per method
                plot_noise_study(body["statistics"], path=folder / "noise.png", **fig)
            accuracy = lambda x, k=p.metric: np.nan if x[k] is None else x[k]  # noqa: E731
            plot_comparison(records, accuracy, path=folder / "comparison.png", **fig)
        return "compare", body, folder

    return _each(r, built or r.problems(), one)


def sweep_command(r: Request, built=None) -> dict:
    """`visjax sweep PROBLEM`: the grid (`--grid`, default the problem's) over `seeds`
    seeds, its best point by the mean metric, it and the defaults re-measured on `seeds`
    held-out seeds (`studies.sweep_then_hold_out`): `runs.parquet`, `runs.csv`,
    `sweep.<format>`, `summary.json` (kind `sweep`). With `out`, each chunk's rows as it
    finishes (`studies.sweep_parts`: `resume` continues an interrupted sweep, `force`
    replaces a finished one); `shard=(i, N)`: the i-th of N slices (`visjax merge`).
    `visjax tune PROBLEM` (`r.command == "tune"`): the sweep, then Adam on the log
    parameters (`steps` steps) from its best point, the tuned point held out as well
    (`studies.sweep_then_tune`): also `history.csv` and `tune.<format>` (kind `tune`)."""
    import optax

    tune, job, executor, dropped = r.command == "tune", r.job, None, _dropped(r)
    mesh = studies.device_mesh() if r.shard is True else None
    if r.ray is not None:
        try:
            executor = studies.RayExecutor(address=None if r.ray == "local" else r.ray)
        except (ImportError, ConnectionError) as e:
            raise ValueError(str(e)) from None

    def one(pm, head, folder):
        p, method = pm
        if not p.scored:
            raise ValueError(f"{p.title}: {r.command} needs the truth (the data file has none)")
        parts, spec, keys = None, r.grid or p.grid, (r.keys(), r.keys(held=True))
        if folder is not None and not tune:
            parts = studies.sweep_parts(folder, job, resume=r.resume, force=r.force)
        try:
            with studies.interruptible() if parts else contextlib.nullcontext() as stop:
                study = Study(
                    chunk=r.chunk, mesh=mesh, shard=job, executor=executor, parts=parts,
                    resume=r.resume and parts is not None, max_memory="available",
                    progress=not r.quiet, log=None if r.quiet else print, stop=stop,
                )  # fmt: skip
                adam = {"optimiser": optax.adam(r.learning_rate), "steps": r.steps}
                select = studies.sweep_then_tune if tune else studies.sweep_then_hold_out
                kw = {"method": method, **(adam if tune else {})}
                found = select(p, spec, *keys, study=study, **kw)
        except KeyboardInterrupt:
            if parts is None:
                raise
            done, n = studies.saved_runs(parts)
            saved = f"visjax: interrupted: {done} of {n} runs are saved in {parts}"
            sys.stderr.write(f"{saved}; run the same command with --resume to continue\n")
            raise SystemExit(130) from None
        if job is not None:  # no summary in the folder (it would replace the other slices')
            merge = "when every shard is done: visjax merge DIR... --out OUT"
            print(f"{head}shard {job[0]}/{job[1]}: {len(found)} runs written to {parts}; {merge}")
            body = {"runs": len(found), "shard": list(job), "parts": str(parts)}
            return "sweep_shard", body, None
        print("\n".join(head + line for line in found.lines(p)))
        result = found.report(p) | {"method": p.check_method(method), "grid": spec}
        result |= {"noise_px": studies.noise_level(p, r.noise), "seeds": r.seeds}
        result["held_out_seeds"] = r.keys(held=True)[[0, -1]].tolist()
        if tune:
            adam = f"optax.adam({r.learning_rate}) on the log parameters, forward mode"
            result |= {"steps": r.steps, "optimiser": adam}
            gain = result["improvement_over_paper"]
            line = f"held-out improvement over the defaults: x {gain:.3g}"
        else:
            line = f"{result['failed_runs']} of {result['runs']} sweep runs failed"
        print("; ".join([f"{head}{line}", *(p.check_lines(result) if tune else ())]))
        _say_dropped(result, dropped, head)
        if folder is not None:  # the table, and the metric against each parameter
            studies.save_table(found.sweep, folder)
            plot_sweep(
                found.summary, p.metric, list(found.best["params"]), paper=found.held["paper"],
                best=found.held["tuned" if tune else "best"], paper_label=p.defaults_label,
                label=p.label, title=p.title, path=folder / "sweep.png", formats=r.formats,
                units={k: v.units for k, v in p.parameters().items()},
            )  # fmt: skip
        if folder is not None and tune:
            found.tuned.to_pandas().to_csv(folder / "history.csv", index=False)
            plot_tune_history(
                found.tuned.history, label=f"training {p.label}", title=p.title,
                path=folder / "tune.png", formats=r.formats,
            )  # fmt: skip
        elif folder is not None:  # the parts come along with the other outputs (a copy:
            # until the outputs are in place, the parts where they were written stay whole)
            shutil.copytree(parts, folder / "parts", dirs_exist_ok=True)
        return r.command, result, folder

    methods = r.methods or (None,)  # several: a folder each (with the variant's name)
    items = [
        (" ".join(filter(None, (tag, m if len(methods) > 1 else None))) or None, (p, m))
        for tag, p in built or r.problems() for m in methods
    ]  # fmt: skip
    try:
        return _each(r, items, one)
    finally:
        if executor is not None:
            executor.shutdown()


def merge_command(r: Request) -> dict:
    """`visjax merge DIR...`: the parts of one sweep's shards (or of an interrupted run and
    its resumption) under `paths` as one table (`studies.merge_sweeps`; parts of different
    sweeps, a run found twice or missing refused): `runs.parquet`, `runs.csv` and
    `summary.json` (kind `merge`, `studies.merge_summary`); a folder per variant."""

    def one(found, head, folder):
        table, _, members = found
        print(f"{head}merged {len(table)} runs from {len(members)} parts folder(s)")
        if folder is not None:
            studies.save_table(table, folder)
        return "merge", studies.merge_summary(*found), folder

    return _each(r, studies.merge_sweeps(r.paths).items(), one)
