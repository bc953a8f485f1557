"""Jang's thesis, *structure of a moving point seen by a moving camera*: the published
matrices, gains and RMS tables of its seven experiment sets, their simulated analogues
(chapter 5), the observer of each set and the experiment, and the testbed as a twin
(`testbed`: the PUMA 560 of chapter 4 carrying the camera, the two-link robot carrying the
marker, rendered frames tracked by KLT, encoder velocities; its assumptions in `TESTBED`).
Nothing else in visjax knows these numbers.

A point seen by a camera on a PUMA 560 (I.1-I.4: the point is static; II.1-II.3: it moves
on a two-link robot). The truth is the perspective dynamics (2.11) integrated with an
8th-order solver (`visjax.sim.moving_camera_point`, on the same function the observer
uses); the camera samples the image (pixel noise optional) and its velocities at 30 Hz, as
in the thesis (section 5.1); the observer runs at 1 kHz on the held samples.

What the thesis leaves open, chosen here (each a documented assumption):

- **Units.** The thesis' PUMA dimensions are in centimetres (Table 4-1), and its matrices
  $A = [[0, \\omega_z, -v_{cx}], [-\\omega_z, 0, -v_{cy}], [0, 0, 0]]$ (THESIS_NOTES, restored)
  are only physically consistent if $v_c$ is in cm/s: read in m/s, set I.1's camera would
  cross a metre of table per second and lose the point within a second. So lengths are in
  cm inside the scenario and the observer ($x_3 = 1/Z$ in 1/cm); positions are reported in
  metres, as the thesis' RMS tables are.
- **Camera velocities.** $\\omega_z$, $v_{cx}$, $v_{cy}$ are read off each set's $A$; the other
  three are 0 (the downward-looking camera of section 5.2). Where the thesis says the
  velocity is time-varying (I.3, I.4, II.2, II.3), a sinusoid is added around the value of
  $A$ (amplitudes in `SETS`).
- **The point.** Depth 80 cm (a camera above a work table); the start is placed so that the
  image of the point crosses the image centre mid-run. Moving sets: the two-link robot
  moves it in a plane parallel to the image plane (Assumption 3.1) with
  $v_{px} = 2\\sin(0.5t)$ cm/s, and in II.3 also $v_{py} = 0.05\\cos(0.3t)$ cm/s (the second
  unknown input, the UUB case). It drives $e_3$ through $M_{32} = Y_{32} = 4.6$ (the
  thesis' gains): noise-free, $|e_3|$ stays below about $0.8\\,x_3$ at this amplitude and
  grows in proportion to it, so a larger $v_{py}$ (1.5 cm/s gives errors of metres) makes
  the depth meaningless; the second input is kept small.
- **Camera.** Its frames are held between samples (`ThesisScenario.held_stream`, or the
  30 Hz `camera_stream` run with `dt=1e-3`: the same computation). The true camera is
  the thesis' least-squares $\\hat K_c$; the observer may be given the thesis' toolbox
  $K_c$ (the perturbed nominal of Tables 5-1/5-2) or a refined one.
- **Durations.** 30 s; steady-state RMS over the last 15 s.
"""

import jax
import jax.numpy as jnp
import numpy as np

from ..._results import RESULTS, result_names
from ..._util import renamed
from ...geometry import camera_matrix, camera_matrix_lstsq
from ...io import Outputs
from ...plots import plot_camera_velocity, plot_error_budget, plot_moving_point, plot_testbed
from ...studies import reproduction_row, solution
from .._reproduction import (
    Reproduction,
    SeedClock,
    check_seeds,
    median,
    write_report,
)
from ._problem import (
    WEAK_PARALLAX as WEAK_PARALLAX,
    MovingPointProblem as MovingPointProblem,
    moving_point_observer_for_data as moving_point_observer_for_data,
    moving_point_problem as moving_point_problem,
    weak_parallax as weak_parallax,
)
from ._scene import (
    KC_REFINED as KC_REFINED,
    KC_TOOLBOX as KC_TOOLBOX,
    SETS as SETS,
    MovingPointRun as MovingPointRun,
    ThesisScenario as ThesisScenario,
    ThesisSet as ThesisSet,
    _held as _held,
    _measurements as _measurements,
    _SetMotion as _SetMotion,
    _velocities as _velocities,
    observer as observer,
    scenario as scenario,
)
from ._testbed import (
    _TESTBED_ARRAYS,
    ERROR_SOURCES as ERROR_SOURCES,
    PUMA560_COUNTS_PER_DEGREE as PUMA560_COUNTS_PER_DEGREE,
    TESTBED as TESTBED,
    UNITS as UNITS,
    ErrorSource as ErrorSource,
    TestbedRun as TestbedRun,
    error_budget_lines as error_budget_lines,
    testbed as testbed,
    testbed_error_budget as testbed_error_budget,
    testbed_record as testbed_record,
    testbed_video as testbed_video,
)


