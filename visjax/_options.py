"""The command line's option vocabulary (`visjax.cli` declares its commands with it): the
option types, each parsing one option's text or raising `argparse.ArgumentTypeError` with
one line (`visjax: error: argument --X: ...`; the checks that are the library's, a shard, a
grid, figure formats, are called, not copied), and the options commands share."""

import argparse
import math

from . import io, report
from ._util import did_you_mean
from ._version import __version__
from .frontend import BAG_PROBLEMS, TAG_FAMILIES
from .plots import figure_formats
from .studies import BUDGET, check_grid_text, parse_shard, problem_names, registered

MAX_SEED = 2**31 - 1
"""The largest seed every JAX mode (int32 without x64) holds exactly."""


def number(kind, test, what):
    """A number of `kind` (`int`, `float`), finite and passing `test`, else `expected
    {what}`."""

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not (math.isfinite(value) and test(value)):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        return value

    parse.__name__ = kind.__name__
    return parse


positive = number(float, lambda v: v > 0, "a positive number")
nonnegative = number(float, lambda v: v >= 0, "a non-negative number")
count = number(int, lambda v: v >= 1, "a positive integer")
points = number(int, lambda v: v >= 4, "an integer of at least 4")
seed_number = number(int, lambda v: 0 <= v <= MAX_SEED, f"an integer from 0 to {MAX_SEED}")


def six(text: str) -> list[float]:
    """Six positive numbers, spaces or commas between (a gain matrix's diagonal)."""
    try:
        values = [float(x) for x in text.replace(",", " ").split()]
    except ValueError:
        values = []
    if len(values) != 6 or not all(math.isfinite(v) and v > 0 for v in values):
        raise argparse.ArgumentTypeError(
            f"expected six positive numbers (the diagonal), got {text!r}"
        )
    return values


def checked(check, name: str):
    """The option type of a library check (its `ValueError` becomes argparse's line)."""

    def parse(text: str):
        try:
            return check(text)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None

    parse.__name__ = name
    return parse


shard_spec = checked(parse_shard, "i/N")  # --shard i/N: 0 <= i < N
grid_spec = checked(check_grid_text, "grid")  # its names and signs need the problem
figure_list = checked(lambda text: list(figure_formats(text)), "formats")


def set_name(text: str) -> str:
    """A set of Jang's thesis: a variant of the registered `moving_point` problem."""
    sets = registered("moving_point").variants
    if text not in sets:
        hint = did_you_mean(text, sets)
        raise argparse.ArgumentTypeError(
            f"unknown set {text!r}{hint}; choose from {', '.join(sets)}"
        )
    return text


def method_names(text: str) -> tuple[str, ...]:
    """`--methods a,b,c`: names, each checked on the built problem (its own and added)."""
    names = tuple(t.strip() for t in text.split(","))
    if not all(names):
        raise argparse.ArgumentTypeError(f"--methods {text!r}: names separated by commas")
    return names


OWN_DATA = "your own data file (.npz, see docs/your-own-data.md)"
OUT = "summary.json, the estimates and the figures"


class Parser(argparse.ArgumentParser):
    """Errors as one line, `visjax: error: ...`, exit status 2, no usage block."""

    def error(self, message):
        self.exit(2, f"visjax: error: {message}\n")

    def _check_value(self, action, value):  # argparse's, with the closest choice named
        if action.choices is not None and value not in action.choices:
            hint, among = did_you_mean(value, action.choices), ", ".join(map(repr, action.choices))
            raise argparse.ArgumentError(
                action, f"invalid choice: {value!r}{hint} (choose from {among})"
            )


def arg(p, flag, kind=None, default=None, help=None, **kw):
    """One option, on one line: `arg(parser, "--scenes", count, 100, "help")`."""
    kw.update({"type": kind} if kind else {}, **({} if default is None else {"default": default}))
    p.add_argument(flag, help=help, **kw)


FORCE = "replace another command's results in --out (a sweep: a finished one)"


def noise_levels(text: str) -> float | tuple[float, ...]:
    """`--noise 0.5`, or (compare) `--noise 0,0.1,0.5,1`: levels, each at least 0."""
    levels = tuple(nonnegative(t) for t in text.split(","))
    return levels[0] if len(levels) == 1 else levels


