"""Chitrakaran, Dawson, Dixon, Chen, *Identification of a moving object's velocity with a
fixed camera*: its constants, published gains, the section-6 scenario, the section-3
comparison, the experiment and its metrics. Nothing else in visjax knows these numbers.

The simulation of section 6: a planar object moving in front of a fixed camera.

Exactly as the paper states it: velocity $v_i = 0.2 \\sin t$ on all six degrees of freedom,
expressed in the camera frame (eq. (59)); $s_1 = [-0.1, 0.1, 0.01]$; $x_f^* = [0, 0, 2]$
(eq. (60)); $R^* = \\mathrm{diag}(1, -1, -1)$ (eq. (61)); $A$ of eq. (62); 1 kHz. The object
starts at the reference pose.

What the paper leaves open, chosen here:

- The other three features: $s_2 = [0.1, 0.1, 0]$, $s_3 = -s_1 = [0.1, -0.1, -0.01]$,
  $s_4 = -s_2$. The four are the corners of a 0.2 m square, coplanar with the object-frame
  origin at the intersection of its diagonals; the plane is tilted so that $s_1$ has
  $z = 0.01$ (object-frame normal $\\propto [0.05, -0.05, 1]$). The origin's image is then the
  intersection of the image diagonals, which makes $z_1^*$ recoverable from $s_1$ (see
  `visjax.estimators.depth_from_known_length`).
- The pose is integrated with an 8th-order solver at tolerance 1e-12; for eq. (59) it also
  has the closed form $x_f = x_f^* + 0.2(1 - \\cos t)\\mathbf 1$,
  $R = \\exp(0.2(1 - \\cos t)[1, 1, 1]^\\wedge) R^*$ (a test compares the two).
- Pixel noise, if asked for, is i.i.d. Gaussian on every coordinate of every frame,
  including the reference frame 0.
"""

import functools

import jax
import numpy as np

from ..._results import RESULTS, result_names
from ...baselines import opencv_reconstruction
from ...geometry import euclidean_reconstruction
from ...io import Outputs
from ...plots import plot_geometry, plot_velocity
from ...sim import random_planar_scenes
from ...studies import reproduction_row, solution, sweep
from .._reproduction import (
    Reproduction,
    SeedClock,
    check_seeds,
    median,
    stages,
    write_report,
)
from ._problem import (
    AXES as AXES,
    ROBUST_GATE as ROBUST_GATE,
    ROBUST_SCALE_PX as ROBUST_SCALE_PX,
    VelocityProblem as VelocityProblem,
    velocity_observer_bandwidth_hz as velocity_observer_bandwidth_hz,
    velocity_problem as velocity_problem,
)
from ._scene import (
    A_EQ62 as A_EQ62,
    DOF_NAMES as DOF_NAMES,
    FEATURES as FEATURES,
    K_EQ63 as K_EQ63,
    R_STAR_EQ61 as R_STAR_EQ61,
    RHO_EQ63 as RHO_EQ63,
    X_F_STAR_EQ60 as X_F_STAR_EQ60,
    Section6Scenario as Section6Scenario,
    VelocityRun as VelocityRun,
    eq56_matrix as eq56_matrix,
    section6_scenario as section6_scenario,
    section6_velocity as section6_velocity,
    window as window,
)


def velocity_experiment(
    duration: float = 10.0,
    rate_hz: float = 1000.0,
    noise_px: float = 0.0,
    *,
    K=K_EQ63,
    rho=RHO_EQ63,
    seed: int = 0,
    progress=None,
) -> VelocityRun:
    """Section 6 as the `velocity` problem states it (`velocity_problem` with
    `constants="per_draw"`): the simulation with `noise_px` of pixel noise (seed `seed`),
    $n^*$ and $z_1^*$ measured from the noisy frames ($z_1^*$ from one known length
    between two features, the paper's premise, section 5: features 1 and 3, the
    square's diagonal), and the estimator (eqs. 39-40) run once (`studies.solution`).

    `progress`, if given, is called with the name of each stage as it starts.

    **Raises:** `RuntimeError` if the run fails (its result code and sample).
    """

    progress = progress or (lambda stage: None)
    progress("simulate section 6")
    problem = velocity_problem(
        noise_px=noise_px, duration=duration, rate_hz=rate_hz, constants="per_draw"
    )
    progress("estimate")
    key = jax.random.key(seed)
    sol = solution(problem, {"K": K, "rho": rho}, key)
    if not bool(sol.result == RESULTS.successful):
        raise RuntimeError(
            f"the velocity estimator failed: {result_names(sol.result)} at sample "
            f"{int(sol.failed_sample)}."
        )
    camera = problem.camera(problem.inputs(key))
    return VelocityRun(
        ts=problem.ts,
        velocity=problem.truth,
        estimate=sol.outputs.v_hat,
        n_star=camera.n_star,
        z1_star=camera.z1_star,
    )