def moving_point_experiment(
    set_name: str,
    duration: float = 30.0,
    noise_px: float = 0.0,
    *,
    seed: int = 0,
    Kc_observer=KC_REFINED,
    K=None,
    Y=None,
) -> MovingPointRun:
    """A thesis set as the `moving_point` problem states it (`moving_point_problem`):
    the simulated set with `noise_px` of pixel noise (seed `seed`), the UIO (eq. (3.5))
    at 1 kHz on the held 30 Hz frames, run once (`studies.solution`, the thesis' gains
    unless `K`, `Y` are given), and the steady-state RMS position error (metres) over the
    second half of the run (at the 100 Hz saved samples).

    **Raises:** `RuntimeError` if the run fails (its result code and sample)."""

    problem = moving_point_problem(
        variant=set_name, noise_px=noise_px, duration=duration, Kc_observer=Kc_observer
    )
    gains = {k: v for k, v in (("K", K), ("Y", Y)) if v is not None}
    sol = solution(problem, gains, jax.random.key(seed))
    if not bool(sol.result == RESULTS.successful):
        raise RuntimeError(
            f"the unknown input observer failed on set {set_name}: "
            f"{result_names(sol.result)} at sample {int(sol.failed_sample)}."
        )
    every = int(round(0.01 / float(problem.ts[1] - problem.ts[0])))
    estimate = sol.outputs.position * problem.to_m  # the thesis' cm -> m
    truth = problem.truth[::every] * problem.to_m
    steady = sol.ts >= duration / 2
    err = np.asarray(estimate - truth)[np.asarray(steady)]
    # the thesis' lengths are in cm: the camera's linear velocity to m/s
    to_si = jnp.array([0.01, 0.01, 0.01, 1.0, 1.0, 1.0])
    return MovingPointRun(
        ts=sol.ts,
        position=truth,
        estimate=estimate,
        rms=jnp.sqrt(jnp.mean(err**2, axis=0)),
        frame_ts=problem.frame_ts,
        camera_velocity=problem.frame_velocities * to_si[None, :],
    )


# --------------------------------------------------------------------------------------
# The reproductions that `visjax moving_point`, `visjax testbed` and `visjax reproduce` print
# and write (`visjax.report`).

TABLE_5_1 = {"toolbox": (0.0121, 0.0349, 0.0958), "least_squares": (0.0119, 0.0179, 0.0800)}
"""Table 5-1 (set I.2): the RMS position error (m, x y z) with the toolbox $K_c$ and with
the least-squares $K_c$ of section 2.3."""
TABLE_5_2 = {"toolbox": (0.0172, 0.0248, 0.0548), "least_squares": (0.0172, 0.0170, 0.0519)}
"""Table 5-2 (set II.1), as Table 5-1."""

BUDGET_SETS = ("I.1", "II.1")
"""The sets whose error budget `visjax testbed` reports (`testbed_error_budget`): the
first static and the first moving set (22 runs of the twin: about 8 minutes on 2 cores
for 30 s each)."""

VPY_AMPLITUDES = (0.0, 0.05, 0.2, 0.5, 1.0, 2.0)
"""The sensitivity study's amplitudes of the second unknown input $v_{py}$ (in the unit
reading's length per second), fixed before any run."""


def set_names(sets=None) -> list[str]:
    """The thesis' sets asked for (all by default), checked by name."""
    names = list(SETS) if not sets else list(sets)
    for name in names:
        if name not in SETS:
            raise ValueError(f"unknown set {name!r}; choose from {list(SETS)}")
    return names


def table_lines(per_set: dict, names, who: str) -> list[str]:
    """Tables 5-3 and 5-4 as printed lines: per set and axis, `who`'s RMS (or
    "infeasible") and the thesis' in brackets."""
    lines = []
    for group, label in (("I.", "Table 5-3 (static point)"), ("II.", "Table 5-4 (moving point)")):
        in_group = [n for n in names if n.startswith(group)]
        if not in_group:
            continue
        lines += [
            "",
            f"{label}: {who} (thesis)",
            f"{'':<4}" + "".join(f"{n:>20}" for n in in_group),
        ]
        for i, axis in enumerate("xyz"):
            cells = []
            for n in in_group:
                rms = per_set[n]["rms"]
                value = f"{rms[i]:.4f}" if rms is not None else "infeasible"
                cells.append(f"{value:>11} ({per_set[n]['thesis_rms'][i]:.4f})")
            lines.append(f"{axis:<4}" + "".join(cells))
    return lines