def common(p, out=OUT, noise=False, seed=None, seeds=None, data=None, fmt=True, levels=False):
    """The shared vocabulary: --noise (`levels`: a list too), --seed, --seeds, --data, --out,
    --quiet, --format."""
    if noise is not False:  # None: the problem's own
        kind, more = (noise_levels, "; a,b,c: each") if levels else (nonnegative, "")
        said = "the problem's own" if noise is None else f"{noise:g}"
        arg(p, "--noise", kind, noise, f"pixel noise sigma, px (default {said}{more})")
    if seed is not None:
        arg(p, "--seed", seed_number, 0, seed)
    if seeds is not None:
        arg(p, "--seeds", count, seeds[0], seeds[1])
    if data is not None:
        arg(p, "--data", str, None, data)
    arg(p, "--out", str, None, f"folder for {out}")
    arg(p, "--force", help=FORCE, action="store_true")
    arg(p, "--quiet", help="no progress bars", action="store_true")
    if fmt:
        arg(p, "--format", figure_list, ["png"], "figure formats: png,pdf,svg (default png)")


SEEDS = (1, "noise seeds from --seed (default 1): medians and 10-90%% bands over them")
FIRST = "the first noise seed (default 0)"
HOURS = "refuse, after the second seed, --seeds estimated to take longer (default 24)"


def verb(sub, name, help, *, seeds, noise, grid):
    """A study verb over any registered problem: `visjax NAME PROBLEM [options]`."""
    p = sub.add_parser(name, help=help)
    names = problem_names()
    p.add_argument("problem", help=f"{', '.join(names)}, their aliases, or yours (--import)")
    held = "; then as many held-out seeds" if grid else ""
    seeds = None if seeds is None else (seeds, f"noise seeds (default {seeds}){held}")
    common(
        p,
        "summary.json, tables and figures",
        noise,
        FIRST,
        seeds,
        OWN_DATA,
        levels=name == "compare",
    )
    arg(p, "--duration", positive, None, "seconds of the problem's scene")
    arg(p, "--rate", positive, None, "sample rate of the scene, Hz (if it has one)")
    arg(p, "--set", None, None, "a variant (moving_point: I.1 ... II.3)", action="append")
    robust = "the problem's robust settings (robust losses, outlier gates; not moving_point)"
    arg(p, "--robust", help=robust, action="store_true")
    dtype = "float64 (default: the papers' accuracy) or float32 (docs/gpu.md: its accuracy)"
    arg(p, "--dtype", None, "float64", dtype, choices=("float64", "float32"))
    if name != "run":
        which = "every one" if name == "compare" else "the estimator; each in turn"
        arg(p, "--methods", method_names, None, f"a,b,c: the methods (default {which})")
    if name == "compare":
        tex = "also write the statistics tables as comparison.md or .tex (repeatable)"
        arg(p, "--table", None, None, tex, choices=("md", "tex"), action="append", dest="tables")
    if grid:
        arg(p, "--grid", grid_spec, None, 'e.g. "K_scale=1e-2:1e1:8,rho_scale=0.1/1"')
        arg(p, "--chunk", count, 64, "runs per vmap call (default 64)")
        slices = "alone: each chunk over every JAX device; i/N: the i-th of N slices (sweep)"
        arg(p, "--shard", shard_spec, False, slices, nargs="?", const=True, metavar="i/N")
    return p