def summarise(r: VelocityRun, duration: float, rate_hz: float, noise_px: float) -> dict:
    """The results of `visjax velocity` (its `summary.json`, kind `velocity`): RMS and max
    error per DOF over the scoring window `window(duration)` (5-10 s for the paper's 10 s)."""
    a, b = window(duration)
    t = np.asarray(r.ts)
    inside = (t >= a) & (t < b)
    err = np.asarray(r.estimate)[inside] - np.asarray(r.velocity)[inside]
    return {
        "rms_window": [float(x) for x in np.sqrt(np.mean(err**2, axis=0))],
        "max_window": [float(x) for x in np.max(np.abs(err), axis=0)],
        "order": list(DOF_NAMES),
        "window_s": [a, b],
        "rate_hz": rate_hz,
        "noise_px": noise_px,
        "duration_s": duration,
        "z1_star_recovered": float(r.z1_star),
        "n_star_recovered": [float(x) for x in r.n_star],
    }


def noise_study(
    noise_levels=(0.0, 0.1, 0.5, 1.0),
    seeds: int = 8,
    duration: float = 10.0,
    rate_hz: float = 1000.0,
    *,
    K=K_EQ63,
    rho=RHO_EQ63,
) -> dict:
    """RMS velocity error over the window per noise level: one `studies.sweep` of the
    `velocity` problem over its `noise_px` parameter (one compiled program for every level
    and seed), seeds `0 ... seeds - 1` (the same draws at every level, scaled).

    The plane normal and $z_1^*$ are measured once from the noise-free scenario (they are
    constants of the set-up); the pixel noise enters every frame of the estimator's input.

    **Returns:** `{noise: array (seeds, 6)}` of RMS errors (NaN for a failed run).
    """

    problem = velocity_problem(duration=duration, rate_hz=rate_hz)
    levels = np.asarray(noise_levels, float)
    table = sweep(problem, {"noise_px": levels}, np.arange(seeds), fixed={"K": K, "rho": rho})
    columns = [f"rms_{a}" for a in AXES]
    return {
        float(s): table.loc[table["point"] == i, columns].to_numpy() for i, s in enumerate(levels)
    }


# Section 3 against OpenCV: the errors of a reconstruction against ground truth.


def rotation_error_deg(R_est, R_true):
    """Angle of $R_{est}^T R_{true}$ in degrees, by atan2 (arccos loses half the digits
    near 0). NumPy, batched."""
    E = np.swapaxes(R_est, -1, -2) @ R_true
    s = np.stack(
        [E[..., 2, 1] - E[..., 1, 2], E[..., 0, 2] - E[..., 2, 0], E[..., 1, 0] - E[..., 0, 1]], -1
    )
    c = np.trace(E, axis1=-2, axis2=-1) - 1.0
    return np.rad2deg(np.arctan2(np.linalg.norm(s, axis=-1), c))


def normal_error_deg(n_est, n_true):
    """The angle between two normals in degrees, by atan2. NumPy, batched."""
    s = np.linalg.norm(np.cross(n_est, n_true), axis=-1)
    return np.rad2deg(np.arctan2(s, np.sum(n_est * n_true, -1)))


def reconstruction_errors(est: dict, scenes) -> dict:
    """Per-scene errors of a section-3 reconstruction (`R_bar`, `x_h`, `n_star`, `alpha`,
    `H`) against the ground truth of `visjax.sim.random_planar_scenes`."""
    return {
        "H_max_abs": np.max(np.abs(est["H"] - scenes.H), axis=(-2, -1)),
        "R_bar_deg": rotation_error_deg(est["R_bar"], scenes.R_bar),
        "x_h_abs": np.linalg.norm(est["x_h"] - scenes.x_h, axis=-1),
        "n_star_deg": normal_error_deg(est["n_star"], scenes.n_star),
        "alpha_rel": np.max(np.abs(est["alpha"] / scenes.alpha - 1.0), axis=-1),
    }


