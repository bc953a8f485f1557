"""The study commands over any registered problem (`visjax.studies.register_problem`):
`run` (one method once, with its figure), `compare` (every method on identical noisy
inputs), `sweep` (a grid of parameters over noise seeds) and `tune` (a sweep, then
gradient descent from its best point). The command line's `visjax run|compare|sweep|tune
PROBLEM` call these; nothing here knows a problem.

Each writes `summary.json` (its schema in `visjax.io.SUMMARIES`), its tables (Parquet and
CSV) and figures into `out` when given (staged by the command line: `visjax.io`). A problem
with named variants (the thesis' experiment sets) is swept and tuned variant by variant
(all of them unless `variants` names some), one folder each, with a top-level summary of
kind `sets`.

`run` is one run: when it does not succeed it raises `visjax.report.RunFailed` once its
files are written. `compare`, `sweep` and `tune` are many runs: each run's result code is
in their tables, and a failed run is not a failed command. `check_study` sizes a study
before any work (`Refused`). With a data file in one of the papers' formats, every
summary reports `dropped_fraction`.
"""

import shutil
import sys
import time
from pathlib import Path

import numpy as np

from . import studies
from .io import (
    command_summary,
    dropped_report,
    figure_files,
    output_name,
    user_path,
    written_directly,
)
from .plots import plot_comparison, plot_sweep, plot_tune_history, save_figure
from .report import RunFailed
from .studies import (
    MemoryLimitError,
    Refused,
    Study,
    check_grid,
    check_run_count,
    clear_parts,
    grid_size,
    innovation_line,
    quality_line,
    registered,
    saved_runs,
    solution,
    solution_table,
    study_runs,
)

MAX_HOURS = 24.0
"""`compare`'s default limit on its run time, hours (`--max-hours`): measured on the first
seed, a comparison estimated to take longer is refused then (a comparison is not resumable,
unlike a sweep)."""


def _settings(arguments: dict) -> dict:
    out = {k: v for k, v in arguments.items() if k not in ("started", "built")}
    for k in ("data", "out"):
        if out.get(k) is not None:
            out[k] = str(out[k])
    if out.get("variants") is not None:
        out["variants"] = list(out["variants"])
    out["formats"] = list(out.get("formats", ()))
    return out


def problems(
    name, data=None, noise=0.1, duration=None, rate=None, variants=None, every=True, robust=False,
    options=None,
):  # fmt: skip
    """`[(tag, problem)]`: the registered problem `name` once (tag `None`), or, for a
    problem with named variants, once per variant (`variants`, default all of them when
    `every`, else the problem's default); `robust`: the problem's robust settings (its
    builder's `robust=True`); `options`: more of its builder's keyword arguments (`None`
    values left out). **Raises:** `ValueError` for an unknown problem, variant or option
    (a problem without robust settings takes no `--robust`)."""

    entry = registered(name)
    data = None if data is None else str(data)
    extra = {k: v for k, v in (options or {}).items() if v is not None}

    def build(variant):
        return entry.make(
            data=data, noise_px=noise, duration=duration, rate_hz=rate, variant=variant,
            robust=True if robust else None, **extra,
        )  # fmt: skip

    entry.check(data, duration, rate, variants)
    if variants:
        return [(v, build(v)) for v in variants]
    if entry.variants and every and data is None:
        return [(v, build(v)) for v in entry.variants]
    return [(None, build(None))]


