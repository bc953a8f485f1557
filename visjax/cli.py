"""The `visjax` command line: options checked, then one library call per command
(`visjax.report` for the papers' jobs, `visjax.verbs` for `run|compare|sweep|tune` over any
registered problem); its grammar is `visjax._options.build_parser`."""

import argparse
import dataclasses
import importlib.util
import inspect
import os
import sys
import warnings
from pathlib import Path

from . import _options as o, io, report, studies, verbs
from ._options import build_parser
from ._xla_workaround import apply_xla_cpu_workarounds
from .estimators import MAX_STEPS
from .io import DataFormatError, OutputConflictError, check_output_path, staged_output
from .report import RunFailed
from .studies import Interrupted, Refused, UserCodeError, handling_signals, registered

PAPER_COMMANDS = ("velocity", "moving_point", "static_points")  # with --data: `run PROBLEM`


_STUDIES = ("run", "compare", "sweep", "tune")  # built, checked, sized: `verbs.check_study`
_VERBS = {"run": "run", "compare": "compare", "sweep": "sweep", "tune": "sweep", "merge": "merge"}


def _installed(module: str) -> bool:
    """Whether `module` can be found (importing its parent package, not `module` itself)."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a parent missing or broken, or without a spec
        return False


def _request(a) -> verbs.Request:
    """A verb's options as a `verbs.Request` (`--set` is `variants`, `--format` `formats`);
    a paper's command on a data file is `run PROBLEM`. **Raises:** `ValueError` for
    options that exclude each other."""
    if a.command not in _VERBS:  # `velocity|moving_point|static_points --data F`
        options = {"filter_hz": getattr(a, "filter_hz", None)}
        return verbs.Request(
            "run", a.command, data=a.data, noise=0.0, seed=a.seed, out=a.out, quiet=a.quiet,
            formats=a.format, options=options,
        )  # fmt: skip
    given = {**vars(a), "variants": getattr(a, "set", None), "formats": getattr(a, "format", None)}
    names = {f.name for f in dataclasses.fields(verbs.Request)}
    return verbs.Request(**{k: v for k, v in given.items() if k in names and v is not None})


def _call(a):
    """The one library call of the command, its parameters taken from the options of the
    same name: a verb's (`verbs`, with its `Request`), or a paper's registered
    reproduction (`visjax velocity` is the reproduction `velocity`)."""
    if a.request is not None:
        verb = getattr(verbs, f"{_VERBS[a.request.command]}_command")
        return verb(a.request) if a.command == "merge" else verb(a.request, built=a.built)
    if a.command in ("reproduce", "track", "data", "import-bag"):
        names = {"track": "track_report", "data": "data_report", "import-bag": "import_bag_report"}
        fn = getattr(report, names.get(a.command, "reproduce"))
        accepted = inspect.signature(fn).parameters
    else:
        entry = studies.registered_reproduction(a.command)
        fn, accepted = entry.rows, inspect.signature(entry.run).parameters
    chosen = getattr(a, "set", None)
    values = {**vars(a), "formats": getattr(a, "format", None), "sets": chosen, "variants": chosen}
    return fn(**{k: v for k, v in values.items() if k in accepted})


def _check(a) -> None:
    """Combinations argparse cannot see, and a verb's problem, variants and options (no
    data is read here). **Raises:** `ValueError`, a usage error, one line."""
    for module in a.modules or ():  # problems and reproductions of the user's (a module
        studies.load_module(module)  # that raises on import: `UserCodeError`, traceback)
    paper = a.command in PAPER_COMMANDS
    for name in (a.set or ()) if a.command == "moving_point" else ():
        o.set_name(name)
    if a.command in (*PAPER_COMMANDS, "testbed"):
        samples = a.duration * getattr(a, "rate", 1e3)  # the papers' scenes run at 1 kHz
        if samples < 2 or samples > MAX_STEPS:
            raise ValueError(
                f"--duration {a.duration:g} s makes {samples:.3g} samples: a run takes 2 to "
                f"{MAX_STEPS:.0e} (visjax.estimators.MAX_STEPS)"
            )
    seed = getattr(a, "seed", None)
    if seed is not None:  # the seeds a command draws: --seeds, then as many held out
        last = seed + getattr(a, "seeds", 1) * (2 if a.command in ("sweep", "tune") else 1) - 1
        if last > o.MAX_SEED:
            raise ValueError(
                f"--seed {seed} draws seeds up to {last}, past {o.MAX_SEED} (2^31 - 1, the "
                "largest seed every JAX mode holds exactly): give a smaller --seed"
            )
    if paper and a.seeds > 1 and (a.data is not None or not a.noise > 0):
        raise ValueError(
            "--seeds applies to the paper's simulation, not to --data"
            if a.data is not None
            else "--seeds above 1 needs --noise above 0: noise-free runs are all the same"
        )
    if a.command in ("run", "compare", "sweep", "tune"):  # the problem's name and options
        registered(a.problem).check(a.data, a.duration, a.rate, a.set, a.robust)
    check_output_path(a.out, file=getattr(a, "out_is_file", False))
    if a.command == "track" and not Path(a.video).is_file():
        raise ValueError(f"video {a.video!r}: no such file")
    if a.command == "track" and a.tags and (a.detector != "corners" or a.planar):
        raise ValueError("--tags finds the tags in every frame: no --detector or --planar")
    if a.command == "import-bag" and not Path(a.bag).exists():
        raise ValueError(f"bag {a.bag!r}: no such file or folder")
    if a.command == "import-bag" and not _installed("rosbags.highlevel"):
        raise ValueError("import-bag needs rosbags: pip install 'visjax[ros]'")
    if a.command == "import-bag" and (a.joint_states is None) != (a.robot is None):
        raise ValueError("--joint-states needs --robot, and --robot needs --joint-states")
    if getattr(a, "rerun", None) is not None:  # before any work: the file and the package
        if not a.rerun.endswith(".rrd"):
            raise ValueError(f"--rerun {a.rerun!r}: a Rerun recording's file ends in .rrd")
        if not _installed("rerun"):
            raise ValueError("--rerun needs rerun-sdk: pip install 'visjax[viz]'")
    if getattr(a, "camera_from_body", None) is not None:
        io.pose_from_text(a.camera_from_body)  # seven numbers, or one line saying so
    for flag in ("tracks", "camera") if a.command == "data" else ():
        if not Path(getattr(a, flag)).is_file():
            raise ValueError(f"--{flag} {getattr(a, flag)!r}: no such file")
    if getattr(a, "data", None) is not None and not Path(a.data).is_file():
        raise ValueError(f"--data {a.data!r}: no such file")
    a.request = _request(a) if a.command in _VERBS or (paper and a.data is not None) else None


def _warning_line(message, category, *_):
    """A Python warning as the command line prints it: one line, no source location."""
    sys.stderr.write(f"warning: {message}\n")


def main(argv=None) -> int:
    """Parse and validate every option before any work (one line and exit status 2 on a
    bad one), then run the command into a temporary folder beside `--out` and move its
    files into place only when it succeeded: a failure leaves nothing half-written. A run
    that did not succeed (`RunFailed`: `run`, a paper's command on a file) exits with 1
    and one line naming its result code, its files kept; `compare`, `sweep` and `tune`
    record each run's code and exit with 0."""
    apply_xla_cpu_workarounds()  # the command line's own choice; `import visjax` sets nothing
    import jax

    parser = build_parser()
    args = parser.parse_args(argv)
    # float64 on the command line unless a study asks for float32 (--dtype), set here once
    jax.config.update("jax_enable_x64", getattr(args, "dtype", "float64") == "float64")

    failed = None
    try:
        with handling_signals(), warnings.catch_warnings():
            warnings.showwarning = _warning_line  # restored on leaving
            try:
                _check(args)
            except (ValueError, argparse.ArgumentTypeError) as e:  # an option, a combination
                parser.error(_one_line(e))
            try:  # a study's size, before any compile; the problems built once, for it
                args.built = verbs.check_study(args.request) if args.command in _STUDIES else None
            except Refused as e:
                parser.error(_one_line(e))
            if args.out is None:
                failed = _run(args)
            else:
                shard = getattr(args, "shard", None)
                slot = f"shard-{shard[0]}-of-{shard[1]}" if isinstance(shard, tuple) else None
                with staged_output(
                    args.out, file=getattr(args, "out_is_file", False), command=args.command,
                    force=bool(getattr(args, "force", False)), slot=slot,
                ) as st:  # fmt: skip
                    args.out = str(st)
                    if args.request is not None:
                        args.request = dataclasses.replace(args.request, out=args.out)
                    failed = _run(args)
    except UserCodeError as e:  # the user's own module or builder: their traceback helps
        sys.stderr.write(f"visjax: error: {_one_line(e)} (your code's traceback below)\n")
        sys.stderr.write(e.user_traceback())
        return 1
    except (ValueError, RuntimeError) as e:  # one line; a bad file, an --out in use: usage
        sys.stderr.write(f"visjax: error: {_one_line(e)}\n")
        return 2 if isinstance(e, Refused | DataFormatError | OutputConflictError) else 1
    except Interrupted as e:
        where = "" if args.out is None else "; nothing was written to --out"
        sys.stderr.write(f"visjax: interrupted by {e.name}{where}\n")
        # every `finally` ran; end at once, as a signal's default would (the interpreter's
        sys.stdout.flush(), sys.stderr.flush()  # shutdown amid JAX's threads can crash)
        os._exit(128 + e.signum)
    if failed is not None:  # its files are in place: the run's result code, one line
        sys.stderr.write(f"visjax: error: {_one_line(failed)}\n")
        return 1
    return 0


def _run(args):
    """The command; a run that did not succeed (`RunFailed`) is returned, not raised, so
    that its files move into place."""
    try:
        _call(args)
    except RunFailed as e:
        return e
    return None


def _one_line(error: Exception) -> str:
    """An error's message in one line (an `equinox.error_if`'s own, not JAX's banner)."""
    lines = [ln.strip() for ln in str(error).strip().splitlines() if ln.strip()]
    for line in lines:
        if line.startswith(("equinox.EquinoxRuntimeError:", "EquinoxRuntimeError:")):
            return line.split(":", 1)[1].strip()
    return lines[0] if lines else type(error).__name__


if __name__ == "__main__":
    sys.exit(main())
