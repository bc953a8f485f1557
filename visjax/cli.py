"""The `visjax` command line: argument parsing only, one library call per command
(`visjax.report`)."""

import argparse
import sys

from . import report

K_DEFAULT = "300 300 200 15 15 15"  # Chitrakaran et al., eq. (63)
RHO_DEFAULT = "100 100 10 1 1 1"


def _six(text: str) -> list[float]:
    values = [float(x) for x in text.replace(",", " ").split()]
    if len(values) != 6 or not all(v > 0 for v in values):
        raise argparse.ArgumentTypeError(
            f"expected six positive numbers (the diagonal), got {text!r}"
        )
    return values


def _run_geometry(a):
    return report.geometry_report(a.scenes, a.points, a.noise, a.seed, a.out)


def _run_velocity(a):
    return report.velocity_report(
        a.duration, a.rate, a.noise, a.seed, a.K, a.rho, out=a.out, quiet=a.quiet
    )


def _run_structure(a):
    return report.structure_report(a.set, a.duration, a.noise, a.seed, out=a.out, quiet=a.quiet)


def _run_euclidean(a):
    return report.euclidean_report(a.duration, a.noise_px, a.seed, out=a.out, quiet=a.quiet)


def _run_reproduce(a):
    return report.reproduce(a.out, quick=a.quick, quiet=a.quiet)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="visjax", description="Vision-based nonlinear estimators in JAX."
    )
    sub = parser.add_subparsers(dest="command", required=True)
    g = sub.add_parser(
        "geometry",
        help="homography estimation and decomposition: visjax vs OpenCV vs ground truth",
    )
    g.add_argument("--scenes", type=int, default=100, help="random planar scenes (default 100)")
    g.add_argument("--points", type=int, default=4, help="points per scene, >= 4 (default 4)")
    g.add_argument("--noise", type=float, default=0.0, help="pixel noise sigma in px (default 0)")
    g.add_argument("--seed", type=int, default=0)
    g.add_argument("--out", type=str, default=None, help="directory for summary.json and figure")
    g.set_defaults(func=_run_geometry)

    v = sub.add_parser(
        "velocity",
        help="seed 000: the fixed-camera velocity estimator on the section-6 simulation",
    )
    v.add_argument("--duration", type=float, default=10.0, help="seconds (default 10)")
    v.add_argument("--rate", type=float, default=1000.0, help="sample rate in Hz (default 1000)")
    v.add_argument("--noise", type=float, default=0.0, help="pixel noise sigma in px (default 0)")
    v.add_argument("--seed", type=int, default=0, help="noise seed")
    v.add_argument(
        "--K", type=_six, default=_six(K_DEFAULT), help=f'diagonal of K (default "{K_DEFAULT}")'
    )
    v.add_argument(
        "--rho",
        type=_six,
        default=_six(RHO_DEFAULT),
        help=f'diagonal of rho (default "{RHO_DEFAULT}")',
    )
    v.add_argument("--out", type=str, default=None, help="directory for summary.json and figure")
    v.add_argument("--quiet", action="store_true", help="no progress bar")
    v.set_defaults(func=_run_velocity)

    st = sub.add_parser(
        "structure",
        help="seed 003: the unknown input observer on simulated analogues of the thesis' sets",
    )
    st.add_argument("--set", action="append", help="I.1 ... II.3 (repeatable; default: all)")
    st.add_argument("--duration", type=float, default=30.0, help="seconds per set (default 30)")
    st.add_argument(
        "--noise", type=float, default=0.1, help="pixel noise sigma in px (default 0.1)"
    )
    st.add_argument("--seed", type=int, default=0)
    st.add_argument("--out", type=str, default=None, help="directory for figures and summary")
    st.add_argument("--quiet", action="store_true", help="no progress bar")
    st.set_defaults(func=_run_structure)

    eu = sub.add_parser(
        "euclidean",
        help="seed 004: Euclidean positions from an uncalibrated moving camera (adaptive LS)",
    )
    eu.add_argument("--noise-px", type=float, default=0.0, help="pixel noise sigma (default 0)")
    eu.add_argument("--duration", type=float, default=30.0, help="seconds (default 30)")
    eu.add_argument("--seed", type=int, default=0)
    eu.add_argument("--out", type=str, default=None, help="directory for figure and summary")
    eu.add_argument("--quiet", action="store_true", help="no progress bar")
    eu.set_defaults(func=_run_euclidean)

    r = sub.add_parser("reproduce", help="every paper's main experiment, figures and a summary")
    r.add_argument("--quick", action="store_true", help="smaller geometry batch")
    r.add_argument("--out", type=str, default="results", help="output directory (default results)")
    r.add_argument("--quiet", action="store_true", help="no progress bars")
    r.set_defaults(func=_run_reproduce)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "points", 4) < 4:
        print("visjax: --points must be at least 4", file=sys.stderr)
        return 2
    if args.command == "structure":
        from .papers.jang import SETS

        for name in args.set or ():
            if name not in SETS:
                parser.error(f"unknown set {name!r}; choose from {list(SETS)}")
    args.func(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