def check_study(
    command, problem, *, grid=None, seeds=1, chunk=64, steps=0, data=None, noise=0.1,
    duration=None, rate=None, variants=None, robust=False, shard=None,
) -> list | None:  # fmt: skip
    """What the command line checks of `compare`, `sweep` and `tune` before any work:
    the run count (at most `studies.MAX_RUNS`; first from the grid's text, before the
    problem is built), then on the problem, built once (the command takes it: `built`), the
    grid (`studies.check_grid`: `--grid`, or the problem's default) and `studies.plan`
    (the run count again, a lower bound of the memory against `available_memory()`, of
    the job's slice with `shard=(i, N)`). (The sweep then measures a chunk's compiled
    program before it runs one: `Study.max_memory`.) **Raises:** `Refused`, one line; what
    building the problem raises (a data file's `DataFormatError`). **Returns:** the built
    problems, `[(tag, problem)]`, for the command (`built=`: each problem built once)."""
    if command not in ("compare", "sweep", "tune"):
        return None
    count = 1 if grid is None else grid_size(grid)
    n_variants = len(variants) if variants else 1
    if count is not None:
        points = f"{count} grid points x {seeds} seeds" if grid else f"{seeds} seeds"
        points += f" and {steps} steps" if command == "tune" else ""
        check_run_count(command, n_variants * study_runs(command, count, seeds, steps), points)
    entry = registered(problem)
    every = command != "compare"
    built = problems(entry.name, data, noise, duration, rate, variants, every, robust)
    study = Study(chunk=chunk, shard=shard if isinstance(shard, tuple) else None)
    total = 0
    for tag, p in built:
        where = entry.name if tag is None else f"{entry.name} [{tag}]"
        params = None if command == "compare" else check_grid(p, grid or p.grid, where)
        found = studies.plan(p, params, seeds, study, kind=command, steps=steps)
        found.check(where)
        total += found.runs
    check_run_count(command, total, f"{len(built)} problem(s), their grids and {seeds} seeds")
    return built


def _folder(out, tag):
    if out is None:
        return None

    return Path(out) if tag is None else Path(out) / output_name(tag)


def _result(results: dict, settings, seed, started, out):
    """The one summary, or the summaries by variant (a `sets` summary at the top)."""
    if list(results) == [None]:
        summary = results[None]
    else:
        summary = command_summary(
            "sets", {"sets": results}, settings=settings, seed=seed, started=started, out=out
        )
    if out is not None:
        print(f"wrote {out}")
    return summary


def run_command(
    problem: str,
    method: str | None = None,
    data=None,
    noise: float = 0.0,
    seed: int = 0,
    duration: float | None = None,
    rate: float | None = None,
    variants=None,
    robust: bool = False,
    out=None,
    quiet: bool = False,
    formats=("png",),
    options=None,
    built=None,
) -> dict:
    """`visjax run PROBLEM`: one method (default the estimator) once, on the problem's
    scene or data file with `noise` px of pixel noise (seed `seed`; `options`: more of the
    problem's builder's keyword arguments, e.g. `{"filter_hz": 5.0}`); prints its result and
    metrics; writes `summary.json` (kind `run`), `estimates.parquet` (the saved outputs
    over time, one column per component) and `run.<format>` (the problem's figure). A run
    that does not succeed (or one on a data file whose frames miss a feature in more than
    `visjax.io.MAX_DROPPED_FRACTION` of them: `too_many_dropped_frames`) is written as
    well, its result code in the summary and no metrics, then raises
    `visjax.report.RunFailed`."""
    started = time.perf_counter()
    settings = _settings(locals())
    import jax

    results, failures = {}, []
    dropped = _dropped(problem, data)
    for tag, p in built or problems(
        problem, data, noise, duration, rate, variants, every=False, robust=robust,
        options=options,
    ):  # fmt: skip
        m = p.check_method(method)
        sol = jax.block_until_ready(solution(p, None, seed, method=m))
        v = studies.verdict(p, m, sol, p.inputs(jax.random.key(seed)))
        code, judged, head, failure = v.result, v.quality, f"[{tag}] " if tag else "", None
        if code != "successful":
            at = f" at sample {v.failed_sample}" if v.failed_sample >= 0 else ""
            failure = f"run {problem}: {head}the run failed: {code}{at}"
        elif dropped is not None and dropped["over"]:
            code = dropped["result"]
            failure = f"run {problem}: {head}the result is {code}: {dropped['line']}"
        elif v.worse_than_trivial:
            code = "worse_than_trivial"
            failure = f"run {problem}: {head}the result is {code}: {quality_line(judged)}"
        body = {
            "problem": p.title, "method": m, "result": code, "failed_sample": v.failed_sample,
            "metrics": v.metrics_json(), "gains": p.gains({}), "problem_settings": p.settings(),
        }  # fmt: skip
        if dropped is not None:
            body["dropped_fraction"] = dropped["fraction"]
        if judged is not None:
            body["quality"] = judged
        print(f"{head}{p.title}: {m}, {code}")
        if judged is not None:
            print(f"{head}  quality: {quality_line(judged)}")
            if failure is None and judged.get("innovation", {}).get("flag", "ok") != "ok":
                warn = innovation_line(judged["innovation"])
                print(f"warning: run {problem}: {head}{warn}", file=sys.stderr)
        if dropped is not None:
            print(f"{head}  {dropped['line']}")
        for k, v in body["metrics"].items():
            print(f"{head}  {k} = {'-' if v is None else v}")
        folder = _folder(out, tag)
        if folder is not None:
            import pandas as pd

            folder.mkdir(parents=True, exist_ok=True)
            pd.DataFrame(solution_table(sol)).to_parquet(folder / "estimates.parquet", index=False)
            save_figure(p.figure(m, sol), folder / "run.png", formats)
        results[tag] = command_summary(
            "run", body, settings=settings, seed=seed, started=started, out=folder
        )
        if failure is not None:
            failures.append(failure)
    summary = _result(results, settings, seed, started, out)
    if failures:
        more = f" (and {len(failures) - 1} more)" if len(failures) > 1 else ""
        raise RunFailed(failures[0] + more)
    return summary


