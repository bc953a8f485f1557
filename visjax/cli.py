"""The `visjax` command line: argument parsing only, one library call per command
(`visjax.report` for the papers' jobs, `visjax.verbs` for `run|compare|sweep|tune` over any
registered problem)."""

import argparse
import inspect
import math
import os
import sys
from pathlib import Path

from . import __version__, report, studies, verbs
from ._xla_workaround import apply_xla_cpu_workarounds
from .estimators import MAX_STEPS
from .io import DataFormatError, OutputConflictError, check_output_path, staged_output
from .report import RunFailed
from .studies import (
    MAX_RUNS,
    Interrupted,
    Refused,
    UserCodeError,
    grid_size,
    handling_signals,
    load_module,
    registered,
    registered_reproduction,
)
from .verbs import check_study

VERBS = ("run", "compare", "sweep", "tune")
PAPER_COMMANDS = ("velocity", "moving_point", "static_points")  # with --data: `run PROBLEM`
_OWN_DATA = "your own data file (.npz, see docs/your-own-data.md)"
_OUT = "summary.json, the estimates and the figures"


def _six(text: str) -> list[float]:
    try:
        values = [float(x) for x in text.replace(",", " ").split()]
    except ValueError:
        values = []
    if len(values) != 6 or not all(math.isfinite(v) and v > 0 for v in values):
        raise argparse.ArgumentTypeError(
            f"expected six positive numbers (the diagonal), got {text!r}"
        )
    return values


def _number(kind, test, what):
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not (math.isfinite(value) and test(value)):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        return value

    return parse


_positive = _number(float, lambda v: v > 0, "a positive number")
_nonnegative = _number(float, lambda v: v >= 0, "a non-negative number")
_count = _number(int, lambda v: v >= 1, "a positive integer")
_points = _number(int, lambda v: v >= 4, "an integer of at least 4")
MAX_SEED = 2**31 - 1  # the largest seed every JAX mode (int32 without x64) holds exactly
_seed = _number(int, lambda v: 0 <= v <= MAX_SEED, f"an integer from 0 to {MAX_SEED}")


