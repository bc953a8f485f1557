"""Nath, Dawson, Tatlicioglu, *Euclidean position estimation of static features using a
moving uncalibrated camera*: the simulation, the gains that work at 1 kHz, the initial
estimates, the experiment and its metrics. Nothing else in visjax knows these numbers.

A camera on a moving platform looking at static features.

The platform (an end effector) moves on an exciting trajectory: it translates on a
Lissajous figure and rotates about all three axes, while the camera, mounted with an
unknown rotation and offset, keeps several known and unknown static features in view.
The estimator is given the platform pose and the pixels; the truth is in the scenario.

Choices (the paper refers its simulation to [28]): camera $f = 8$ mm, $k_u = k_v = 10^5$
px/m, skew angle $\\phi = 88°$, principal point (320, 240); $R_c$ a 5° rotation, $x_c =
[0.05, -0.03, 0.10]$ m; six known features and four unknown ones on a 0.4 m x 0.3 m patch
about 1.5 m in front of the platform, with 0.25 m of relief; the platform moves by
up to 0.1 m and 0.1 rad at 0.2-0.5 Hz. `exciting=False` gives pure translation along the
optical axis (a trajectory that does not excite the regressors).
"""

import jax
import numpy as np

from ..._results import RESULTS, result_names
from ..._util import renamed
from ...estimators import (
    pe_measure,
)
from ...io import Outputs
from ...plots import plot_static_points
from ...studies import reproduction_row, solution
from .._reproduction import (
    Reproduction,
    SeedClock,
    check_seeds,
    median,
    stages,
    write_report,
)
from ._problem import (
    FinalEstimate as FinalEstimate,
    StaticPointsProblem as StaticPointsProblem,
    static_points_problem as static_points_problem,
)
from ._scene import (
    StaticPointsRun as StaticPointsRun,
    UncalibratedScenario as UncalibratedScenario,
    initial_estimator as initial_estimator,
    nominal_camera as nominal_camera,
    scenario as scenario,
    stream as stream,
)


def static_points_experiment(
    duration: float = 30.0,
    noise_px: float = 0.0,
    *,
    seed: int = 0,
    exciting: bool = True,
    pe_window: float = 2.0,
) -> StaticPointsRun:
    """The project's scenario as the `static_points` problem states it
    (`static_points_problem` at 1 kHz): `noise_px` of pixel noise (seed `seed`), the
    estimator from the nominal camera (`initial_estimator`'s derived gains) run once
    (`studies.solution`), saved every 10 ms with its diagnostics.

    **Raises:** `RuntimeError` if the run fails (its result code and sample)."""

    problem = static_points_problem(
        noise_px=noise_px, duration=duration, rate_hz=1000.0, exciting=exciting
    )
    sol = solution(problem, {}, jax.random.key(seed))
    if not bool(sol.result == RESULTS.successful):
        raise RuntimeError(
            f"the adaptive structure estimator failed: {result_names(sol.result)} at sample "
            f"{int(sol.failed_sample)}."
        )
    d = sol.diagnostics
    return StaticPointsRun(
        ts=sol.ts,
        omega_s=sol.outputs.omega_s,
        omega_true=problem.truth,
        p_tilde_c=d.p_tilde_c,
        p_tilde_s=d.p_tilde_s,
        pe=pe_measure(d.info_rate_s, sol.ts, pe_window),
        depth_s=d.depth_s,
        depth_c=d.depth_c,
        lambda_min_gamma_c=d.lambda_min_gamma_c,
        resets=d.resets,
    )


def final_errors(r: StaticPointsRun) -> np.ndarray:
    """The final position error of each unknown feature, metres."""
    return np.linalg.norm(np.asarray(r.omega_s[-1] - r.omega_true), axis=-1)


# The reproduction that `visjax static_points` and `visjax reproduce` print and write
# (`visjax.report`).

POSITION_BOUND_MM = 1.0
"""The reproduction table's bound on the largest final position error (mm): the paper's
simulation shows the estimates converging onto the features."""