def _dropped(problem, data) -> dict | None:
    """`io.dropped_report` of the data file of the registered problem `problem`."""
    return None if data is None else dropped_report(registered(problem).name, data)


def _say_dropped(body: dict, dropped, head: str) -> None:
    """`dropped_fraction` into a study's summary, and its line printed."""
    if dropped is not None:
        body["dropped_fraction"] = dropped["fraction"]
        print(f"{head}{dropped['line']}")


def compare_command(
    problem: str,
    data=None,
    noise: float = 0.1,
    seeds: int = 4,
    duration: float | None = None,
    out=None,
    quiet: bool = False,
    seed: int = 0,
    formats=("png",),
    rate: float | None = None,
    variants=None,
    robust: bool = False,
    max_hours: float = MAX_HOURS,
    built=None,
) -> dict:
    """`visjax compare PROBLEM`: every method of the problem (the estimator, its batch
    baselines, its EKF) on identical noisy inputs (`visjax.studies.compare`, noise seeds
    `seed, ..., seed + seeds - 1`), from the problem's scene or a data file (noise added
    on top of its pixels). A comparison whose first seed puts the whole past `max_hours`
    is refused then (`Refused`, naming the estimate). Writes `summary.json` (kind
    `compare`: `records`, one per method and seed, and `problem_settings`),
    `records.parquet`, `records.csv` and
    `comparison.<format>` (accuracy and latency with their spread over seeds), and prints
    the medians per method (and the predicted standard deviation where the problem has
    one, `AbstractProblem.uncertainty`). With a data file in one of the papers' formats,
    `dropped_fraction` (each run's result code is its own: many runs, no failed command)."""
    started = time.perf_counter()
    settings = _settings(locals())
    import pandas as pd

    results = {}
    dropped = _dropped(problem, data)
    for tag, p in built or problems(
        problem, data, noise, duration, rate, variants, every=False, robust=robust
    ):
        try:
            study = Study(progress=not quiet, max_seconds=max_hours * 3600)
            records = studies.compare(p, np.arange(seed, seed + seeds), study=study)
        except studies.StudyTooLong as e:
            where = problem if tag is None else f"{problem} [{tag}]"
            raise Refused(f"compare {where}: {e}: use fewer --seeds or raise --max-hours") from None
        body = {
            "problem": problem,
            "data": None if data is None else str(data),
            "noise_px": noise,
            "seeds": seeds,
            "problem_settings": p.settings(),
            "records": records,
        }
        head = f"[{tag}] " if tag else ""
        label = p.label or p.metric
        print(f"{head}{p.title}: {seeds} noise seed(s); {p.metric}: {label}")
        _say_dropped(body, dropped, head)
        worse, judged = studies.judge_records(p, records)
        if judged is not None:
            body["quality"] = judged
        rows = records.medians(p.metric)
        std_key = rows[0].get("std_key") if rows else None
        std_head = f"{'predicted ' + std_key:>28}" if std_key else ""
        worse_head = f"{'worse than trivial':>20}" if worse is not None else ""
        print(
            f"{'method':<14}{'failed':>8}{p.metric + ' (median)':>24}{std_head}"
            f"{'latency/sample (s)':>20}{worse_head}"
        )
        for r in rows:
            acc = "-" if r["metric"] is None else f"{r['metric']:.4g}"
            std = (
                "" if not std_key else f"{'-' if r['std'] is None else format(r['std'], '.4g'):>28}"
            )
            bad = "" if worse is None else f"{worse[r['method']]:>20}"
            print(f"{r['method']:<14}{r['failed']:>8}{acc:>24}{std}{r['latency']:>20.3g}{bad}")
        if worse is not None and any(worse.values()):
            q = body["quality"]
            print(
                f"{head}warning: {sum(worse.values())} run(s) no better than "
                f"{q['trivial_estimate']} ({p.metric} {q['trivial']:.4g}; column above)"
            )
        folder = _folder(out, tag)
        if folder is not None:
            folder.mkdir(parents=True, exist_ok=True)
            table = pd.DataFrame(records)
            table.to_parquet(folder / "records.parquet", index=False)
            table.to_csv(folder / "records.csv", index=False)
            plot_comparison(
                records,
                lambda r, metric=p.metric: r[metric] if r[metric] is not None else float("nan"),
                label=label,
                title=p.title,
                path=folder / "comparison.png",
                formats=formats,
            )
            print(
                f"wrote {folder / 'summary.json'}, {folder / 'records.parquet'}, "
                f"{folder / 'records.csv'}, {figure_files(folder / 'comparison.png', formats)}"
            )
        results[tag] = command_summary(
            "compare", body, settings=settings, seed=seed, started=started, out=folder
        )
    if list(results) == [None]:
        return results[None]
    return _result(results, settings, seed, started, out)


