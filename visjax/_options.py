"""The command line's option vocabulary (`visjax.cli` declares its commands with it): the
option types, each parsing one option's text or raising `argparse.ArgumentTypeError` with
one line (`visjax: error: argument --X: ...`; the checks that are the library's, a shard, a
grid, figure formats, are called, not copied), and the options commands share."""

import argparse
import math

from .plots import figure_formats
from .studies import check_grid_text, parse_shard, problem_names, registered

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
        raise argparse.ArgumentTypeError(f"unknown set {text!r}; choose from {', '.join(sets)}")
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
