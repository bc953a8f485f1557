"""The registry of reproductions: a name -> a function that runs a paper's experiment into
a folder and returns the rows of `visjax reproduce`'s table, which the command iterates.

The papers' reproductions are registered by `visjax.papers`, beside their problems. A
user's is one line, `visjax.studies.register_reproduction("name", run, title=...)`, in a
module named with `visjax --import MODULE reproduce`.

`run(out, *, quick, quiet, formats, **options) -> rows`: `out` the folder of its files
(`None`: write nothing), `quick` the shorter settings of `visjax reproduce --quick`,
`quiet` no progress bars, `formats` the figure formats, and any options of its own (the
command line's per-paper commands pass theirs). Each row is a dict of `ROW_KEYS`: `name`
(what the number is), `value` (a float, or `None` where the experiment could not give
it), `reference` (the number it is held against, a float), `reference_kind` (what the
reference is: `published`, a paper's number; `truth`, the simulation's; `bound`, a bound
the value must stay under; `OpenCV`, the reference library's; `ideal`, the response the
paper's law assigns; `trivial`, the error of a trivial estimate, e.g. zero velocity) and
`unit`.
"""

import contextlib
import dataclasses
import math
import re
from collections.abc import Callable, Sequence

import jax

from .._util import did_you_mean

ROW_KEYS = ("name", "value", "reference", "reference_kind", "unit")
"""The keys of a row of `visjax reproduce`'s table, in its columns' order."""
REFERENCE_KINDS = ("published", "truth", "bound", "OpenCV", "ideal", "trivial")
"""What a row's reference may be (the module's docstring says what each means)."""


class RunFailed(RuntimeError):
    """A command's run did not succeed: its result code is not `successful` (a failed run,
    or a data file with too many frames missing). Raised after every file and the summary
    (which records the result code) are written; its message is one line, e.g.
    `run velocity: the run failed: diverged at sample 123`. The command line prints it as
    `visjax: error: ...`, keeps the files and exits with status 1."""


_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]*")


@dataclasses.dataclass(frozen=True)
class RegisteredReproduction:
    """A registered reproduction: `name`, `run` (see the module's docstring), `title`
    (the heading `visjax reproduce` prints before it), `folder` (its output folder under
    `reproduce`'s `--out`), `quick` (what `--quick` shortens, one phrase for `--help`)."""

    name: str
    run: Callable[..., Sequence[dict]]
    title: str
    folder: str
    quick: str = ""

    def rows(self, out=None, *, quick=False, quiet=False, formats=("png",), **options):
        """Run it and return its rows, checked (`check_rows`); `quick` on the host's CPU
        (`quick_device`)."""
        with quick_device(quick):
            rows = self.run(out, quick=quick, quiet=quiet, formats=tuple(formats), **options)
        return check_rows(self.name, rows)


def quick_device(quick: bool):
    """Where a reproduction computes: `--quick`'s shorter settings on the host's CPU when
    JAX's default backend is an accelerator (`jax.default_device`), the rest where JAX
    computes by default.

    Every stage of `reproduce --quick` is one or a few short runs, which compile more than
    they compute: on an H200 the quick reproduction did not finish in 152 s, against 73 s
    on a 2-core CPU (issue 47). The full settings (long scenes, many seeds) stay on the
    accelerator."""
    if quick and jax.default_backend() != "cpu":
        return jax.default_device(jax.devices("cpu")[0])
    return contextlib.nullcontext()


_REPRODUCTIONS: dict[str, RegisteredReproduction] = {}


def register_reproduction(
    name: str,
    run: Callable[..., Sequence[dict]],
    *,
    title: str,
    folder: str | None = None,
    quick: str = "",
    replace: bool = False,
) -> RegisteredReproduction:
    """Register a reproduction under `name` for `visjax reproduce` (run in the order of
    registration). `folder`: its output folder (default `name`). A name already taken is
    an error unless `replace`."""
    if not (isinstance(name, str) and _NAME.fullmatch(name)):
        raise ValueError(
            "a reproduction's name must be letters, digits, '_' or '-', starting with a "
            f"letter; got {name!r}."
        )
    if not callable(run):
        raise TypeError(f"`run` of reproduction {name!r} must be callable.")
    folder = name if folder is None else folder
    if not (isinstance(folder, str) and _NAME.fullmatch(folder)):
        raise ValueError(f"reproduction {name!r}: `folder` must be a plain name; got {folder!r}.")
    if name in _REPRODUCTIONS and not replace:
        raise ValueError(f"a reproduction named {name!r} is registered already (replace=True).")
    used = {e.folder: e.name for e in _REPRODUCTIONS.values() if e.name != name}
    if folder in used:
        raise ValueError(
            f"reproduction {name!r} would share the output folder {folder!r} with "
            f"{used[folder]!r}; give another `folder`."
        )
    entry = RegisteredReproduction(name, run, str(title), folder, str(quick))
    _REPRODUCTIONS[name] = entry
    return entry


def reproduction_names() -> list[str]:
    """The registered reproductions' names, in the order `visjax reproduce` runs them."""
    return list(_REPRODUCTIONS)


def registered_reproduction(name: str) -> RegisteredReproduction:
    """The registry entry of `name`. **Raises:** `ValueError` listing the names."""
    if name not in _REPRODUCTIONS:
        hint = did_you_mean(name, _REPRODUCTIONS)
        raise ValueError(f"unknown reproduction {name!r}{hint}; choose from {reproduction_names()}")
    return _REPRODUCTIONS[name]


def reproduction_row(
    name: str, value, reference, reference_kind: str, unit: str
) -> dict[str, object]:
    """One row of `visjax reproduce`'s table (`ROW_KEYS`), its numbers as Python floats
    (`value` may be `None`: the experiment could not give it)."""
    return {
        "name": str(name),
        "value": None if value is None else float(value),
        "reference": float(reference),
        "reference_kind": str(reference_kind),
        "unit": str(unit),
    }


def check_rows(name: str, rows) -> list[dict]:
    """`rows` of the reproduction `name` as a list of dicts, each with exactly `ROW_KEYS`:
    a `str` name and unit, a finite float (or `None`) value, a finite float reference, a
    `reference_kind` of `REFERENCE_KINDS`. **Raises:** `ValueError` naming the first row
    and key that are wrong."""
    try:
        rows = list(rows)
    except TypeError:
        raise ValueError(
            f"reproduction {name!r} returned {type(rows).__name__}, not a list of rows."
        ) from None
    for i, row in enumerate(rows):
        where = f"reproduction {name!r}, row {i}"
        if not isinstance(row, dict) or set(row) != set(ROW_KEYS):
            got = sorted(row) if isinstance(row, dict) else type(row).__name__
            raise ValueError(f"{where}: a row is a dict of the keys {ROW_KEYS}; got {got}.")
        for key in ("name", "unit", "reference_kind"):
            if not isinstance(row[key], str):
                raise ValueError(f"{where}: `{key}` must be a str; got {row[key]!r}.")
        if row["reference_kind"] not in REFERENCE_KINDS:
            raise ValueError(
                f"{where}: `reference_kind` must be one of {REFERENCE_KINDS}; "
                f"got {row['reference_kind']!r}."
            )
        for key in ("value", "reference"):
            value = row[key]
            if value is None and key == "value":
                continue
            ok = isinstance(value, int | float) and not isinstance(value, bool)
            if not (ok and math.isfinite(value)):
                raise ValueError(f"{where}: `{key}` must be a finite number; got {value!r}.")
    return rows