def _mesh(shard: bool):
    if not shard:
        return None
    import jax
    from jax.sharding import Mesh

    return Mesh(np.array(jax.devices()), ("runs",))


def _held_keys(first: int, seeds: int):
    """The held-out seeds after a study's own `first, ..., first + seeds - 1`: the next
    `seeds`."""
    return np.arange(first + seeds, first + 2 * seeds)


def _selected(problem, grid, seeds, first, study, tune=None):
    """The command's sweep then its held-out measure (`tune`: `(optimiser, steps)`, then
    `studies.sweep_then_tune`): `(spec, selection)`; with a job slice, the slice's
    `SweepResult` (no best: that needs every run, after `visjax merge`)."""
    spec = grid or getattr(problem, "grid", "")
    if not spec:
        raise ValueError(f"{problem.title} has no default grid: give --grid")
    points = studies.parse_grid(spec)
    keys, held = np.arange(first, first + seeds), _held_keys(first, seeds)
    try:
        if tune is not None:
            optimiser, steps = tune
            return spec, studies.sweep_then_tune(
                problem, points, keys, held, optimiser=optimiser, steps=steps, study=study
            )
        return spec, studies.sweep_then_hold_out(problem, points, keys, held, study=study)
    except MemoryLimitError as e:  # the sweep's own memory check (XLA's analysis of a chunk)
        raise Refused(str(e)) from None


def _job_slice(shard):
    """`shard` as the command line parses it (`--shard`): `True` (or `"devices"`): every
    chunk over every JAX device (a mesh); `(i, N)`: the i-th of N disjoint slices of the
    runs (a job array; checked by `studies.Study`). **Returns:** `(devices, slice)`."""
    if shard is True or shard == "devices":
        return True, None
    return False, (None if shard in (None, False) else tuple(shard))


def _parts_folder(folder: Path, job) -> Path:
    """Where a sweep's parts go: beside its other outputs, in the folder the user asked
    for (never the staging one: an interrupted sweep keeps them)."""

    final = Path(user_path(str(folder)))
    parts = final / ("parts" if job is None else f"parts-{job[0]}-of-{job[1]}")
    written_directly(parts)  # the command's own entry of --out (its manifest)
    return parts


