"""The `visjax` command line: argument parsing only, one library call per command
(`visjax.report`)."""

import argparse
import math
import os
import sys
from pathlib import Path

from . import report
from .papers.chitrakaran import K_EQ63, RHO_EQ63  # the paper's gains live in its module

K_DEFAULT = " ".join(f"{k:g}" for k in K_EQ63)
RHO_DEFAULT = " ".join(f"{r:g}" for r in RHO_EQ63)


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
_seed = _number(int, lambda v: v >= 0, "a non-negative integer")


def _formats(text: str) -> list[str]:
    """`--format png,pdf,svg`: figure formats, comma-separated."""
    from .report import FORMATS

    chosen = [f.strip().lower() for f in text.split(",") if f.strip()]
    bad = [f for f in chosen if f not in FORMATS]
    if not chosen or bad:
        raise argparse.ArgumentTypeError(
            f"expected figure formats among {', '.join(FORMATS)} (comma-separated), got {text!r}"
        )
    return list(dict.fromkeys(chosen))


class _Parser(argparse.ArgumentParser):
    """Errors as one line, `visjax: error: ...`, exit status 2, no usage block."""

    def error(self, message):
        self.exit(2, f"visjax: error: {message}\n")


def _check_out(out) -> None:
    """`--out` must be a folder that can be created or written, checked before any work."""
    if out is None:
        return
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"--out {out!r} exists and is not a folder")
    parent = path if path.exists() else path.parent
    while not parent.exists():
        parent = parent.parent
    if not os.access(parent, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"--out {out!r}: {str(parent)!r} is not writable")


def _check_out_file(out) -> None:
    """`--out` of `track` must be a `.npz` or `.csv` file that can be written (not a folder),
    checked before any work."""
    path = Path(out)
    if path.suffix.lower() not in (".npz", ".csv"):
        raise argparse.ArgumentTypeError(f"--out {out!r} must end in .npz or .csv")
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"--out {out!r} is a folder, not a file")
    parent = path.parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"--out {out!r}: {str(parent)!r} is not writable")


def _run_geometry(a):
    return report.geometry_report(
        a.scenes, a.points, a.noise, a.seed, a.out, formats=a.format, quiet=a.quiet
    )


def _run_velocity(a):
    if a.data is not None:
        return report.velocity_data_report(
            a.data, out=a.out, quiet=a.quiet, filter_hz=a.filter_hz, formats=a.format
        )
    return report.velocity_report(
        a.duration, a.rate, a.noise, a.seed, a.K, a.rho, out=a.out, quiet=a.quiet,
        formats=a.format, seeds=a.seeds,
    )  # fmt: skip


def _run_structure(a):
    if a.data is not None:
        return report.structure_data_report(a.data, out=a.out, quiet=a.quiet, formats=a.format)
    return report.structure_report(
        a.set, a.duration, a.noise, a.seed, out=a.out, quiet=a.quiet, formats=a.format,
        seeds=a.seeds,
    )  # fmt: skip


def _run_euclidean(a):
    if a.data is not None:
        return report.euclidean_data_report(a.data, out=a.out, quiet=a.quiet, formats=a.format)
    return report.euclidean_report(
        a.duration, a.noise, a.seed, out=a.out, quiet=a.quiet, formats=a.format, seeds=a.seeds
    )


def _run_compare(a):
    return report.compare_report(
        a.problem, a.data, a.noise, a.seeds, a.duration, out=a.out, quiet=a.quiet, seed=a.seed,
        formats=a.format,
    )  # fmt: skip


def _study_kwargs(a):
    return dict(
        grid=a.grid,
        noise=a.noise,
        seeds=a.seeds,
        data=a.data,
        duration=a.duration,
        rate=a.rate,
        sets=a.set,
        chunk=a.chunk,
        shard=a.shard,
        out=a.out,
        quiet=a.quiet,
        seed=a.seed,
        formats=a.format,
    )