def moving_point_reproduction(
    sets=None,
    duration: float = 30.0,
    noise_px: float = 0.1,
    *,
    seed: int = 0,
    seeds: int = 1,
    quiet=True,
    write=None,
    max_hours: float = 24.0,
) -> Reproduction:
    """The UIO on the simulated analogues of the sets (`moving_point_experiment`), as `visjax
    structure` reports it: per set the RMS position error beside the thesis' Tables
    5-3/5-4, `sets.parquet` (one row per set and axis), per set `estimate_<set>.npz` (`t`,
    `position`, `estimate`) and the figures `structure_<set>` (like Figs. 5-7/5-8) and
    `camera_velocity_<set>` (like Figs. 5-5/5-6), each written as soon as its set is done.
    With `seeds` > 1, the noise seeds `seed, ..., seed + seeds - 1`: each set's `rms` is
    their median (each seed's in `rms_seeds`), `estimate` has a leading seed axis and the
    figures show the median error and its 10-90 % band."""
    import functools

    from tqdm import tqdm

    check_seeds(seeds, noise_px)
    names = set_names(sets)
    per_set = {}
    bar = tqdm(names, desc="moving_point", unit="set", disable=quiet)
    clock = SeedClock(len(names) * seeds, max_hours, "moving_point", bar)
    for name in bar:
        runs = []
        for i in range(seeds):
            runs.append(moving_point_experiment(name, duration, noise_px, seed=seed + i))
            clock.tick()
        r = runs[0]
        rms = [[float(x) for x in run.rms] for run in runs]
        per_set[name] = {"rms": rms[0] if seeds == 1 else median(rms)}
        if seeds > 1:
            per_set[name]["rms_seeds"] = rms
        per_set[name]["thesis_rms"] = list(SETS[name].thesis_rms)
        if write is None:
            continue
        estimate = np.asarray(r.estimate) if seeds == 1 else np.stack([x.estimate for x in runs])
        kind = "moving" if SETS[name].moving else "static"
        arrays = dict(t=np.asarray(r.ts), position=np.asarray(r.position), estimate=estimate)
        title = (
            f"unknown input observer (Jang's thesis), set {name} ({kind} point), simulated: "
            f"pixel noise {noise_px:g} px, camera 30 Hz, observer 1 kHz"
        )
        figures = {
            f"structure_{name}": functools.partial(
                plot_moving_point, r.ts, r.position, estimate, title=title
            ),
            f"camera_velocity_{name}": functools.partial(
                plot_camera_velocity,
                r.frame_ts,
                r.camera_velocity,
                title=f"Jang's thesis, set {name}: camera velocity (simulated analogue)",
            ),
        }
        write(Outputs(arrays={f"estimate_{name}.npz": arrays}, figures=figures))
    body = {"duration_s": duration, "noise_px": noise_px, "sets": per_set}
    if seeds > 1:
        body["seeds"] = seeds
    if write is not None:
        import pandas as pd

        rows = [
            {
                "set": name,
                "axis": axis,
                "rms_m": per_set[name]["rms"][i],
                "thesis_rms_m": per_set[name]["thesis_rms"][i],
            }
            for name in names
            for i, axis in enumerate("xyz")
        ]
        write(Outputs(tables={"sets": pd.DataFrame(rows)}))
    lines = [
        f"Unknown input observer (Jang's thesis, eq. 3.5), simulated analogues: {duration:g} s, "
        f"pixel noise {noise_px:g} px, RMS position error over the second half (m)"
    ] + table_lines(per_set, names, "visjax")
    return Reproduction(body, lines, settings={"sets": names}, seed=seed if noise_px > 0 else None)