def _refuse_finished(folder: Path, parts: Path, resume: bool, force: bool) -> None:
    """An output folder holding a finished sweep is replaced only with `--force`; its
    parts are cleared with `--force` (a fresh start)."""
    import json

    final = Path(user_path(str(folder)))
    summary = final / "summary.json"
    if force:
        clear_parts(parts)  # only what a sweep wrote there; a link is never followed
        return
    if resume or not summary.exists():
        return
    try:
        kind = json.loads(summary.read_text()).get("kind")
    except (ValueError, OSError):
        kind = None
    if kind == "sweep":
        raise ValueError(
            f"{final} holds a finished sweep: --force to replace it, or --resume to rebuild "
            "its table from its parts"
        )


def _print_result(tag, problem, held, extra=""):
    head = f"[{tag}] " if tag else ""
    for name, r in held.items():
        values = ", ".join(f"{k} = {np.round(v, 4).tolist()}" for k, v in r["params"].items())
        failed = f" ({r['failed']} held-out run(s) failed)" if r["failed"] else ""
        name = problem.defaults_label if name == "paper" else name  # the JSON key stays
        print(
            f"{head}{name:<11} {values:<40} held-out {problem.metric} = {r['metric']:.4g}{failed}"
        )
    if extra:
        print(f"{head}{extra}")


def _point(held, name) -> dict:
    return {"params": held[name]["params"], "metric": held[name]["metric"]}


def _common_result(p, found, spec, noise, seeds, seed, chosen) -> dict:
    """The keys of a sweep's and a tuning's summary they share (`chosen`: the held-out
    point reported as `best`)."""
    return {
        "metric": p.metric, "best": _point(found.held, chosen),
        "paper": _point(found.held, "paper"), "problem": p.title, "grid": spec,
        "noise_px": noise, "seeds": seeds, "held_out_seeds": [seed + seeds, seed + 2 * seeds - 1],
    }  # fmt: skip


def _write_sweep(folder, p, found, chosen, formats) -> None:
    """A sweep's table (`runs.parquet`, `runs.csv`) and its figure (`sweep.<format>`: the
    metric against each parameter, `chosen` and the defaults marked, held-out)."""
    studies.save_table(found.sweep, folder)
    plot_sweep(
        found.summary, p.metric, list(found.best["params"]), best=found.held[chosen],
        paper=found.held["paper"], paper_label=p.defaults_label, label=p.label, title=p.title,
        path=folder / "sweep.png", units={k: v.units for k, v in p.parameters().items()},
        formats=formats,
    )  # fmt: skip


def sweep_command(
    problem: str,
    grid: str | None = None,
    noise: float = 0.1,
    seeds: int = 8,
    data=None,
    duration: float | None = None,
    rate: float | None = None,
    variants=None,
    robust: bool = False,
    chunk: int = 64,
    shard=False,
    out=None,
    quiet: bool = False,
    seed: int = 0,
    formats=("png",),
    resume: bool = False,
    force: bool = False,
    ray=None,
    built=None,
) -> dict:
    """`visjax sweep PROBLEM`: a grid of the problem's parameters (`--grid`, default the
    problem's) over `seeds` noise seeds from `seed` (`studies.sweep`), the best point by
    the mean metric, and the best point and the defaults (the paper's values) re-measured
    on `seeds` held-out seeds. Writes `runs.parquet`, `runs.csv`, `sweep.<format>` and
    `summary.json` (kind `sweep`: `{"metric", "best": {"params", "metric"}, "paper":
    {"params", "metric"}, ...}`, the metrics held-out).

    With `--out`, each chunk's rows are also written as it finishes (`parts/`, one Parquet
    part per chunk and a manifest): an interrupted sweep (SIGINT, SIGTERM, a lost node)
    keeps them and `--resume` continues it; `--force` replaces a finished one. `--shard
    i/N` runs the i-th of N disjoint slices (`parts-i-of-N/`; `visjax merge` assembles
    them); `--shard` alone shards each chunk over the JAX devices; `--ray [ADDRESS]` runs
    the chunks as tasks on a Ray cluster (a local one without an address)."""
    started = time.perf_counter()
    settings = _settings(locals())

    devices, job = _job_slice(shard)
    if (resume or force or job is not None) and out is None:
        raise ValueError("--resume, --force and --shard i/N need --out (where the parts are)")
    if resume and force:
        raise ValueError("--resume and --force exclude each other")
    executor = None
    if ray is not None and ray is not False:
        try:
            executor = studies.RayExecutor(address=None if ray in (True, "local") else ray)
        except (ImportError, ConnectionError) as e:
            raise ValueError(str(e)) from None
    try:
        return _sweeps(
            problem, grid, noise, seeds, data, duration, rate, variants, chunk, out, quiet,
            seed, formats, resume, force, devices, job, executor, settings, started, robust,
            built,
        )  # fmt: skip
    finally:
        if executor is not None:
            executor.shutdown()


