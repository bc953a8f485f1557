"""What a paper's reproduction computes: the summary's keys and the printed lines
(`Reproduction`); the files to write go to a `write` callback as `visjax.io.Outputs` as soon
as they are ready. `write_report` runs one, writes its files and summary and prints: what
each paper's registered reproduction (`visjax.studies.register_reproduction`) does."""

import dataclasses
import time
from pathlib import Path

import numpy as np

from ..io import command_summary, write_outputs
from ..studies import RunFailed, StudyTooLong


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


def write_report(kind: str, settings: dict, out, formats, reproduce) -> dict:
    """Run `reproduce(write)` (a paper's reproduction, returning a `Reproduction`), writing
    its files into `out` as they come (nothing without `out`), then its `summary.json`
    (kind `kind`); print its lines and the files written; raise its failure, if any, after
    everything is written (`visjax.studies.RunFailed`). **Returns:** the summary."""
    started = time.perf_counter()
    out = None if out is None else Path(out)
    written = []

    def write(outputs):
        written.extend(write_outputs(outputs, out, formats))

    rep = reproduce(None if out is None else write)
    settings = {**settings, **rep.settings, "formats": list(formats)}
    summary = command_summary(
        kind, rep.body, settings=settings, seed=rep.seed, started=started, out=out
    )
    print("\n".join(rep.lines))
    if out is not None:
        shown = ", ".join(["summary.json", *written[:8]])
        more = f" and {len(written) - 8} more" if len(written) > 8 else ""
        print(f"wrote {out}/: {shown}{more}")
    if rep.failure is not None:
        raise RunFailed(rep.failure)
    return summary


def check_seeds(seeds, noise) -> None:
    """`seeds` a positive int, and noise when there is more than one seed."""
    if not (isinstance(seeds, int) and not isinstance(seeds, bool) and seeds >= 1):
        raise ValueError(f"`seeds` must be a positive int; got {seeds!r}.")
    if seeds > 1 and not noise > 0:
        raise ValueError(
            f"{seeds} seeds need pixel noise (`noise` > 0): noise-free runs are all the same."
        )


class SeedClock:
    """The time of a loop over `runs` noise seeds, checked as it goes: after the second
    run (the first that reuses the compiled program), a loop estimated to take longer than
    `max_hours` in all is refused (`visjax.studies.StudyTooLong`, naming the estimate),
    before the rest of the runs; call `tick()` after each run. `bar`: a progress bar,
    closed before the refusal (so that the error is the last line printed)."""

    def __init__(self, runs: int, max_hours: float, what: str, bar=None):
        self.runs, self.max_hours, self.what, self.bar = int(runs), float(max_hours), what, bar
        self.started = time.perf_counter()
        self.marks: list[float] = []

    def tick(self) -> None:
        self.marks.append(time.perf_counter())
        if len(self.marks) != 2 or self.runs <= 2:
            return
        first = self.marks[0] - self.started
        each = self.marks[1] - self.marks[0]
        total = first + each * (self.runs - 1)
        if total > 3600.0 * self.max_hours:
            if self.bar is not None:
                self.bar.close()
            raise StudyTooLong(
                f"{self.what}: {self.runs} runs estimated at {total / 3600:.3g} h ({each:.3g} s "
                f"each after the first), past --max-hours {self.max_hours:g}: use fewer "
                "--seeds, a shorter --duration, or raise --max-hours"
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
