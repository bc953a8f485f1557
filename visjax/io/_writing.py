"""Writing a command's outputs: the files of a run (`Outputs`, `write_outputs`) and its
`summary.json` (`command_summary`), each checked against its schema."""

import dataclasses
import datetime
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .._version import __version__
from ._outputs import SUMMARIES, finite_or_null, validate_summary, write_summary


@dataclasses.dataclass(frozen=True)
class Outputs:
    """Files of a run, written by `write_outputs` as soon as they are ready (a long run
    loses nothing already done when it is interrupted).

    **Fields:** `arrays`: file name (`.npz`) -> {key: array}; `tables`: file stem -> a
    pandas DataFrame, written as Parquet (and as CSV for the stems in `csv`); `figures`:
    file stem -> `draw(path, formats)` (a `visjax.plots` function with its data bound);
    `json`: file name -> a JSON-able dict (NaN and inf written as null); `videos`: file
    name -> `write(path)`."""

    arrays: dict[str, dict] = dataclasses.field(default_factory=dict)
    tables: dict[str, Any] = dataclasses.field(default_factory=dict)
    csv: tuple[str, ...] = ()
    figures: dict[str, Callable] = dataclasses.field(default_factory=dict)
    json: dict[str, dict] = dataclasses.field(default_factory=dict)
    videos: dict[str, Callable] = dataclasses.field(default_factory=dict)


def write_outputs(outputs: Outputs, out, formats=("png",)) -> list[str]:
    """Write `outputs` into the folder `out` (created if needed), each figure in every
    format of `formats`. **Returns:** the names of the files written."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, arrays in outputs.arrays.items():
        np.savez(out / name, **{k: np.asarray(v) for k, v in arrays.items()})
        written.append(name)
    for stem, table in outputs.tables.items():
        table.to_parquet(out / f"{stem}.parquet", index=False)
        written.append(f"{stem}.parquet")
        if stem in outputs.csv:
            table.to_csv(out / f"{stem}.csv", index=False)
            written.append(f"{stem}.csv")
    for name, obj in outputs.json.items():
        (out / name).write_text(json.dumps(finite_or_null(obj), indent=2, allow_nan=False))
        written.append(name)
    for stem, draw in outputs.figures.items():
        draw(path=out / f"{stem}.png", formats=formats)
        written += [f"{stem}.{f}" for f in formats]
    for name, write in outputs.videos.items():
        write(out / name)
        written.append(name)
    return written


def figure_files(path, formats) -> str:
    """The files of a figure written at `path` in `formats`, for a printed file list."""
    return ", ".join(str(Path(path).with_suffix("." + f)) for f in formats)


def command_summary(
    kind: str, body: dict, *, settings: dict, seed, started: float, out=None
) -> dict:
    """A command's summary: `body` with the keys every summary has (`COMMON`: the versions,
    the time, the wall time since `started`, a `time.perf_counter()` value, the seed, the
    settings), checked against the schema `kind` of `SUMMARIES`, written to
    `out / "summary.json"` when `out` is given. **Returns:** the summary as written."""
    import jax

    if kind not in SUMMARIES:  # an old kind is read, never written
        raise ValueError(f"summary `kind` must be one of {sorted(SUMMARIES)}; got {kind!r}.")
    summary = {
        "kind": kind,
        "visjax_version": __version__,
        "jax_version": jax.__version__,
        "backend": jax.default_backend(),
        "device": jax.devices()[0].device_kind,
        "dtype": "float64" if jax.config.jax_enable_x64 else "float32",
        "created_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "wall_time_s": time.perf_counter() - started,
        "seed": seed,
        "settings": {k: (str(v) if isinstance(v, Path) else v) for k, v in settings.items()},
        **body,
    }
    if out is not None:
        return write_summary(Path(out) / "summary.json", summary)
    return validate_summary(finite_or_null(summary))