def testbed_reproduction(
    sets=None,
    units: str = "cm",
    duration: float = 30.0,
    *,
    seed: int = 0,
    video: bool = True,
    studies: bool = True,
    quiet=True,
    write=None,
) -> Reproduction:
    """Chapters 4-5 on the testbed twin (`testbed`), as `visjax testbed` reports it: each set
    end to end, Tables 5-3/5-4 beside the thesis', per set the figure `testbed_<set>`, its
    arrays `testbed_<set>.npz` and (with `video`) the MP4 `testbed_<set>.mp4`, written as
    soon as the set is done; `tables` (Parquet and CSV, one row per set and axis); with
    `studies`, `testbed_studies`."""
    import functools

    from tqdm import tqdm

    names = set_names(sets)
    if units not in UNITS:
        raise ValueError(f"`units` must be one of {list(UNITS)}; got {units!r}")
    per_set, runs = {}, {}
    for name in tqdm(names, desc="testbed", unit="set", disable=quiet):
        keep = write is not None and video
        r = testbed(name, units=units, duration=duration, keep_frames=keep, seed=seed)
        per_set[name] = testbed_record(r)
        if write is not None:
            kind = "moving" if SETS[name].moving else "static"
            arrays = {k: np.asarray(getattr(r, k)) for k in _TESTBED_ARRAYS}
            if r.q_arm is not None:
                arrays["q_arm"] = np.asarray(r.q_arm)
            title = (
                f"Jang's thesis, set {name} ({kind} point) on the testbed twin: A read in "
                f"{units}/s, camera 30 Hz, observer 1 kHz"
            )
            figures = {f"testbed_{name}": functools.partial(plot_testbed, r, title=title)}
            videos = {}
            if keep and r.frames is not None:
                videos[f"testbed_{name}.mp4"] = functools.partial(testbed_video, r)
            write(
                Outputs(
                    arrays={f"testbed_{name}.npz": arrays},
                    figures=figures if r.feasible else {},
                    videos=videos,
                )
            )
        runs[name] = r.__class__(**{**r.__dict__, "frames": None})
    lines = [
        f"UIO (Jang's thesis, eq. 3.5) on the testbed twin: A read in {units}/s, "
        f"{duration:g} s, RMS position error over the second half (m), at 1 kHz"
    ] + table_lines(per_set, names, "twin")
    lines += [f"{n}: {per_set[n]['reason']}" for n in names if not per_set[n]["feasible"]]
    if studies:
        lines += testbed_studies(runs, names, units, duration, seed, quiet=quiet, write=write)
    if write is not None:
        import pandas as pd

        def cell(e, key, i):
            return e[key][i] if e[key] else None

        rows = [
            {
                "set": name,
                "table": "5-3" if name.startswith("I.") else "5-4",
                "axis": axis,
                "rms_m": cell(per_set[name], "rms", i),
                "rms_frames_m": cell(per_set[name], "rms_frames", i),
                "rms_ideal_pixels_m": cell(per_set[name], "rms_ideal_pixels", i),
                "thesis_rms_m": per_set[name]["thesis_rms"][i],
                "feasible": per_set[name]["feasible"],
            }
            for name in names
            for i, axis in enumerate("xyz")
        ]
        write(Outputs(tables={"tables": pd.DataFrame(rows)}, csv=("tables",)))
    body = {"units": units, "duration_s": duration, "sets": per_set}
    return Reproduction(body, lines, settings={"sets": names}, seed=seed)