EXAMPLES = {
    None: [
        "visjax reproduce --quick --out results",
        "visjax run velocity --noise 0.1 --out run",
        "visjax compare point_depth --seeds 8 --out cmp",
    ],
    "geometry": [
        "visjax geometry --scenes 100 --noise 0.5 --out geometry",
        "visjax geometry --points 8 --format png,pdf --out geometry8",
    ],
    "velocity": [
        "visjax velocity --out velocity",
        "visjax velocity --seeds 16 --noise 0.1 --out velocity16",
        "visjax velocity --data my_plate.npz --out mine",
    ],
    "moving_point": [
        "visjax moving_point --set I.1 --set II.1 --out sets",
        "visjax moving_point --data my_point.npz --out mine",
    ],
    "static_points": [
        "visjax static_points --duration 20 --out static",
        "visjax static_points --data my_scene.npz --out mine",
    ],
    "run": [
        "visjax run velocity --noise 0.1 --out run",
        "visjax run moving_point --set II.1 --method ekf --out ekf",
        "visjax run velocity --data my_plate.npz --out mine",
    ],
    "compare": [
        "visjax compare velocity --seeds 8 --noise 0.1 --out cmp",
        "visjax compare point_depth --noise 0,0.5,1 --out noise",
        "visjax compare static_points --tune --budget 16 --out tuned",
    ],
    "sweep": [
        'visjax sweep velocity --grid "K_scale=0.01:10:8" --seeds 8 --out sweep',
        'visjax sweep velocity --grid "K_scale=0.01:10:64" --shard 0/4 --out part0',
        'visjax sweep velocity --grid "K_scale=0.01:10:8" --resume --out sweep',
    ],
    "merge": [
        "visjax merge part0 part1 part2 part3 --out merged",
        "visjax merge sweep --out merged --force",
    ],
    "tune": [
        'visjax tune velocity --grid "K_scale=0.01:10:8" --steps 30 --out tuned',
        "visjax tune static_points --learning-rate 0.05 --out tuned",
    ],
    "track": [
        "visjax track plate.mp4 --out tracks.csv",
        "visjax track plate.mp4 --planar --max-features 50 --out tracks.npz",
        "visjax track plate.mp4 --tags 36h11 --out tags.npz",
    ],
    "data": [
        "visjax data velocity --tracks tracks.npz --camera camera.yaml --out plate.npz",
        "visjax data moving_point --tracks tracks.csv --camera camera.json --out point.npz",
    ],
    "import-bag": [
        "visjax import-bag plate.bag --problem velocity --image-topic /camera/image_raw "
        "--camera-info /camera/camera_info --tags 36h11 --camera tag.yaml --out plate.npz",
        "visjax import-bag run1 --problem moving_point --image-topic /cam/image "
        "--camera-info /cam/camera_info --odometry /odom --camera point.yaml --out point.npz",
    ],
    "testbed": [
        "visjax testbed --set I.1 --duration 10 --no-video --out twin",
        "visjax testbed --out twin",
    ],
    "reproduce": [
        "visjax reproduce --quick --out results",
        "visjax reproduce --format png,pdf --out results",
    ],
}
"""Each command's `--help` ends with these (`with_examples`; `None`: `visjax --help`)."""


def with_examples(parser, sub) -> None:
    """Each parser's help ends with its `EXAMPLES` (the text kept as written)."""
    for name, p in [(None, parser), *sub.choices.items()]:
        lines = EXAMPLES.get(name)
        if lines:
            p.epilog = "examples:\n" + "\n".join(f"  {line}" for line in lines)
            p.formatter_class = argparse.RawDescriptionHelpFormatter