def geometry_study(scenes: int = 100, points: int = 4, noise: float = 0.0, seed: int = 0):
    """Section 3 on random planar scenes (`visjax.sim.random_planar_scenes`): the Euclidean
    reconstruction from the homography (eqs. (17)-(20)) by visjax (`jax.vmap`, timed after
    its compilation) and by OpenCV (a loop, `baselines.opencv_reconstruction`), both
    against the ground truth. A rough prior of the plane normal (about 1 degree off) picks
    between the two physical decompositions; both pipelines get the same one.

    **Returns:** `(scenes, ours, errors, seconds)`: the scenes; visjax's `R_bar`, `x_h`,
    `n_star`, `alpha`, `H` per scene; `{"visjax": ..., "opencv": ...}` per-scene errors
    (`reconstruction_errors`); `{"visjax_compile", "visjax", "opencv"}` in seconds."""
    import time

    sc = random_planar_scenes(scenes, points, seed=seed, noise_px=noise)
    rng = np.random.default_rng(seed + 1)
    prior = sc.n_star + 0.02 * rng.normal(size=sc.n_star.shape)
    recon = jax.jit(jax.vmap(euclidean_reconstruction))
    t0 = time.perf_counter()
    jax.block_until_ready(recon(sc.p_ref, sc.p_cur, sc.A, prior))
    t_compile = time.perf_counter() - t0
    t0 = time.perf_counter()
    rec = jax.block_until_ready(recon(sc.p_ref, sc.p_cur, sc.A, prior))
    t_visjax = time.perf_counter() - t0
    ours = {k: np.asarray(getattr(rec, k)) for k in ("R_bar", "x_h", "n_star", "alpha", "H")}
    t0 = time.perf_counter()
    cv = [
        opencv_reconstruction(sc.p_ref[i], sc.p_cur[i], sc.A[i], prior[i]) for i in range(len(sc))
    ]
    t_cv = time.perf_counter() - t0
    theirs = {k: np.stack([c[k] for c in cv]) for k in cv[0]}
    errors = {
        "visjax": reconstruction_errors(ours, sc),
        "opencv": reconstruction_errors(theirs, sc),
    }
    seconds = {"visjax_compile": t_compile, "visjax": t_visjax, "opencv": t_cv}
    return sc, ours, errors, seconds


# The reproductions that `visjax geometry`, `visjax velocity` and `visjax reproduce` print
# and write (`visjax.report`).


def geometry_reproduction(
    scenes: int = 100, points: int = 4, noise: float = 0.0, seed: int = 0, *, quiet=True, write=None
) -> Reproduction:
    """Section 3 (`geometry_study`) as `visjax geometry` reports it: the median and largest
    error of each quantity for visjax and OpenCV, the timings, `scenes.parquet` (one row
    per scene and method) and the figure `geometry`."""

    bar = stages(2, "geometry", quiet)
    bar.set_postfix_str("visjax (batched) and OpenCV (per scene)")
    sc, ours, errors, seconds = geometry_study(scenes, points, noise, seed)
    bar.update()
    body = {
        "scenes": scenes,
        "points": points,
        "noise_px": noise,
        "seconds": seconds,
        "errors": {
            who: {
                k: {"median": float(np.median(v)), "max": float(np.max(v))} for k, v in errs.items()
            }
            for who, errs in errors.items()
        },
    }
    if write is not None:
        import pandas as pd

        bar.set_postfix_str("figure")
        table = pd.concat(
            [
                pd.DataFrame({"scene": np.arange(scenes), "method": who, **errs})
                for who, errs in errors.items()
            ],
            ignore_index=True,
        )
        figure = functools.partial(plot_geometry, sc, ours, errors)
        write(Outputs(tables={"scenes": table}, figures={"geometry": figure}))
    bar.update()
    bar.close()
    lines = [
        "Euclidean reconstruction from a homography (Chitrakaran et al., section 3): "
        f"{scenes} random planar scenes, {points} points, pixel noise {noise} px",
        f"{'error vs ground truth':<22}{'visjax median':>15}{'visjax max':>13}"
        f"{'OpenCV median':>15}{'OpenCV max':>13}",
    ]
    for k, v in body["errors"]["visjax"].items():
        c = body["errors"]["opencv"][k]
        lines.append(
            f"{k:<22}{v['median']:>15.3e}{v['max']:>13.3e}{c['median']:>15.3e}{c['max']:>13.3e}"
        )
    lines.append(
        f"time: visjax {seconds['visjax'] * 1e3:.2f} ms batched "
        f"(+{seconds['visjax_compile']:.1f} s compile), "
        f"OpenCV {seconds['opencv'] * 1e3:.2f} ms loop"
    )
    return Reproduction(body, lines, seed=seed)