def testbed_studies(runs, names, units, duration, seed, *, quiet=True, write=None) -> list[str]:
    """Section 2.3's least squares from set I.1's data with Tables 5-1/5-2 redone
    (`calibration.json`), the sensitivity of the moving sets to the amplitude of $v_{py}$
    (exact pixels, so that only $v_{py}$ varies; `sensitivity`, Parquet and CSV), and the
    error budget of the sets of `BUDGET_SETS` among `names` (`testbed_error_budget`;
    `error_budget`, Parquet and CSV, and its figure). **Returns:** the printed lines."""
    import functools

    from tqdm import tqdm

    lines = []
    base = runs.get("I.1")
    if base is not None and base.feasible:
        cam = base.position[base.frame_index]
        m = cam[:, :2] / cam[:, 2:]
        ok = np.all(np.isfinite(base.pixels), axis=1)
        theta = np.asarray(camera_matrix_lstsq(m[ok], base.pixels[ok]).theta)
        K_ls = np.asarray(camera_matrix(theta))
        tables = {}
        for set_name, table, thesis in (
            ("I.2", "table_5_1", TABLE_5_1),
            ("II.1", "table_5_2", TABLE_5_2),
        ):
            row = {"set": set_name, "thesis": {k: list(v) for k, v in thesis.items()}}
            for label, K in (("toolbox", KC_TOOLBOX), ("least_squares", K_ls)):
                r = testbed(set_name, units=units, duration=duration, Kc_observer=K, seed=seed)
                row[label] = [float(x) for x in r.rms] if r.feasible else None
            tables[table] = row
        calibration = {
            "theta_least_squares": [float(x) for x in theta],
            "Kc_least_squares": K_ls.tolist(),
            "Kc_true": np.asarray(KC_REFINED).tolist(),
            "Kc_toolbox": np.asarray(KC_TOOLBOX).tolist(),
            "Kc_thesis_least_squares": np.asarray(KC_REFINED).tolist(),
            "frames_used": int(ok.sum()),
            **tables,
            "note": "the twin renders with the thesis' least-squares Kc as the true camera; "
            "the observer is given the toolbox Kc or the least squares of section 2.3 from "
            "set I.1's tracked pixels and the forward-kinematics truth",
        }
        true = ", ".join(f"{x:.2f}" for x in camera_matrix_to_theta(KC_REFINED))
        lines += [
            "",
            "section 2.3 least squares from set I.1 (twin): [f, af, cx, cy] = "
            + ", ".join(f"{x:.2f}" for x in theta)
            + f"  (true {true})",
        ]
        for table, row in tables.items():
            for label in ("toolbox", "least_squares"):
                v = row[label]
                cells = ", ".join(f"{x:.4f}" for x in v) if v else "infeasible"
                th = ", ".join(f"{x:.4f}" for x in row["thesis"][label])
                lines.append(f"{table} ({row['set']}), {label} Kc: {cells}   (thesis {th})")
        if write is not None:
            write(Outputs(json={"calibration.json": calibration}))
    moving = [n for n in names if SETS[n].moving]
    rows = []
    for name in tqdm(moving, desc="v_py sensitivity", unit="set", disable=quiet or not moving):
        for a in VPY_AMPLITUDES:
            r = testbed(
                name,
                units=units,
                duration=duration,
                vp_amplitude=(SETS[name].vp_amplitude[0], a),
                track=False,
                seed=seed,
            )
            rms = r.rms if r.feasible else np.full(3, np.nan)
            rows += [
                {
                    "set": name, f"v_py_amplitude_{units}_s": a, "axis": axis,
                    "rms_m": float(rms[i]), "feasible": bool(r.feasible), "result": r.result,
                }
                for i, axis in enumerate("xyz")
            ]  # fmt: skip
    if rows:
        import pandas as pd

        table = pd.DataFrame(rows)
        wide = table.pivot(index=["set", f"v_py_amplitude_{units}_s"], columns="axis")["rms_m"]
        lines += ["", f"sensitivity to v_py (amplitude in {units}/s; exact pixels), RMS (m):"]
        printed = (
            wide.add_prefix("rms_")
            .reset_index()
            .to_string(index=False, float_format=lambda x: f"{x:.4f}")
        )
        lines += printed.splitlines()
        if write is not None:
            write(Outputs(tables={"sensitivity": table}, csv=("sensitivity",)))
    budget_sets = [n for n in names if n in BUDGET_SETS]
    if budget_sets:
        table = testbed_error_budget(
            budget_sets, units=units, duration=duration, seed=seed, quiet=quiet
        )
        lines += error_budget_lines(table)
        if write is not None:
            title = (
                f"Jang's thesis on the testbed twin: the error budget (A read in {units}/s, "
                f"{duration:g} s), beside the thesis' measured RMS"
            )
            figure = functools.partial(plot_error_budget, table, title=title)
            write(
                Outputs(
                    tables={"error_budget": table},
                    csv=("error_budget",),
                    figures={"error_budget": figure},
                )
            )
    return lines


def camera_matrix_to_theta(K) -> list[float]:
    """$[f, \\alpha f, c_x, c_y]$ of a camera matrix, the parameters of section 2.3."""
    K = np.asarray(K, float)
    return [K[0, 0], K[1, 1], K[0, 2], K[1, 2]]