def build_parser() -> argparse.ArgumentParser:
    """The command line's grammar: every command and option (`visjax.cli` runs them)."""

    parser = Parser(prog="visjax", description="Vision-based estimators in JAX (docs/)")
    parser.add_argument("--version", action="version", version=f"visjax {__version__}")
    arg(parser, "--import", None, None, "a module registering problems or reproductions of yours",
         dest="modules", action="append", metavar="MODULE")  # fmt: skip
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)

    g = sub.add_parser("geometry", help="homography and decomposition vs OpenCV vs the truth")
    arg(g, "--scenes", count, 100, "random planar scenes (default 100)")
    arg(g, "--points", points, 4, "points per scene, >= 4 (default 4)")
    common(g, "summary.json, scenes.parquet and the figure", 0.0, "the seed (default 0)")

    v = sub.add_parser("velocity", help="Chitrakaran et al.'s section 6, or your data")
    arg(v, "--duration", positive, 10.0, "seconds (default 10)")
    arg(v, "--rate", positive, 1000.0, "sample rate, Hz (default 1000)")
    arg(v, "--K", six, None, "diagonal of K (default: the problem's, eq. (63))")
    arg(v, "--rho", six, None, "diagonal of rho (default: the problem's, eq. (63))")
    arg(v, "--filter-hz", positive, None, "with --data: a causal 2nd-order low-pass")
    common(v, OUT, 0.0, FIRST, SEEDS, OWN_DATA)
    arg(v, "--max-hours", positive, 24.0, HOURS)

    st = _problem_parser(sub, "moving_point", "structure", "Jang's unknown input observer")
    arg(st, "--set", None, None, "I.1 ... II.3 (repeatable; default: all)", action="append")
    arg(st, "--duration", positive, 30.0, "seconds per set (default 30)")
    common(st, OUT, 0.1, FIRST, SEEDS, OWN_DATA)
    arg(st, "--max-hours", positive, 24.0, HOURS)

    eu = _problem_parser(sub, "static_points", "euclidean", "Nath et al.'s uncalibrated camera")
    arg(eu, "--duration", positive, 30.0, "seconds (default 30)")
    common(eu, OUT, 0.0, FIRST, SEEDS, OWN_DATA)
    arg(eu, "--max-hours", positive, 24.0, HOURS)
    arg(eu, "--noise-px", nonnegative, None, argparse.SUPPRESS, dest="noise")  # 0.2's name

    run = verb(sub, "run", "one method of a problem once", seeds=None, noise=0.0, grid=False)
    arg(run, "--method", None, None, "the method (default: the estimator)")
    rerun = "also a Rerun recording of the run(s), FILE.rrd (pip install 'visjax[viz]')"
    arg(run, "--rerun", None, None, rerun)
    help = "a problem's methods on identical noisy inputs"
    cmp = verb(sub, "compare", help, seeds=4, noise=None, grid=False)
    hours = "refuse, after the first seed, a comparison estimated to take longer (default 24)"
    arg(cmp, "--max-hours", positive, 24.0, hours)
    arg(cmp, "--rerun", None, None, rerun)
    tune = "first tune every method, with the same --budget, on as many other seeds"
    arg(cmp, "--tune", help=tune, action="store_true")
    budget = f"objective evaluations per method for --tune (default {BUDGET})"
    arg(cmp, "--budget", count, BUDGET, budget)
    help = "a grid of a problem's parameters over noise seeds"
    sw = verb(sub, "sweep", help, seeds=8, noise=None, grid=True)
    arg(sw, "--resume", help="continue an interrupted sweep from its parts", action="store_true")
    ray = "run the chunks on a Ray cluster (no address: a local one; pip install visjax[ray])"
    arg(sw, "--ray", None, None, ray, nargs="?", const="local", metavar="ADDRESS")
    me = sub.add_parser("merge", help="the parts of a sweep's shards as one table")
    me.add_argument("paths", nargs="+", metavar="DIR", help="folders holding the parts")
    arg(me, "--out", None, None, "runs.parquet, runs.csv and summary.json", required=True)
    arg(me, "--force", help=FORCE, action="store_true")
    arg(me, "--quiet", help="less printing", action="store_true")
    help = "a sweep, then gradient-based tuning from its best point"
    tu = verb(sub, "tune", help, seeds=4, noise=None, grid=True)
    arg(tu, "--steps", count, 30, "optimiser steps (default 30)")
    arg(tu, "--learning-rate", positive, 0.1, "Adam's step on the log parameters (0.1)")

    tr = sub.add_parser("track", help="a video to pixel tracks (KLT, forward-backward check)")
    tr.add_argument("video", help="the video (MP4 or anything OpenCV reads, or .npz)")
    arg(tr, "--out", None, None, "the tracks file: .npz or .csv", required=True)
    arg(tr, "--force", help="replace the tracks file if it exists", action="store_true")
    arg(tr, "--detector", None, "corners", "features to track", choices=("corners", "aruco"))
    tags = "AprilTags of this family: their corners, found in every frame (feature 4 id + c)"
    arg(tr, "--tags", None, None, tags, choices=TAG_FAMILIES)
    arg(tr, "--max-features", count, 200, "features alive at once (default 200)")
    arg(tr, "--fb-threshold", positive, 0.5, "forward-backward error that drops one, px")
    arg(tr, "--fps", positive, None, "frame rate (default: the video's)")
    planar = "a planar scene: cut the tracks that do not follow the frames' homography"
    arg(tr, "--planar", help=planar, action="store_true")
    arg(tr, "--homography-threshold", positive, 3.0, "px, the --planar test (default 3)")
    damaged = "track a video whose decoder reports damaged frames (they are concealed)"
    arg(tr, "--allow-damaged", help=damaged, action="store_true")
    arg(tr, "--quiet", help="no progress bar and no summary", action="store_true")
    tr.set_defaults(out_is_file=True)

    da = sub.add_parser("data", help="pixel tracks and a camera file to a problem's data file")
    da.add_argument("problem", choices=io.PROBLEMS, help="the problem whose data file to write")
    arg(da, "--tracks", None, None, "the tracks (visjax track's .npz or .csv)", required=True)
    arg(da, "--camera", None, None, "the camera's constants, YAML or JSON", required=True)
    arg(da, "--out", None, None, "the data file (.npz)", required=True)
    arg(da, "--force", help="replace the data file if it exists", action="store_true")
    arg(da, "--quiet", help="print nothing", action="store_true")
    da.set_defaults(out_is_file=True)

    ib = sub.add_parser("import-bag", help="a ROS bag (1 or 2) to a problem's data file")
    ib.add_argument("bag", help="the .bag file, or the ROS 2 bag's folder")
    arg(ib, "--problem", None, None, "the problem", required=True, choices=BAG_PROBLEMS)
    arg(ib, "--image-topic", None, None, "the camera's images", required=True)
    arg(ib, "--camera-info", None, None, "the camera's CameraInfo topic", required=True)
    velocity = ib.add_mutually_exclusive_group()
    arg(velocity, "--twist", None, None, "the body's TwistStamped topic")
    arg(velocity, "--odometry", None, None, "the body's Odometry topic")
    arg(velocity, "--joint-states", None, None, "the robot's JointState topic (with --robot)")
    arg(ib, "--robot", None, None, "the robot of --joint-states", choices=("puma560", "two_link"))
    arg(ib, "--tags", None, None, "track AprilTags of this family (else KLT)", choices=TAG_FAMILIES)
    what = "what the bag cannot tell (YAML or JSON, as for visjax data, without intrinsics)"
    arg(ib, "--camera", None, None, what)
    pose = "the camera's pose in the body frame, 'x y z qx qy qz qw' (without /tf_static)"
    arg(ib, "--camera-from-body", None, None, pose)
    arg(ib, "--out", None, None, "the data file (.npz)", required=True)
    arg(ib, "--force", help="replace the data file if it exists", action="store_true")
    arg(ib, "--quiet", help="print nothing", action="store_true")
    ib.set_defaults(out_is_file=True)

    tb = sub.add_parser("testbed", help="Jang's thesis end to end on a twin of its testbed")
    arg(tb, "--set", set_name, None, "I.1 ... II.3 (repeatable; default all)", action="append")
    units = "the unit of the velocities in the thesis' A matrices (default cm)"
    arg(tb, "--units", None, "cm", units, choices=("cm", "m"))
    arg(tb, "--duration", positive, 30.0, "seconds per set (default 30)")
    arg(tb, "--no-video", help="no MP4 of the rendered frames", action="store_false", dest="video")
    no_studies = "skip the camera matrix (Tables 5-1/5-2), the v_py sensitivity, the error budget"
    arg(tb, "--no-studies", help=no_studies, action="store_false", dest="studies")
    seed = "the texture's and the image noise's seed (0)"
    common(tb, "tables, estimates, figures and videos", False, seed)

    r = sub.add_parser("reproduce", help="every paper's main experiment and a summary")
    arg(r, "--quick", help=report.quick_help(), action="store_true")
    arg(r, "--rerun", None, None, rerun)
    common(r, "everything (default results)")
    r.set_defaults(out="results")
    with_examples(parser, sub)
    return parser


def _problem_parser(sub, name, old, who):
    """A paper's command named for its problem, its name before version 0.3 an alias."""
    p = sub.add_parser(name, aliases=[old], help=f"{who}, or your data")
    p.set_defaults(command=name)
    return p