def _run_sweep(a):
    return report.sweep_report(a.problem, **_study_kwargs(a))


def _run_tune(a):
    return report.tune_report(
        a.problem, steps=a.steps, learning_rate=a.learning_rate, **_study_kwargs(a)
    )


def _grid_spec(text: str) -> str:
    from .studies import parse_grid

    try:
        parse_grid(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None
    return text


def _add_out(parser, what: str = "summary.json, the estimates and the figures") -> None:
    parser.add_argument("--out", type=str, default=None, help=f"folder for {what}")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")


def _add_format(parser) -> None:
    parser.add_argument(
        "--format",
        type=_formats,
        default=["png"],
        help="figure formats, comma-separated: png, pdf, svg (default png)",
    )


def _add_noise(parser, default: float) -> None:
    parser.add_argument(
        "--noise",
        type=_nonnegative,
        default=default,
        help=f"pixel noise sigma in px (default {default:g})",
    )


def _add_seed(parser, help: str = "the first noise seed (default 0)") -> None:
    parser.add_argument("--seed", type=_seed, default=0, help=help)


def _add_seeds(parser) -> None:
    parser.add_argument(
        "--seeds",
        type=_count,
        default=1,
        help="noise seeds, from --seed (default 1); with more, the errors are medians over "
        "them and the figures show their 10-90%% band (needs --noise > 0)",
    )


def _add_study_options(parser, seeds: int) -> None:
    parser.add_argument("problem", choices=("velocity", "structure", "euclidean"))
    parser.add_argument(
        "--grid",
        type=_grid_spec,
        default=None,
        help='gain multipliers of the reference (published) gains: "K=1e-2:1e1:8,rho=0.1/1" '
        "(low:high:count log-spaced, or values separated by /); default: the problem's "
        "(velocity: K, rho; structure: K, Y; euclidean: alpha, gamma)",
    )
    _add_noise(parser, 0.1)
    parser.add_argument(
        "--seeds",
        type=_count,
        default=seeds,
        help=f"training noise seeds (default {seeds}); as many held-out seeds after them "
        "measure the reported metrics",
    )
    _add_seed(parser, "the first training seed (default 0)")
    _add_data(parser, "your own data file (.npz, velocity or euclidean; needs the truth)")
    parser.add_argument(
        "--duration", type=_positive, default=None, help="seconds (default: the problem's)"
    )
    parser.add_argument(
        "--rate", type=_positive, default=None, help="sample rate in Hz (velocity, euclidean)"
    )
    parser.add_argument(
        "--set", action="append", help="structure: I.1 ... II.3 (repeatable; default: all)"
    )
    parser.add_argument("--chunk", type=_count, default=64, help="runs per vmap call (64)")
    parser.add_argument(
        "--shard",
        action="store_true",
        help="shard each chunk over every JAX device (GPUs; on CPUs one process per device "
        "with jax.distributed, see docs/sweeps-and-tuning.md)",
    )
    _add_out(parser, "runs.parquet, runs.csv, summary.json and the figures")
    _add_format(parser)


def _run_track(a):
    return report.track_report(
        a.video,
        a.out,
        detector=a.detector,
        max_features=a.max_features,
        fb_threshold=a.fb_threshold,
        fps=a.fps,
        quiet=a.quiet,
    )


def _set_name(text: str) -> str:
    from .papers.jang import SETS

    if text not in SETS:
        raise argparse.ArgumentTypeError(f"unknown set {text!r}; choose from {', '.join(SETS)}")
    return text


def _run_testbed(a):
    return report.testbed_report(
        a.set,
        a.units,
        a.duration,
        seed=a.seed,
        video=not a.no_video,
        studies=not a.no_studies,
        out=a.out,
        quiet=a.quiet,
        formats=a.format,
    )


def _run_reproduce(a):
    return report.reproduce(a.out, quick=a.quick, quiet=a.quiet, formats=a.format)


_OWN_DATA = (
    "run on your own data file (.npz, see docs/your-own-data.md) instead of the paper's simulation"
)


def _add_data(parser, help: str) -> None:
    parser.add_argument("--data", type=str, default=None, help=help)


def _quick_help() -> str:
    from .report import QUICK

    def show(v):
        return "all" if v is None else ("/".join(v) if isinstance(v, list) else f"{v:g}")

    changes = ", ".join(
        f"{k.replace('_', ' ')} {show(full)} -> {show(quick)}"
        for k, (full, quick) in QUICK.items()
        if not isinstance(full, bool)
    )
    return (
        f"shorter runs: {changes}, and the testbed without its studies (the camera matrix "
        "of section 2.3, the v_py sensitivity); the velocity simulation runs in full. "
        "results/ then differs from the documentation's tables, which are full runs"
    )


def build_parser() -> argparse.ArgumentParser:
    from . import __version__

    parser = _Parser(
        prog="visjax",
        description="Vision-based nonlinear estimators in JAX: the velocity estimator of "
        "Chitrakaran et al., the unknown input observer of Jang's thesis, and the adaptive "
        "least-squares structure estimator of Nath et al.",
    )
    parser.add_argument("--version", action="version", version=f"visjax {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    g = sub.add_parser(
        "geometry",
        help="homography estimation and Euclidean decomposition (Chitrakaran et al., section "
        "3): visjax vs OpenCV vs ground truth",
    )
    g.add_argument("--scenes", type=_count, default=100, help="random planar scenes (default 100)")
    g.add_argument("--points", type=_points, default=4, help="points per scene, >= 4 (default 4)")
    _add_noise(g, 0.0)
    _add_seed(g, "the scenes' and the noise's seed (default 0)")
    _add_out(g, "summary.json, scenes.parquet and the figure")
    _add_format(g)
    g.set_defaults(func=_run_geometry)

    v = sub.add_parser(
        "velocity",
        help="the fixed-camera velocity estimator of Chitrakaran et al. on the paper's "
        "section-6 simulation, or on your data",
    )
    v.add_argument("--duration", type=_positive, default=10.0, help="seconds (default 10)")
    v.add_argument(
        "--rate", type=_positive, default=1000.0, help="sample rate in Hz (default 1000)"
    )
    _add_noise(v, 0.0)
    _add_seed(v)
    _add_seeds(v)
    v.add_argument(
        "--K", type=_six, default=_six(K_DEFAULT), help=f'diagonal of K (default "{K_DEFAULT}")'
    )
    v.add_argument(
        "--rho",
        type=_six,
        default=_six(RHO_DEFAULT),
        help=f'diagonal of rho (default "{RHO_DEFAULT}")',
    )
    v.add_argument(
        "--filter-hz",
        type=_positive,
        default=None,
        help="with --data: a causal 2nd-order low-pass of the estimate at this bandwidth",
    )
    _add_out(v)
    _add_format(v)
    _add_data(v, _OWN_DATA)
    v.set_defaults(func=_run_velocity)

    st = sub.add_parser(
        "structure",
        help="the unknown input observer of Jang's thesis on simulated analogues of its "
        "seven experiment sets, or on your data",
    )
    st.add_argument("--set", action="append", help="I.1 ... II.3 (repeatable; default: all)")
    st.add_argument("--duration", type=_positive, default=30.0, help="seconds per set (default 30)")
    _add_noise(st, 0.1)
    _add_seed(st)
    _add_seeds(st)
    _add_out(st)
    _add_format(st)
    _add_data(st, _OWN_DATA)
    st.set_defaults(func=_run_structure)

    eu = sub.add_parser(
        "euclidean",
        help="Euclidean positions of static features from an uncalibrated moving camera "
        "(Nath et al.'s adaptive least squares), on its simulation or on your data",
    )
    _add_noise(eu, 0.0)
    # the option's name before version 0.3, kept so that old scripts run
    eu.add_argument("--noise-px", dest="noise", type=_nonnegative, help=argparse.SUPPRESS)
    eu.add_argument("--duration", type=_positive, default=30.0, help="seconds (default 30)")
    _add_seed(eu)
    _add_seeds(eu)
    _add_out(eu)
    _add_format(eu)
    _add_data(eu, _OWN_DATA)
    eu.set_defaults(func=_run_euclidean)

    c = sub.add_parser(
        "compare",
        help="an estimator against its batch least-squares baselines and its EKF, on "
        "identical noisy inputs over noise seeds",
    )
    c.add_argument("problem", choices=("velocity", "structure", "euclidean"))
    _add_data(c, "your own data file (.npz, see docs/your-own-data.md); noise is added on top")
    _add_noise(c, 0.1)
    c.add_argument("--seeds", type=_count, default=4, help="noise seeds (default 4)")
    _add_seed(c)
    c.add_argument(
        "--duration",
        type=_positive,
        default=None,
        help="seconds of the paper's scenario (default: the problem's; not with --data)",
    )
    _add_out(c, "summary.json, records.parquet, records.csv and the figure")
    _add_format(c)
    c.set_defaults(func=_run_compare)

    sw = sub.add_parser(
        "sweep",
        help="a grid of gains over noise seeds, batched: runs.parquet, runs.csv, the figure, "
        "summary.json (best and paper's gains on held-out seeds)",
    )
    _add_study_options(sw, seeds=8)
    sw.set_defaults(func=_run_sweep)

    tu = sub.add_parser(
        "tune",
        help="a sweep, then gradient-based tuning from its best point; tuned and paper's "
        "gains on held-out seeds",
    )
    _add_study_options(tu, seeds=4)
    tu.add_argument("--steps", type=_count, default=30, help="optimiser steps (default 30)")
    tu.add_argument(
        "--learning-rate",
        type=_positive,
        default=0.1,
        help="Adam's step on the log gains (default 0.1: about 10%%)",
    )
    tu.set_defaults(func=_run_tune)

    tr = sub.add_parser(
        "track",
        help="a video to pixel tracks: KLT with a forward-backward check (Jang's thesis, "
        "section 2.4)",
    )
    tr.add_argument("video", help="the video (MP4 or anything OpenCV reads, or .npz)")
    tr.add_argument(
        "--out",
        required=True,
        help="the tracks file: .npz (keys t and pixels, NaN where not seen) or .csv",
    )
    tr.add_argument("--detector", choices=("corners", "aruco"), default="corners")
    tr.add_argument(
        "--max-features", type=_count, default=200, help="features alive at once (default 200)"
    )
    tr.add_argument(
        "--fb-threshold",
        type=_positive,
        default=0.5,
        help="forward-backward round-trip error in px that drops a feature (default 0.5)",
    )
    tr.add_argument("--fps", type=_positive, default=None, help="frame rate (default: the video's)")
    tr.add_argument("--quiet", action="store_true", help="no progress bar and no summary")
    tr.set_defaults(func=_run_track, out_is_file=True)

    tb = sub.add_parser(
        "testbed",
        help="Jang's thesis end to end on a twin of its testbed: PUMA 560 and two-link "
        "kinematics, rendered 30 Hz video, KLT tracking, encoder velocities, the UIO",
    )
    tb.add_argument(
        "--set", action="append", type=_set_name, help="I.1 ... II.3 (repeatable; default: all)"
    )
    tb.add_argument(
        "--units",
        choices=("cm", "m"),
        default="cm",
        help="the unit of the velocities in the thesis' A matrices (the thesis does not say; "
        "default cm)",
    )
    tb.add_argument("--duration", type=_positive, default=30.0, help="seconds per set (default 30)")
    _add_seed(tb, "the table texture's seed (default 0)")
    tb.add_argument("--no-video", action="store_true", help="no MP4 of the rendered frames")
    tb.add_argument(
        "--no-studies",
        action="store_true",
        help="skip the least-squares camera matrix (Tables 5-1/5-2) and the v_py sensitivity",
    )
    _add_out(tb, "tables, estimates, figures and videos")
    _add_format(tb)
    tb.set_defaults(func=_run_testbed)

    r = sub.add_parser("reproduce", help="every paper's main experiment, figures and a summary")
    r.add_argument("--quick", action="store_true", help=_quick_help())
    r.add_argument("--out", type=str, default="results", help="output folder (default results)")
    r.add_argument("--quiet", action="store_true", help="no progress bars")
    _add_format(r)
    r.set_defaults(func=_run_reproduce)
    return parser


def main(argv=None) -> int:
    """Parse and validate every option before any work (one line and exit status 2 on a
    bad one), then run the command into a temporary folder beside `--out` and move its
    files into place only when it succeeded: a failure leaves nothing half-written."""
    from ._xla_workaround import apply_xla_cpu_workarounds

    apply_xla_cpu_workarounds()  # the command line's own choice; `import visjax` sets nothing
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command in ("structure", "sweep", "tune") and args.set:
        from .papers.jang import SETS

        for name in args.set or ():
            if name not in SETS:
                parser.error(f"unknown set {name!r}; choose from {list(SETS)}")
    if (
        args.command in ("velocity", "euclidean")
        and args.duration * getattr(args, "rate", 1000.0) < 2
    ):
        parser.error("--duration times the rate must give at least 2 samples")
    if args.command in ("sweep", "tune"):
        if args.set and args.problem != "structure":
            parser.error("--set applies to the structure problem only")
        if args.data is not None and args.problem == "structure":
            parser.error("--data applies to velocity and euclidean (structure: the thesis' sets)")
        if args.rate is not None and args.problem == "structure":
            parser.error("--rate applies to velocity and euclidean")
        if args.data is not None and (args.duration is not None or args.rate is not None):
            parser.error("--duration and --rate apply to the paper's scenario, not to --data")
    if args.command in ("velocity", "structure", "euclidean") and args.seeds > 1:
        if args.data is not None:
            parser.error("--seeds applies to the paper's simulation, not to --data")
        if not args.noise > 0:
            parser.error("--seeds above 1 needs --noise above 0: noise-free runs are all the same")
    if args.command == "compare" and args.data is not None and args.duration is not None:
        parser.error("--duration applies to the paper's scenario, not to --data")
    try:
        if getattr(args, "out_is_file", False):
            _check_out_file(args.out)
        else:
            _check_out(args.out)
    except argparse.ArgumentTypeError as e:
        parser.error(str(e))
    if args.command == "track" and not Path(args.video).is_file():
        parser.error(f"video {args.video!r}: no such file")
    data = getattr(args, "data", None)
    if data is not None and not Path(data).is_file():
        parser.error(f"--data {data!r}: no such file")
    try:
        return _execute(args)
    except (ValueError, RuntimeError) as e:
        # a bad data file or a run the estimator could not finish: one line, no traceback
        message = _one_line(e)
        sys.stderr.write(f"visjax: error: {message}\n")
        return 1


def _one_line(error: Exception) -> str:
    """The message of an error in one line: for a runtime error raised inside compiled
    code (`equinox.error_if`), its own message, not the traceback banner around it."""
    lines = [ln.strip() for ln in str(error).strip().splitlines() if ln.strip()]
    for line in lines:
        if line.startswith(("equinox.EquinoxRuntimeError:", "EquinoxRuntimeError:")):
            return line.split(":", 1)[1].strip()
    return lines[0] if lines else type(error).__name__


def _execute(args) -> int:
    if args.out is None:
        args.func(args)
        return 0
    from .io import staged_output

    file = getattr(args, "out_is_file", False)
    with staged_output(args.out, file=file) as staged:
        args.out = str(staged)
        args.func(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