def reproduce_moving_point(
    out=None,
    *,
    quick: bool = False,
    quiet: bool = False,
    formats=("png",),
    sets=None,
    duration: float | None = None,
    noise: float = 0.1,
    seed: int = 0,
    seeds: int = 1,
    max_hours: float = 24.0,
) -> list[dict]:
    """The UIO on the simulated analogues of the seven sets (`moving_point_reproduction`),
    registered as the reproduction `moving_point` (what `visjax moving_point` runs):
    `summary.json` (kind `moving_point`), `sets.parquet`, per set `estimate_<set>.npz`,
    `structure_<set>.<format>` and `camera_velocity_<set>.<format>` into `out`.
    `duration` per set: 30 s, 20 with `quick`. **Returns:** its rows: the mean RMS of the
    static sets (I.x) and of the moving ones (II.x) against the thesis' Tables 5-3/5-4."""
    duration = (20.0 if quick else 30.0) if duration is None else duration
    settings = dict(sets=sets, duration=duration, noise=noise, seed=seed, seeds=seeds)
    summary = write_report(
        "moving_point",
        settings,
        out,
        formats,
        lambda write: moving_point_reproduction(
            sets,
            duration,
            noise,
            seed=seed,
            seeds=seeds,
            quiet=quiet,
            write=write,
            max_hours=max_hours,
        ),  # fmt: skip
    )
    return moving_point_rows(summary)


def moving_point_rows(summary: dict) -> list[dict]:
    """The rows of `visjax reproduce`'s table from a `moving_point` summary: per set, the
    axis furthest from the thesis (the largest ratio either way of its RMS to the thesis'
    Tables 5-3/5-4), its RMS against the thesis'. One row per set, never an average over
    sets: a set that misses the thesis (II.3's x, 2.5 times it) shows as itself."""
    rows = []
    for name, e in summary["sets"].items():
        thesis = np.asarray(e["thesis_rms"], float)
        if e.get("rms") is None:  # a run that did not succeed: no number
            i, rms = int(np.argmax(thesis)), np.full(3, np.nan)
        else:
            rms = np.asarray(e["rms"], float)
            with np.errstate(divide="ignore", invalid="ignore"):
                i = int(np.nanargmax(np.abs(np.log(rms / thesis))))
        rows.append(
            reproduction_row(
                f"Jang's thesis, UIO, set {name}: RMS {'xyz'[i]} (the axis furthest from "
                "the thesis)", None if np.isnan(rms[i]) else float(rms[i]), float(thesis[i]),
                "published", "m",
            )
        )  # fmt: skip
    return rows


def reproduce_testbed(
    out=None,
    *,
    quick: bool = False,
    quiet: bool = False,
    formats=("png",),
    sets=None,
    units: str = "cm",
    duration: float | None = None,
    seed: int = 0,
    video: bool = True,
    studies: bool | None = None,
) -> list[dict]:
    """Chapters 4-5 on the testbed twin (`testbed_reproduction`), registered as the
    reproduction `testbed` (what `visjax testbed` runs): `summary.json` (kind `testbed`),
    `tables.parquet/.csv`, `testbed_<set>.<format>/.mp4/.npz`, and with `studies`
    `calibration.json` and `sensitivity.parquet/.csv` into `out`. With `quick`: sets I.1
    and II.1, 10 s each, no studies (else every set, 30 s, the studies). **Returns:** its
    rows: each set's worst-axis RMS against the thesis'."""
    import time

    if quick:
        sets = ["I.1", "II.1"] if sets is None else sets
    duration = (10.0 if quick else 30.0) if duration is None else duration
    studies = (not quick) if studies is None else studies
    settings = dict(
        sets=sets, units=units, duration=duration, seed=seed, video=video, studies=studies
    )
    started = time.time()
    summary = write_report(
        "testbed",
        settings,
        out,
        formats,
        lambda write: testbed_reproduction(
            sets,
            units,
            duration,
            seed=seed,
            video=video,
            studies=studies,
            quiet=quiet,
            write=write,
        ),  # fmt: skip
    )
    if not quiet:
        print(f"({time.time() - started:.0f} s)")
    return testbed_rows(summary)


def testbed_rows(summary: dict) -> list[dict]:
    """The rows of `visjax reproduce`'s table from a `testbed` summary: each set's
    worst-axis RMS against the thesis'."""
    rows = []
    for name, e in summary["sets"].items():
        rms = e["rms"]
        rows.append(
            reproduction_row(
                f"Jang's thesis, testbed twin set {name}: worst-axis RMS"
                + ("" if rms is not None else " (infeasible)"),
                max(rms) if rms is not None else None,
                float(max(e["thesis_rms"])),
                "published",
                "m",
            )
        )
    return rows


RENAMED = {
    "structure_experiment": "moving_point_experiment",
    "structure_reproduction": "moving_point_reproduction",
    "StructureRun": "MovingPointRun",
}
"""The names of visjax 0.3 (old -> new): still given, with a `FutureWarning`."""
__getattr__ = renamed("visjax.papers.jang", RENAMED, globals())
