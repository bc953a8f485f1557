"""What a paper's reproduction hands to `visjax.report`: the summary's keys and the printed
lines (`Reproduction`); the files to write go to a `write` callback as `visjax.io.Outputs` as soon
as they are ready. The reproductions compute; the report writes and prints."""

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class Reproduction:
    """A reproduction's result. **Fields:** `body` (the summary's own keys, JSON-able);
    `lines` (the printed tables and figures, one string per line); `settings` (settings it
    resolved, such as default gains, recorded over the caller's); `seed` (the noise seed,
    `None` for a noise-free run); `failure` (`None`, or what stopped the run, raised by the
    report after everything is written)."""

    body: dict
    lines: list[str]
    settings: dict = dataclasses.field(default_factory=dict)
    seed: int | None = None
    failure: str | None = None


def check_seeds(seeds, noise) -> None:
    """`seeds` a positive int, and noise when there is more than one seed."""
    if not (isinstance(seeds, int) and not isinstance(seeds, bool) and seeds >= 1):
        raise ValueError(f"`seeds` must be a positive int; got {seeds!r}.")
    if seeds > 1 and not noise > 0:
        raise ValueError(
            f"{seeds} seeds need pixel noise (`noise` > 0): noise-free runs are all the same."
        )


def median(rows) -> list:
    """The median over seeds (the first axis), as a list of floats."""
    return [float(x) for x in np.median(np.asarray(rows, float), axis=0)]


def stages(total: int, desc: str, quiet: bool):
    """A progress bar of `total` stages (tqdm), silent when `quiet`."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="stage", disable=quiet)


def floats(x) -> list[float] | None:
    """A vector as a list of floats, or `None` if any entry is not finite (an infeasible or
    failed run)."""
    x = np.asarray(x, float)
    return [float(v) for v in x] if np.all(np.isfinite(x)) else None
