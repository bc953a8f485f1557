"""The homography observer on SL(3) from direct point correspondences.

T. Hamel, R. Mahony, J. Trumpf, P. Morin, M.-D. Hua, *Homography estimation on the Special
Linear group based on direct point correspondence*, IEEE CDC-ECC 2011.

The observer and its stream builder are `visjax.estimators.HomographyEstimator` and
`homography_stream` (their module states the model, the observer and its derivation), the
OpenCV baseline `visjax.baselines.ransac_homographies`, the scene
`visjax.sim.homography_scene`: all built on visjax's public contract only, as a user's
estimator would be (`docs/extending.md`). Here: the problems `homography` and its
`velocity_front_end` variant (`homography_problem`) and the registered reproduction.
Equation numbers: the paper's text was not available to this transcription; the observer
is cited by name and its properties derived and tested.
"""

import functools

import numpy as np

from ..._util import renamed
from ...baselines import ransac_homographies as ransac_homographies
from ...estimators import (
    HomographyEstimator as HomographyEstimator,  # re-exported: the problem's estimator
    HomographyMeasurement as HomographyMeasurement,
    HomographyOutput as HomographyOutput,
    HomographyState as HomographyState,
    homography_innovation as homography_innovation,
    homography_stream as homography_stream,
    unit_bearings as unit_bearings,
)
from ...io import Outputs
from ...plots import plot_comparison
from ...sim import (
    HomographyScene as HomographyScene,
    homography_scene as homography_scene,
    plane_group_velocity as plane_group_velocity,
)
from ...studies import (
    Study,
    compare,
    reproduction_row,
)
from .._reproduction import Reproduction, write_report
from ._problem import (
    FrameHomographies as FrameHomographies,
    HomographyProblem as HomographyProblem,
    VelocityFrontEndProblem as VelocityFrontEndProblem,
    homography_error as homography_error,
    homography_problem as homography_problem,
)
from ._scene import (
    ANGULAR_VELOCITY as ANGULAR_VELOCITY,
    CAMERA as CAMERA,
    PLANE_DISTANCE as PLANE_DISTANCE,
    PLANE_POINTS as PLANE_POINTS,
    ROBUST_ITERATIONS as ROBUST_ITERATIONS,
    ROBUST_THRESHOLD_PX as ROBUST_THRESHOLD_PX,
    START as START,
    START_ROTATION as START_ROTATION,
    VELOCITY as VELOCITY,
)


def _records_metric(metric: str):
    """A record's `metric`, NaN where the run gave none (a failed run)."""

    def value(record):
        v = record[metric]
        return float("nan") if v is None else v

    return value


def reproduce_homography(
    out=None,
    *,
    quick: bool = False,
    quiet: bool = False,
    formats=("png",),
    noise: float = 0.1,
    seeds: int | None = None,
    duration: float | None = None,
    seed: int = 0,
) -> list[dict]:
    """The observer as the front end of the velocity problem (the variant
    `velocity_front_end`: Chitrakaran et al.'s estimator fed by the observer's homography
    or by the per-frame four-point one, on the same draws), registered as the reproduction
    `homography`: `studies.compare` over `seeds` noise seeds at `noise` px; `summary.json`
    (kind `homography`), `records.parquet/.csv` and `comparison.<format>` into `out`.
    `seeds`, `duration`: 5 seeds of 10 s (the scoring window 5-10 s), 2 of 4 s with `quick`.
    **Returns:** its rows: each front end's median worst-axis RMS against that of answering
    zero velocity (kind `trivial`)."""
    import pandas as pd

    seeds = (2 if quick else 5) if seeds is None else int(seeds)
    duration = (4.0 if quick else 10.0) if duration is None else float(duration)

    def reproduce(write):
        problem = homography_problem(
            noise_px=noise, duration=duration, variant="velocity_front_end"
        )
        keys = np.arange(seed, seed + seeds)
        records = compare(problem, keys, study=Study(progress=not quiet))
        metric = problem.metric
        trivial = float(problem.trivial()[metric])
        per = {}
        for m in problem.methods:
            mine = [r for r in records if r["method"] == m]
            good = [r[metric] for r in mine if r["result"] == "successful" and r[metric]]
            per[m] = {
                "median": float(np.median(good)) if good else None,
                "failed": sum(r["result"] != "successful" for r in mine),
            }
        if write is not None:
            draw = functools.partial(
                plot_comparison, records, _records_metric(metric), label=problem.label,
                title=problem.title,
            )  # fmt: skip
            write(
                Outputs(
                    tables={"records": pd.DataFrame(records)},
                    csv=("records",),
                    figures={"comparison": draw},
                )
            )
        lines = [f"{problem.title}: {seeds} seed(s); {metric}: {problem.label}"]
        lines.append(f"{'front end':<14}{'failed':>8}{metric + ' (median)':>24}")
        for m, v in per.items():
            value = "-" if v["median"] is None else f"{v['median']:.4g}"
            lines.append(f"{m:<14}{v['failed']:>8}{value:>24}")
        lines.append(f"{'zero velocity':<14}{'':>8}{trivial:>24.4g}")
        body = {
            "noise_px": float(noise),
            "seeds": seeds,
            "duration_s": duration,
            "metric": metric,
            "trivial": trivial,
            "methods": per,
        }
        return Reproduction(body, lines, seed=seed)

    settings = dict(noise=noise, seeds=seeds, duration=duration, seed=seed)
    summary = write_report("homography", settings, out, formats, reproduce)
    return [
        reproduction_row(
            f"Hamel et al., velocity front end ({m}): median worst-axis RMS at {noise:g} px",
            v["median"],
            summary["trivial"],
            "trivial",
            "m/s or rad/s",
        )
        for m, v in summary["methods"].items()
    ]


RENAMED = {"HomographyObserver": "HomographyEstimator"}
"""The names of visjax 0.3 (old -> new): still given, with a `FutureWarning`."""
__getattr__ = renamed("visjax.papers.hamel", RENAMED, globals())