def _sweeps(
    problem, grid, noise, seeds, data, duration, rate, variants, chunk, out, quiet, seed,
    formats, resume, force, devices, job, executor, settings, started, robust=False,
    built=None,
):  # fmt: skip

    say = None if quiet else print
    results, mesh = {}, _mesh(devices)
    dropped = _dropped(problem, data)
    for tag, p in built or problems(problem, data, noise, duration, rate, variants, robust=robust):
        if not p.scored:
            raise ValueError(f"{p.title}: a sweep needs the truth (the data file has none)")
        folder = _folder(out, tag)
        parts = None
        if folder is not None:
            parts = _parts_folder(folder, job)
            _refuse_finished(folder, parts, resume, force)
        try:
            with studies.interruptible() as stop:
                study = studies.Study(
                    chunk=chunk, mesh=mesh, shard=job, executor=executor, parts=parts,
                    resume=resume and parts is not None, max_memory="available",
                    progress=not quiet, log=say, stop=stop,
                )  # fmt: skip
                spec, found = _selected(p, grid, seeds, seed, study)
        except KeyboardInterrupt:
            if folder is None:
                raise
            done, n = saved_runs(parts)
            sys.stderr.write(
                f"visjax: interrupted: {done} of {n} runs are saved in {parts}; "
                "run the same command with --resume to continue\n"
            )
            raise SystemExit(130) from None
        head = f"[{tag}] " if tag else ""
        if job is not None:
            print(
                f"{head}shard {job[0]}/{job[1]}: {len(found)} runs written to "
                f"{parts}; when every shard is done: visjax merge DIR... --out OUT"
            )
            body = {"runs": len(found), "shard": list(job), "parts": str(parts)}
            # not written into the variant's folder: that would replace the folder, and the
            # other slices' parts in it, when the outputs move into place
            results[tag] = command_summary(
                "sweep_shard", body, settings=settings, seed=seed, started=started, out=None
            )
            continue
        table, best = found.sweep, found.best
        result = {
            **_common_result(p, found, spec, noise, seeds, seed, "best"),
            "best_training_metric": best["metric"],
            "best_gains": p.gains(best["params"]),
            "paper_gains": p.gains({}),
            "failed_runs": int((table["result"] != "successful").sum()),
            "runs": len(table),
            "problem_settings": p.settings(),
            **p.checks(best["params"]),
        }
        failed = f"{result['failed_runs']} of {len(table)} sweep runs failed"
        _print_result(tag, p, found.held, failed)
        _say_dropped(result, dropped, f"[{tag}] " if tag else "")
        if folder is not None:
            _write_sweep(folder, p, found, "best", formats)
            # the parts come along with the other outputs (a copy: until the outputs are
            # in place, the parts where they were written stay whole)
            shutil.copytree(parts, folder / "parts", dirs_exist_ok=True)
        results[tag] = command_summary(
            "sweep", result, settings=settings, seed=seed, started=started, out=folder
        )
    if job is not None and list(results) == [None]:
        return results[None]
    return _result(results, settings, seed, started, out)