def velocity_reproduction(
    duration: float = 10.0,
    rate_hz: float = 1000.0,
    noise_px: float = 0.0,
    *,
    seed: int = 0,
    seeds: int = 1,
    K=None,
    rho=None,
    quiet=True,
    write=None,
    max_hours: float = 24.0,
) -> Reproduction:
    """Section 6 (`velocity_experiment`, `summarise`) as `visjax velocity` reports it: RMS
    and max error per DOF over the scoring window, `estimate.npz` (`t`, `v_hat`,
    `velocity`) and the figure `velocity` (like the paper's Fig. 2). With `seeds` > 1 (and
    noise), the noise seeds `seed, ..., seed + seeds - 1`: the errors are their medians
    (each seed's in `rms_window_seeds`), `v_hat` has a leading seed axis and the figure
    shows the median error and its 10-90 % band. `K`, `rho` default to eq. (63)."""

    check_seeds(seeds, noise_px)
    K = list(K_EQ63) if K is None else list(K)
    rho = list(RHO_EQ63) if rho is None else list(rho)
    bar = stages(2 + seeds, "velocity", quiet)
    started = []

    def progress(stage):
        if started:
            bar.update()
        started.append(stage)
        bar.set_postfix_str(stage)

    runs = []
    clock = SeedClock(seeds, max_hours, "velocity", bar)  # `StudyTooLong` after seed 2
    for i in range(seeds):
        if i:
            clock.tick()
            progress(f"seed {seed + i}")
        runs.append(
            velocity_experiment(
                duration,
                rate_hz,
                noise_px,
                K=K,
                rho=rho,
                seed=seed + i,
                progress=None if i else progress,
            )
        )
    per_seed = [summarise(r, duration, rate_hz, noise_px) for r in runs]
    body = dict(per_seed[0])
    if seeds > 1:
        body["seeds"] = seeds
        for key in ("rms_window", "max_window"):
            body[key] = median([p[key] for p in per_seed])
        body["rms_window_seeds"] = [p["rms_window"] for p in per_seed]
        body["z1_star_recovered_seeds"] = [p["z1_star_recovered"] for p in per_seed]
        body["z1_star_recovered"] = float(np.median(body["z1_star_recovered_seeds"]))
        n_mean = np.mean([p["n_star_recovered"] for p in per_seed], axis=0)
        body["n_star_recovered"] = [float(x) for x in n_mean / np.linalg.norm(n_mean)]
    body["K"], body["rho"] = [float(k) for k in K], [float(x) for x in rho]
    r = runs[0]
    estimate = np.asarray(r.estimate) if seeds == 1 else np.stack([x.estimate for x in runs])
    progress("figure")
    if write is not None:
        title = (
            f"velocity estimator (Chitrakaran et al.), section 6: {rate_hz:g} Hz, "
            f"{duration:g} s, pixel noise {noise_px:g} px"
            + (f", {seeds} seeds" if seeds > 1 else "")
        )
        arrays = dict(t=np.asarray(r.ts), v_hat=estimate, velocity=np.asarray(r.velocity))
        figure = functools.partial(plot_velocity, r.ts, r.velocity, estimate, title=title)
        write(Outputs(arrays={"estimate.npz": arrays}, figures={"velocity": figure}))
    bar.update()
    bar.close()
    a, b = body["window_s"]
    lines = [
        "Velocity estimator (Chitrakaran et al., eqs. 39-40), section-6 simulation: "
        f"{duration:g} s at {rate_hz:g} Hz, pixel noise {noise_px:g} px"
    ]
    if seeds > 1:
        lines.append(f"medians over {seeds} noise seeds ({seed} to {seed + seeds - 1})")
    lines.append(f"recovered z1* = {body['z1_star_recovered']:.6f} m")
    lines.append(f"{'DOF':<6}{f'RMS {a:g}-{b:g} s':>16}{f'max {a:g}-{b:g} s':>16}")
    for name, rms, mx in zip(DOF_NAMES, body["rms_window"], body["max_window"]):
        unit = "m/s" if name.startswith("v") else "rad/s"
        lines.append(f"{name:<6}{rms:>16.5f}{mx:>16.5f}  {unit}")
    return Reproduction(
        body, lines, settings={"K": K, "rho": rho}, seed=seed if noise_px > 0 else None
    )