def _shard(text: str):
    """`--shard i/N`: two integers, 0 <= i < N."""
    try:
        i, n = (int(x) for x in text.split("/"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected i/N (e.g. 0/8), got {text!r}") from None
    if not (n >= 1 and 0 <= i < n):
        raise argparse.ArgumentTypeError(f"expected i/N with 0 <= i < N, got {text!r}")
    return (i, n)


def _formats(text: str) -> list[str]:
    chosen = [f.strip().lower() for f in text.split(",") if f.strip()]
    if not chosen or any(f not in report.FORMATS for f in chosen):
        raise argparse.ArgumentTypeError(
            f"expected figure formats among {', '.join(report.FORMATS)} (comma-separated), "
            f"got {text!r}"
        )
    return list(dict.fromkeys(chosen))


def _grid_spec(text: str) -> str:
    """A `--grid` spec that parses (`studies.parse_grid`), of at most `studies.MAX_RUNS`
    points (counted from the text first: nothing that large is built), every value
    finite. Names and signs need the problem: `verbs.check_study`."""

    size = grid_size(text)
    if size is not None and size > MAX_RUNS:
        raise argparse.ArgumentTypeError(
            f"the grid {text!r} has {size:.3g} points, more than one command runs ({MAX_RUNS:.0e})"
        )
    try:
        points = studies.parse_grid(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None
    for name, values in points.items():
        if not all(math.isfinite(v) for v in values):
            raise argparse.ArgumentTypeError(
                f"grid axis {name!r} has a value that is not finite in {text!r}"
            )
    return text


def _set_name(text: str) -> str:
    """A set of Jang's thesis: a variant of the registered `moving_point` problem."""
    sets = registered("moving_point").variants
    if text not in sets:
        raise argparse.ArgumentTypeError(f"unknown set {text!r}; choose from {', '.join(sets)}")
    return text


class _Parser(argparse.ArgumentParser):
    """Errors as one line, `visjax: error: ...`, exit status 2, no usage block."""

    def error(self, message):
        self.exit(2, f"visjax: error: {message}\n")


def _arg(p, flag, kind=None, default=None, help=None, **kw):
    """One option, on one line: `_arg(parser, "--scenes", _count, 100, "help")`."""
    kw.update({"type": kind} if kind else {}, **({} if default is None else {"default": default}))
    p.add_argument(flag, help=help, **kw)


_FORCE = "replace another command's results in --out (a sweep: a finished one)"


def _common(p, out=_OUT, noise=None, seed=None, seeds=None, data=None, fmt=True):
    """The shared vocabulary: --noise, --seed, --seeds, --data, --out, --quiet, --format."""
    if noise is not None:
        _arg(p, "--noise", _nonnegative, noise, f"pixel noise sigma, px (default {noise:g})")
    if seed is not None:
        _arg(p, "--seed", _seed, 0, seed)
    if seeds is not None:
        _arg(p, "--seeds", _count, seeds[0], seeds[1])
    if data is not None:
        _arg(p, "--data", str, None, data)
    _arg(p, "--out", str, None, f"folder for {out}")
    _arg(p, "--force", help=_FORCE, action="store_true")
    _arg(p, "--quiet", help="no progress bars", action="store_true")
    if fmt:
        _arg(p, "--format", _formats, ["png"], "figure formats: png,pdf,svg (default png)")


_SEEDS = (1, "noise seeds from --seed (default 1): medians and 10-90%% bands over them")
_FIRST = "the first noise seed (default 0)"
_HOURS = "refuse, after the second seed, --seeds estimated to take longer (default 24)"


def _verb(sub, name, help, *, seeds, noise, grid):
    """A study verb over any registered problem: `visjax NAME PROBLEM [options]`."""
    p = sub.add_parser(name, help=help)
    names = studies.problem_names()
    p.add_argument("problem", help=f"{', '.join(names)}, their aliases, or yours (--import)")
    held = "; then as many held-out seeds" if grid else ""
    seeds = None if seeds is None else (seeds, f"noise seeds (default {seeds}){held}")
    _common(p, "summary.json, tables and figures", noise, _FIRST, seeds, _OWN_DATA)
    _arg(p, "--duration", _positive, None, "seconds of the problem's scene")
    _arg(p, "--rate", _positive, None, "sample rate of the scene, Hz (if it has one)")
    _arg(p, "--set", None, None, "a variant (moving_point: I.1 ... II.3)", action="append")
    robust = "the problem's robust settings (robust losses, outlier gates; not moving_point)"
    _arg(p, "--robust", help=robust, action="store_true")
    if grid:
        _arg(p, "--grid", _grid_spec, None, 'e.g. "K_scale=1e-2:1e1:8,rho_scale=0.1/1"')
        _arg(p, "--chunk", _count, 64, "runs per vmap call (default 64)")
        shard = "alone: each chunk over every JAX device; i/N: the i-th of N slices (sweep)"
        _arg(p, "--shard", _shard, False, shard, nargs="?", const=True, metavar="i/N")
    return p


def build_parser() -> argparse.ArgumentParser:

    parser = _Parser(prog="visjax", description="Vision-based estimators in JAX (docs/)")
    parser.add_argument("--version", action="version", version=f"visjax {__version__}")
    _arg(parser, "--import", None, None, "a module registering problems or reproductions of yours",
         dest="modules", action="append", metavar="MODULE")  # fmt: skip
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    g = sub.add_parser("geometry", help="homography and decomposition vs OpenCV vs the truth")
    _arg(g, "--scenes", _count, 100, "random planar scenes (default 100)")
    _arg(g, "--points", _points, 4, "points per scene, >= 4 (default 4)")
    _common(g, "summary.json, scenes.parquet and the figure", 0.0, "the seed (default 0)")

    v = sub.add_parser("velocity", help="Chitrakaran et al.'s section 6, or your data")
    _arg(v, "--duration", _positive, 10.0, "seconds (default 10)")
    _arg(v, "--rate", _positive, 1000.0, "sample rate, Hz (default 1000)")
    _arg(v, "--K", _six, None, "diagonal of K (default: the problem's, eq. (63))")
    _arg(v, "--rho", _six, None, "diagonal of rho (default: the problem's, eq. (63))")
    _arg(v, "--filter-hz", _positive, None, "with --data: a causal 2nd-order low-pass")
    _common(v, _OUT, 0.0, _FIRST, _SEEDS, _OWN_DATA)
    _arg(v, "--max-hours", _positive, 24.0, _HOURS)

    st = _problem_parser(sub, "moving_point", "structure", "Jang's unknown input observer")
    _arg(st, "--set", None, None, "I.1 ... II.3 (repeatable; default: all)", action="append")
    _arg(st, "--duration", _positive, 30.0, "seconds per set (default 30)")
    _common(st, _OUT, 0.1, _FIRST, _SEEDS, _OWN_DATA)
    _arg(st, "--max-hours", _positive, 24.0, _HOURS)

    eu = _problem_parser(sub, "static_points", "euclidean", "Nath et al.'s uncalibrated camera")
    _arg(eu, "--duration", _positive, 30.0, "seconds (default 30)")
    _common(eu, _OUT, 0.0, _FIRST, _SEEDS, _OWN_DATA)
    _arg(eu, "--max-hours", _positive, 24.0, _HOURS)
    _arg(eu, "--noise-px", _nonnegative, None, argparse.SUPPRESS, dest="noise")  # 0.2's name

    run = _verb(sub, "run", "one method of a problem once", seeds=None, noise=0.0, grid=False)
    _arg(run, "--method", None, None, "the method (default: the estimator)")
    help = "a problem's methods on identical noisy inputs"
    cmp = _verb(sub, "compare", help, seeds=4, noise=0.1, grid=False)
    hours = "refuse, after the first seed, a comparison estimated to take longer (default 24)"
    _arg(cmp, "--max-hours", _positive, 24.0, hours)
    help = "a grid of a problem's parameters over noise seeds"
    sw = _verb(sub, "sweep", help, seeds=8, noise=0.1, grid=True)
    _arg(sw, "--resume", help="continue an interrupted sweep from its parts", action="store_true")
    ray = "run the chunks on a Ray cluster (no address: a local one; pip install visjax[ray])"
    _arg(sw, "--ray", None, None, ray, nargs="?", const="local", metavar="ADDRESS")
    me = sub.add_parser("merge", help="the parts of a sweep's shards as one table")
    me.add_argument("paths", nargs="+", metavar="DIR", help="folders holding the parts")
    _arg(me, "--out", None, None, "runs.parquet, runs.csv and summary.json", required=True)
    _arg(me, "--force", help=_FORCE, action="store_true")
    _arg(me, "--quiet", help="less printing", action="store_true")
    help = "a sweep, then gradient-based tuning from its best point"
    tu = _verb(sub, "tune", help, seeds=4, noise=0.1, grid=True)
    _arg(tu, "--steps", _count, 30, "optimiser steps (default 30)")
    _arg(tu, "--learning-rate", _positive, 0.1, "Adam's step on the log parameters (0.1)")

    tr = sub.add_parser("track", help="a video to pixel tracks (KLT, forward-backward check)")
    tr.add_argument("video", help="the video (MP4 or anything OpenCV reads, or .npz)")
    _arg(tr, "--out", None, None, "the tracks file: .npz or .csv", required=True)
    _arg(tr, "--force", help="replace the tracks file if it exists", action="store_true")
    _arg(tr, "--detector", None, "corners", "features to track", choices=("corners", "aruco"))
    _arg(tr, "--max-features", _count, 200, "features alive at once (default 200)")
    _arg(tr, "--fb-threshold", _positive, 0.5, "forward-backward error that drops one, px")
    _arg(tr, "--fps", _positive, None, "frame rate (default: the video's)")
    planar = "a planar scene: cut the tracks that do not follow the frames' homography"
    _arg(tr, "--planar", help=planar, action="store_true")
    _arg(tr, "--homography-threshold", _positive, 3.0, "px, the --planar test (default 3)")
    damaged = "track a video whose decoder reports damaged frames (they are concealed)"
    _arg(tr, "--allow-damaged", help=damaged, action="store_true")
    _arg(tr, "--quiet", help="no progress bar and no summary", action="store_true")
    tr.set_defaults(out_is_file=True)

    tb = sub.add_parser("testbed", help="Jang's thesis end to end on a twin of its testbed")
    _arg(tb, "--set", _set_name, None, "I.1 ... II.3 (repeatable; default all)", action="append")
    units = "the unit of the velocities in the thesis' A matrices (default cm)"
    _arg(tb, "--units", None, "cm", units, choices=("cm", "m"))
    _arg(tb, "--duration", _positive, 30.0, "seconds per set (default 30)")
    _arg(tb, "--no-video", help="no MP4 of the rendered frames", action="store_false", dest="video")
    no_studies = "skip the camera matrix (Tables 5-1/5-2) and the v_py sensitivity"
    _arg(tb, "--no-studies", help=no_studies, action="store_false", dest="studies")
    _common(tb, "tables, estimates, figures and videos", None, "the texture's seed (0)")

    r = sub.add_parser("reproduce", help="every paper's main experiment and a summary")
    _arg(r, "--quick", help=report.quick_help(), action="store_true")
    _common(r, "everything (default results)")
    r.set_defaults(out="results")
    return parser


def _problem_parser(sub, name, old, who):
    """A paper's command named for its problem, its name before version 0.3 an alias."""
    p = sub.add_parser(name, aliases=[old], help=f"{who}, or your data")
    p.set_defaults(command=name)
    return p


def _call(a):
    """The one library call of the command, its parameters taken from the options of the
    same name (`--format` is `formats`; `--set` is `sets` or `variants`): a verb's, or a
    paper's registered reproduction (`visjax velocity` is the reproduction `velocity`)."""

    if a.command in (*VERBS, "merge"):
        fn = getattr(verbs, f"{a.command}_command")
        accepted = inspect.signature(fn).parameters
    elif getattr(a, "data", None) is not None:  # a paper's command on a file: `run PROBLEM`
        options = {"filter_hz": getattr(a, "filter_hz", None)}
        return verbs.run_command(
            a.command, data=a.data, noise=0.0, seed=a.seed, out=a.out, quiet=a.quiet,
            formats=a.format, options=options,
        )  # fmt: skip
    elif a.command in ("reproduce", "track"):
        fn = getattr(report, "reproduce" if a.command == "reproduce" else "track_report")
        accepted = inspect.signature(fn).parameters
    else:
        entry = registered_reproduction(a.command)
        fn, accepted = entry.rows, inspect.signature(entry.run).parameters
    chosen, formats = getattr(a, "set", None), getattr(a, "format", None)
    values = {**vars(a), "formats": formats, "sets": chosen, "variants": chosen}
    return fn(**{k: v for k, v in values.items() if k in accepted})


def _check(a) -> None:
    """Combinations argparse cannot see, and a verb's problem, variants and options."""
    if a.command == "moving_point":
        for name in a.set or ():
            _set_name(name)
    if a.command in ("velocity", "static_points") and a.duration * getattr(a, "rate", 1e3) < 2:
        raise argparse.ArgumentTypeError("--duration times the rate must give at least 2 samples")
    if a.command in ("velocity", "moving_point", "static_points", "testbed"):
        samples = a.duration * getattr(a, "rate", 1e3)  # the papers' scenes run at 1 kHz
        if samples > MAX_STEPS:
            raise argparse.ArgumentTypeError(
                f"--duration {a.duration:g} s makes {samples:.3g} samples, more than a run "
                f"takes ({MAX_STEPS:.0e}, visjax.estimators.MAX_STEPS)"
            )
    seed = getattr(a, "seed", None)
    if seed is not None:  # the seeds a command draws: --seeds, then as many held out
        last = seed + getattr(a, "seeds", 1) * (2 if a.command in ("sweep", "tune") else 1) - 1
        if last > MAX_SEED:
            raise argparse.ArgumentTypeError(
                f"--seed {seed} draws seeds up to {last}, past {MAX_SEED} (2^31 - 1, the "
                "largest seed every JAX mode holds exactly): give a smaller --seed"
            )
    if a.command in ("velocity", "moving_point", "static_points") and a.seeds > 1:
        if a.data is not None:
            raise argparse.ArgumentTypeError(
                "--seeds applies to the paper's simulation, not to --data"
            )
        if not a.noise > 0:
            raise argparse.ArgumentTypeError(
                "--seeds above 1 needs --noise above 0: noise-free runs are all the same"
            )

    for module in a.modules or ():  # problems and reproductions of the user's
        try:  # a module that raises on import: `UserCodeError`, with its traceback
            load_module(module)
        except ValueError as e:  # not found, not a module's name: one line
            raise argparse.ArgumentTypeError(str(e)) from None
    if a.command in VERBS:
        try:  # the problem's name, options and variants, before any work
            registered(a.problem).check(
                a.data, a.duration, a.rate, a.set, a.robust, getattr(a, "method", None)
            )
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None

    try:
        check_output_path(a.out, file=getattr(a, "out_is_file", False))
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None
    if a.command == "track" and not Path(a.video).is_file():
        raise argparse.ArgumentTypeError(f"video {a.video!r}: no such file")
    if getattr(a, "data", None) is not None and not Path(a.data).is_file():
        raise argparse.ArgumentTypeError(f"--data {a.data!r}: no such file")
    if a.command in ("compare", "sweep", "tune"):
        _check_study(a)


def _check_study(a) -> None:
    """A study's size and grid, before any compile (`verbs.check_study`: the run count,
    the grid's parameter names and values on the built problem, a lower bound of the
    memory it needs); the problems it built go to the command (`built`: built once)."""

    shard = getattr(a, "shard", None)
    try:
        a.built = check_study(
            a.command, a.problem, grid=getattr(a, "grid", None), seeds=a.seeds,
            chunk=getattr(a, "chunk", 64), steps=getattr(a, "steps", 0), data=a.data,
            noise=a.noise, duration=a.duration, rate=a.rate, variants=a.set, robust=a.robust,
            shard=shard if isinstance(shard, tuple) else None,
        )  # fmt: skip
    except Refused as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def main(argv=None) -> int:
    """Parse and validate every option before any work (one line and exit status 2 on a
    bad one), then run the command into a temporary folder beside `--out` and move its
    files into place only when it succeeded: a failure leaves nothing half-written.

    A run that did not succeed (`visjax.report.RunFailed`: a failed run of a command that
    is one run, `velocity|moving_point|static_points --data` and `run`, or a data file
    with too many frames missing) exits with status 1 and one line naming its result code;
    its files, written before, are kept (its summary records the code). A failure that
    stops a command before its files (a paper's simulation that fails) leaves nothing.
    Commands over many runs (`compare`, `sweep`, `tune`) record each run's code and exit
    with 0."""

    apply_xla_cpu_workarounds()  # the command line's own choice; `import visjax` sets nothing
    import jax

    jax.config.update("jax_enable_x64", True)  # float64 on the command line, set here once
    parser = build_parser()
    args = parser.parse_args(argv)

    failed = None
    try:
        with handling_signals():
            try:
                _check(args)
            except argparse.ArgumentTypeError as e:
                parser.error(str(e))
            if args.out is None:
                failed = _run(args, RunFailed)
            else:
                file = getattr(args, "out_is_file", False)
                force = bool(getattr(args, "force", False))
                shard = getattr(args, "shard", None)
                slot = f"shard-{shard[0]}-of-{shard[1]}" if isinstance(shard, tuple) else None
                with staged_output(
                    args.out, file=file, command=args.command, force=force, slot=slot
                ) as st:
                    args.out = str(st)
                    failed = _run(args, RunFailed)
    except (DataFormatError, OutputConflictError) as e:  # a bad file, an --out in use: usage
        sys.stderr.write(f"visjax: error: {_one_line(e)}\n")
        return 2
    except UserCodeError as e:  # the user's own module or builder: their traceback helps
        sys.stderr.write(f"visjax: error: {_one_line(e)} (your code's traceback below)\n")
        sys.stderr.write(_user_traceback(e.__cause__))
        return 1
    except ValueError as e:
        sys.stderr.write(f"visjax: error: {_one_line(e)}\n")
        return 2 if isinstance(e, Refused) else 1
    except RuntimeError as e:  # a failed run: one line
        sys.stderr.write(f"visjax: error: {_one_line(e)}\n")
        return 1
    except Interrupted as e:
        where = "" if args.out is None else "; nothing was written to --out"
        sys.stderr.write(f"visjax: interrupted by {e.name}{where}\n")
        # the staging folder is gone (every `finally` ran); end at once, as a signal's
        # default would: the interpreter's shutdown with JAX's threads mid-computation
        # can crash (a segmentation fault after the line above)
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(128 + e.signum)
    if failed is not None:  # its files are in place: the run's result code, one line
        sys.stderr.write(f"visjax: error: {_one_line(failed)}\n")
        return 1
    return 0


def _run(args, run_failed):
    """The command; a run that did not succeed (`run_failed`) is returned, not raised, so
    that its files move into place."""
    try:
        _call(args)
    except run_failed as e:
        return e
    return None


def _user_traceback(error) -> str:
    """The traceback of an error raised in a user's code, from its first frame outside
    visjax and the import machinery (empty for none)."""
    import traceback

    if error is None:
        return ""
    package = str(Path(__file__).resolve().parent)
    frames = traceback.extract_tb(error.__traceback__)
    ours = ("<frozen importlib", "importlib/__init__.py", package)
    while frames and any(
        str(frames[0].filename).startswith(o) or o in frames[0].filename for o in ours
    ):
        frames = frames[1:]
    body = "".join(traceback.format_list(frames))
    last = "".join(traceback.format_exception_only(type(error), error))
    return "Traceback (most recent call last):\n" + body + last


def _one_line(error: Exception) -> str:
    """An error's message in one line (an `equinox.error_if`'s own, not JAX's banner)."""
    lines = [ln.strip() for ln in str(error).strip().splitlines() if ln.strip()]
    for line in lines:
        if line.startswith(("equinox.EquinoxRuntimeError:", "EquinoxRuntimeError:")):
            return line.split(":", 1)[1].strip()
    return lines[0] if lines else type(error).__name__


if __name__ == "__main__":
    sys.exit(main())