def static_points_reproduction(
    duration: float = 30.0,
    noise_px: float = 0.0,
    *,
    seed: int = 0,
    seeds: int = 1,
    quiet=True,
    write=None,
    max_hours: float = 24.0,
) -> Reproduction:
    """The adaptive least-squares structure estimator on its simulation
    (`static_points_experiment`), as `visjax static_points` reports it: the final position errors,
    `estimate.npz` (`t`, `features` over time, `truth`) and the figure `euclidean`. With
    `seeds` > 1, the noise seeds `seed, ..., seed + seeds - 1`: the errors are their
    medians (each seed's in `final_position_error_m_seeds`), `features` has a leading seed
    axis and the figure shows the medians and their 10-90 % bands."""
    import functools

    check_seeds(seeds, noise_px)
    bar = stages(1 + seeds, "static_points", quiet)
    bar.set_postfix_str("simulate and estimate (compiles once)")
    runs = []
    clock = SeedClock(seeds, max_hours, "static_points", bar)
    for i in range(seeds):
        runs.append(static_points_experiment(duration, noise_px, seed=seed + i))
        clock.tick()
        bar.update()
    r = (
        runs[0]
        if seeds == 1
        else jax.tree_util.tree_map(lambda *xs: np.stack([np.asarray(x) for x in xs]), *runs)
    )
    per_seed = [[float(e) for e in final_errors(x)] for x in runs]
    errors = per_seed[0] if seeds == 1 else median(per_seed)
    body = {
        "final_position_error_m": errors,
        "duration_s": duration,
        "noise_px": noise_px,
        "final_camera_prediction_error_px": float(
            np.median([np.asarray(x.p_tilde_c[-1]).max() for x in runs])
        ),
        "covariance_resets": int(np.median([int(x.resets[-1]) for x in runs])),
    }
    if seeds > 1:
        body["seeds"] = seeds
        body["final_position_error_m_seeds"] = per_seed
    bar.set_postfix_str("figure")
    if write is not None:
        arrays = dict(
            t=np.asarray(runs[0].ts),
            features=np.asarray(r.omega_s),
            truth=np.asarray(runs[0].omega_true),
        )
        title = (
            f"adaptive least-squares structure estimator (Nath et al.): {duration:g} s at 1 kHz, "
            f"pixel noise {noise_px:g} px" + (f", {seeds} seeds" if seeds > 1 else "")
        )
        figure = functools.partial(plot_static_points, r, title=title)
        write(Outputs(arrays={"estimate.npz": arrays}, figures={"euclidean": figure}))
    bar.update()
    bar.close()
    lines = [
        "Adaptive least-squares structure estimator (Nath et al., eqs. 37-51): "
        f"{duration:g} s at 1 kHz, pixel noise {noise_px:g} px, uncalibrated camera"
        + (f"; medians over {seeds} noise seeds" if seeds > 1 else "")
    ]
    lines += [
        f"feature {i + 1}: final position error {e * 1000:8.3f} mm" for i, e in enumerate(errors)
    ]
    lines.append(
        f"camera prediction error {body['final_camera_prediction_error_px']:.3f} px, "
        f"covariance resets {body['covariance_resets']}"
    )
    return Reproduction(body, lines, seed=seed if noise_px > 0 else None)


def reproduce_static_points(
    out=None,
    *,
    quick: bool = False,
    quiet: bool = False,
    formats=("png",),
    duration: float | None = None,
    noise: float = 0.0,
    seed: int = 0,
    seeds: int = 1,
    max_hours: float = 24.0,
) -> list[dict]:
    """The adaptive least-squares structure estimator on its simulation
    (`static_points_reproduction`), registered as the reproduction `static_points` (what
    `visjax static_points` runs): `summary.json` (kind `static_points`), `estimate.npz` and
    `euclidean.<format>` into `out`. `duration`: 30 s, 20 with `quick`. **Returns:** its
    row: the largest final position error against `POSITION_BOUND_MM`."""
    duration = (20.0 if quick else 30.0) if duration is None else duration
    settings = dict(duration=duration, noise=noise, seed=seed, seeds=seeds)
    summary = write_report(
        "static_points",
        settings,
        out,
        formats,
        lambda write: static_points_reproduction(
            duration,
            noise,
            seed=seed,
            seeds=seeds,
            quiet=quiet,
            write=write,
            max_hours=max_hours,
        ),  # fmt: skip
    )
    return static_points_rows(summary)


def static_points_rows(summary: dict) -> list[dict]:
    """The row of `visjax reproduce`'s table from a `euclidean` summary: the largest final
    position error against `POSITION_BOUND_MM`."""
    e = summary["final_position_error_m"]
    return [
        reproduction_row(
            "Nath et al., structure: largest final position error",
            max(e) * 1000,
            POSITION_BOUND_MM,
            "bound",
            "mm",
        )
    ]


RENAMED = {
    "euclidean_experiment": "static_points_experiment",
    "euclidean_reproduction": "static_points_reproduction",
    "EuclideanRun": "StaticPointsRun",
}
"""The names of visjax 0.3 (old -> new): still given, with a `FutureWarning`."""
__getattr__ = renamed("visjax.papers.nath", RENAMED, globals())