VELOCITY_BOUND = 0.05
"""The reproduction table's bound on the largest RMS velocity error over the scoring window
(m/s or rad/s): the paper's Fig. 2 shows errors well inside it once the estimate converges."""


def reproduce_velocity(
    out=None,
    *,
    quick: bool = False,
    quiet: bool = False,
    formats=("png",),
    duration: float = 10.0,
    rate: float = 1000.0,
    noise: float = 0.0,
    seed: int = 0,
    seeds: int = 1,
    K=None,
    rho=None,
    max_hours: float = 24.0,
) -> list[dict]:
    """Section 6 (`velocity_reproduction`), registered as the reproduction `velocity`
    (what `visjax velocity` runs): `summary.json` (kind `velocity`), `estimate.npz` and
    `velocity.<format>` (like the paper's Fig. 2) into `out`. `--quick` runs it in full.
    **Returns:** its rows of `visjax reproduce`'s table: the largest RMS error over the
    window against `VELOCITY_BOUND`, and the recovered $z_1^*$ against the truth."""
    settings = dict(duration=duration, rate=rate, noise=noise, seed=seed, seeds=seeds, K=K, rho=rho)
    summary = write_report(
        "velocity",
        settings,
        out,
        formats,
        lambda write: velocity_reproduction(
            duration,
            rate,
            noise,
            seed=seed,
            seeds=seeds,
            K=K,
            rho=rho,
            quiet=quiet,
            write=write,
            max_hours=max_hours,
        ),  # fmt: skip
    )
    return velocity_rows(summary)


def velocity_rows(summary: dict) -> list[dict]:
    """The rows of `visjax reproduce`'s table from a `velocity` summary: the largest RMS
    error over the window against `VELOCITY_BOUND`, the recovered $z_1^*$ against the truth."""
    a, b = summary["window_s"]
    z1 = float((np.asarray(R_STAR_EQ61) @ FEATURES[0] + X_F_STAR_EQ60)[2])
    return [
        reproduction_row(
            f"Chitrakaran et al., velocity: largest RMS error {a:g}-{b:g} s",
            max(summary["rms_window"]),
            VELOCITY_BOUND,
            "bound",
            "m/s or rad/s",
        ),
        reproduction_row(
            "Chitrakaran et al., z1* recovered", summary["z1_star_recovered"], z1, "truth", "m"
        ),
    ]


def reproduce_geometry(
    out=None,
    *,
    quick: bool = False,
    quiet: bool = False,
    formats=("png",),
    scenes: int | None = None,
    points: int = 4,
    noise: float = 0.0,
    seed: int = 0,
) -> list[dict]:
    """Section 3 (`geometry_reproduction`), registered as the reproduction `geometry`
    (what `visjax geometry` runs): random planar scenes reconstructed by visjax and by
    OpenCV, both against the truth; `summary.json` (kind `geometry`), `scenes.parquet` and
    `geometry.<format>` into `out`. `scenes`: 100, 20 with `quick`. **Returns:** its row:
    visjax's largest $\bar R$ error against OpenCV's."""
    scenes = (20 if quick else 100) if scenes is None else scenes
    settings = dict(scenes=scenes, points=points, noise=noise, seed=seed)
    summary = write_report(
        "geometry",
        settings,
        out,
        formats,
        lambda write: geometry_reproduction(scenes, points, noise, seed, quiet=quiet, write=write),
    )
    return geometry_rows(summary)


def geometry_rows(summary: dict) -> list[dict]:
    """The row of `visjax reproduce`'s table from a `geometry` summary: visjax's largest
    $\\bar R$ error against OpenCV's."""
    g = summary["errors"]
    return [
        reproduction_row(
            "Chitrakaran et al., reconstruction: largest R_bar error",
            g["visjax"]["R_bar_deg"]["max"],
            g["opencv"]["R_bar_deg"]["max"],
            "OpenCV",
            "deg",
        )
    ]