def merge_command(paths, out=None, quiet: bool = False) -> dict:
    """`visjax merge DIR...`: the parts of one sweep's shards (or of an interrupted run and
    its resumption), found in or under each DIR, as one table: `runs.parquet`, `runs.csv`
    and `summary.json` (kind `merge`: the runs, the sources, the best point by the mean
    metric over the seeds when the table names its metric). Parts of different sweeps,
    a run found twice or runs missing are refused, naming the chunks. Sweeps over several
    variants: one table per sweep, in a folder per variant."""
    started = time.perf_counter()
    settings = _settings(locals())

    results = {}
    for tag, (table, manifest, members) in studies.merge_sweeps(paths).items():
        metric = manifest.get("info", {}).get("metric")
        body = {
            "runs": len(table),
            "chunks": manifest["n_chunks"],
            "sources": [str(m) for m in members],
            "failed_runs": int((table["result"] != "successful").sum()),
            "metric": metric,
        }
        if metric in table.columns and (table["result"] == "successful").any():
            try:
                body["best"] = studies.best(table, metric)
            except ValueError:
                body["best"] = None
        head = f"[{tag}] " if tag else ""
        print(f"{head}merged {len(table)} runs from {len(members)} parts folder(s)")
        folder = _folder(out, tag)
        if folder is not None:
            studies.save_table(table, folder)
        results[tag] = command_summary(
            "merge", body, settings=settings, seed=0, started=started, out=folder
        )
    if list(results) == [None]:
        return results[None]
    return _result(results, settings, 0, started, out)


def tune_command(
    problem: str,
    grid: str | None = None,
    noise: float = 0.1,
    seeds: int = 4,
    steps: int = 30,
    learning_rate: float = 0.1,
    data=None,
    duration: float | None = None,
    rate: float | None = None,
    variants=None,
    robust: bool = False,
    chunk: int = 64,
    shard=False,
    out=None,
    quiet: bool = False,
    seed: int = 0,
    formats=("png",),
    built=None,
) -> dict:
    """`visjax tune PROBLEM`: a sweep of the grid (`--grid`, default the problem's) on
    `seeds` training seeds, then `studies.tune` (Adam on the log parameters, forward-mode
    gradients through the runner, `steps` steps) from the sweep's best point on the same
    seeds; the tuned point, the sweep's best and the defaults (the paper's values)
    re-measured on `seeds` held-out seeds. Writes `runs.parquet`, `runs.csv` (the sweep),
    `history.csv`, `sweep.png`, `tune.png` and `summary.json` (kind `tune`)."""
    started = time.perf_counter()
    settings = _settings(locals())
    import optax

    devices, job = _job_slice(shard)
    if job is not None:
        raise ValueError("--shard i/N is for sweep (tune follows one path: it needs every run)")
    results, mesh = {}, _mesh(devices)
    dropped = _dropped(problem, data)
    for tag, p in built or problems(problem, data, noise, duration, rate, variants, robust=robust):
        if not p.scored:
            raise ValueError(f"{p.title}: tuning needs the truth (the data file has none)")
        study = studies.Study(
            chunk=chunk, mesh=mesh, max_memory="available", progress=not quiet,
            log=None if quiet else print,
        )  # fmt: skip
        optimiser = (optax.adam(learning_rate), steps)
        spec, found = _selected(p, grid, seeds, seed, study, tune=optimiser)
        held, tuned = found.held, found.tuned
        result = {
            **_common_result(p, found, spec, noise, seeds, seed, "tuned"),
            "sweep_best": _point(held, "sweep best"),
            "improvement_over_paper": held["paper"]["metric"] / held["tuned"]["metric"],
            "steps": steps,
            "optimiser": f"optax.adam({learning_rate}) on the log parameters, forward mode",
            "training_loss": {"sweep_best": tuned.loss0, "tuned": tuned.loss},
            "tuned_gains": p.gains(tuned.params),
            "paper_gains": p.gains({}),
            "held_out_failed_runs": {k: v["failed"] for k, v in held.items()},
            "problem_settings": p.settings(),
            **p.checks(tuned.params),
        }
        extra = f"held-out improvement over the defaults: x {result['improvement_over_paper']:.3g}"
        for line in p.check_lines(result):
            extra += f"; {line}"
        _print_result(tag, p, held, extra)
        _say_dropped(result, dropped, f"[{tag}] " if tag else "")
        folder = _folder(out, tag)
        if folder is not None:
            _write_sweep(folder, p, found, "tuned", formats)
            tuned.to_pandas().to_csv(folder / "history.csv", index=False)
            plot_tune_history(
                tuned.history,
                label=f"training {p.label}",
                title=p.title,
                path=folder / "tune.png",
                formats=formats,
            )
        results[tag] = command_summary(
            "tune", result, settings=settings, seed=seed, started=started, out=folder
        )
    return _result(results, settings, seed, started, out)
