"""The reproduction report: runs each paper's reproduction (a function of its
`visjax.papers` module), writes its files and `summary.json`, and prints its tables; and
`reproduce`, which runs them all. The command line calls these.

Every `summary.json` follows its schema in `visjax.io.SUMMARIES` (checked when it is
written) and records the visjax version, the settings, the seed and the wall time;
estimated trajectories go to NPZ files and tables to Parquet (`visjax.io.TABLES`,
`visjax.io.ARRAYS`); figures are written in every format of `formats` (png, pdf, svg).
"""

import math
import time
from pathlib import Path

import numpy as np

FORMATS = ("png", "pdf", "svg")


class RunFailed(RuntimeError):
    """A command's run did not succeed: its result code is not `successful` (a failed run,
    or a data file with too many frames missing). Raised after every file and the summary
    (which records the result code) are written; its message is one line, e.g.
    `run velocity: the run failed: diverged at sample 123`. The command line
    prints it as `visjax: error: ...`, keeps the files and exits with status 1."""


def _report(kind: str, settings: dict, out, formats, reproduce) -> dict:
    """Run `reproduce(write)` (a papers reproduction), writing its files into `out` as they
    come (nothing without `out`), then its summary; print its lines and the files written;
    raise its failure, if any, after everything is written (`RunFailed`)."""
    from .io import command_summary, write_outputs

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


def geometry_report(
    scenes=100, points=4, noise=0.0, seed=0, out=None, formats=("png",), quiet=False
):
    """Chitrakaran et al., section 3 (`papers.chitrakaran.geometry_reproduction`): random
    planar scenes reconstructed by visjax and by OpenCV, both against ground truth.
    Writes `summary.json` (kind `geometry`), `scenes.parquet` and `geometry.<format>`."""
    from .papers.chitrakaran import geometry_reproduction

    settings = dict(scenes=scenes, points=points, noise=noise, seed=seed)
    return _report(
        "geometry",
        settings,
        out,
        formats,
        lambda write: geometry_reproduction(scenes, points, noise, seed, quiet=quiet, write=write),
    )


def velocity_report(
    duration=10.0, rate=1000.0, noise=0.0, seed=0, K=None, rho=None, out=None, quiet=False,
    formats=("png",), seeds=1, max_hours=24.0,
) -> dict:  # fmt: skip
    """Chitrakaran et al., section 6 (`papers.chitrakaran.velocity_reproduction`): the
    velocity estimator on the paper's simulation. Writes `summary.json` (kind `velocity`),
    `estimate.npz` and `velocity.<format>` (like the paper's Fig. 2)."""
    from .papers.chitrakaran import velocity_reproduction

    settings = dict(duration=duration, rate=rate, noise=noise, seed=seed, seeds=seeds, K=K, rho=rho)
    return _report(
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
        ),
    )


def moving_point_report(
    sets=None, duration=30.0, noise=0.1, seed=0, out=None, quiet=False, formats=("png",), seeds=1,
    max_hours=24.0,
) -> dict:  # fmt: skip
    """Jang's thesis (`papers.jang.structure_reproduction`): the UIO on the simulated
    analogues of the seven experiment sets, beside the thesis' Tables 5-3/5-4. Writes
    `summary.json` (kind `structure`), `sets.parquet`, per set `estimate_<set>.npz`,
    `structure_<set>.<format>` and `camera_velocity_<set>.<format>`."""
    from .papers.jang import structure_reproduction

    settings = dict(sets=sets, duration=duration, noise=noise, seed=seed, seeds=seeds)
    return _report(
        "structure",
        settings,
        out,
        formats,
        lambda write: structure_reproduction(
            sets,
            duration,
            noise,
            seed=seed,
            seeds=seeds,
            quiet=quiet,
            write=write,
            max_hours=max_hours,
        ),
    )


def static_points_report(
    duration=30.0, noise=0.0, seed=0, out=None, quiet=False, formats=("png",), seeds=1,
    max_hours=24.0,
) -> dict:  # fmt: skip
    """Nath et al. (`papers.nath.euclidean_reproduction`): the adaptive least-squares
    structure estimator on its simulation. Writes `summary.json` (kind `euclidean`),
    `estimate.npz` and `euclidean.<format>`."""
    from .papers.nath import euclidean_reproduction

    settings = dict(duration=duration, noise=noise, seed=seed, seeds=seeds)
    return _report(
        "euclidean",
        settings,
        out,
        formats,
        lambda write: euclidean_reproduction(
            duration,
            noise,
            seed=seed,
            seeds=seeds,
            quiet=quiet,
            write=write,
            max_hours=max_hours,
        ),
    )


def testbed_report(
    sets=None, units="cm", duration=30.0, *, seed=0, video=True, studies=True, out=None,
    quiet=False, formats=("png",),
) -> dict:  # fmt: skip
    """Jang's thesis, chapters 4-5, on the testbed twin (`papers.jang.testbed_reproduction`):
    each set end to end beside Tables 5-3/5-4, figures like Figs. 5-5 to 5-8, an MP4 per set
    and, with `studies`, the camera matrix of section 2.3 with Tables 5-1/5-2 redone and the
    sensitivity to $v_{py}$. Writes `summary.json` (kind `testbed`), `tables.parquet/.csv`,
    `testbed_<set>.<format>/.mp4/.npz`, and with `studies` `calibration.json` and
    `sensitivity.parquet/.csv`."""
    from .papers.jang import testbed_reproduction

    settings = dict(
        sets=sets, units=units, duration=duration, seed=seed, video=video, studies=studies
    )
    started = time.time()
    summary = _report(
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
    return summary


def track_report(
    video,
    out,
    *,
    detector="corners",
    max_features=200,
    fb_threshold=0.5,
    fps=None,
    planar=False,
    homography_threshold=3.0,
    quiet=False,
    allow_damaged=False,
) -> dict:
    """Jang's thesis, sections 2.4 and 5.1: a video to pixel tracks by pyramidal KLT with a
    forward-backward check (`visjax.frontend.track_frames`).

    **Arguments:** `video` a file `visjax.frontend.read_video` reads (MP4 or `.npz`);
    `out` the tracks file: `.npz` with exactly the keys `t` (N,) seconds and `pixels`
    (N, n, 2), NaN where a feature is not seen, or `.csv` (`visjax.io.save_tracks_csv`);
    `detector`, `max_features`, `fb_threshold`, `planar`, `homography_threshold` as in
    `track_frames`; `fps` overrides the video's frame rate; `quiet` no progress bar and no
    summary line; `allow_damaged` tracks a video whose decoder reports damage
    (`read_video`).

    **Returns:** the summary: frames, features, features in frame 0, fraction tracked, and
    `lost_tracks`: how many tracks each check ended (`visjax.frontend.LOST_REASONS`; with
    `planar`, `homography` counts the outlier tracks cut).
    Raises `visjax.io.DataFormatError` (nothing written; exit status 2 on the command
    line) for a video that cannot be tracked: not a readable or a damaged video
    (`read_video`), fewer than 2 frames (a still image), no frame rate, no feature found.
    """
    from .frontend import read_video, track_frames
    from .io import DataFormatError, save_tracks_csv

    out = Path(out)
    if out.suffix.lower() not in (".npz", ".csv"):
        raise ValueError(f"{out}: the tracks file must end in .npz or .csv.")
    frames, video_fps = read_video(video, allow_damaged=allow_damaged)
    if frames.shape[0] < 2:
        raise DataFormatError(
            f"{video}: {frames.shape[0]} frame (a still image?); tracking needs at least 2."
        )
    rate = video_fps if fps is None else fps
    if not (rate is not None and math.isfinite(rate) and rate > 0):
        raise DataFormatError(f"{video}: the video does not state its frame rate; give --fps.")
    tracks = track_frames(
        frames, fps=rate, detector=detector, max_features=max_features,
        fb_threshold=fb_threshold, planar=planar, homography_threshold=homography_threshold,
        progress=not quiet,
    )  # fmt: skip
    if tracks.pixels.shape[1] == 0:
        raise DataFormatError(
            f"{video}: the {detector!r} detector found no feature to track (blank frames?)."
        )
    if out.suffix.lower() == ".csv":
        save_tracks_csv(out, tracks.t, tracks.pixels)
    else:
        with out.open("wb") as f:
            np.savez(f, t=tracks.t, pixels=tracks.pixels)
    summary = {
        "frames": int(frames.shape[0]),
        "fps": float(rate),
        "features": int(tracks.pixels.shape[1]),
        "features_frame0": int(np.sum(tracks.born == 0)),
        "fraction_tracked": tracks.fraction_tracked,
        "lost_tracks": tracks.lost_counts(),
    }
    if not quiet:
        lost = ", ".join(f"{k} {v}" for k, v in summary["lost_tracks"].items() if v)
        print(
            f"tracked {summary['frames']} frames at {rate:g} Hz: {summary['features']} features "
            f"({summary['features_frame0']} in frame 0), "
            f"{summary['fraction_tracked']:.1%} of feature-frames since detection tracked; "
            f"tracks ended by: {lost or 'none'}; wrote {out}"
        )
    return summary


QUICK = {
    "geometry_scenes": (100, 20),
    "structure_duration_s": (30.0, 20.0),
    "euclidean_duration_s": (30.0, 20.0),
    "testbed_sets": (None, ["I.1", "II.1"]),
    "testbed_duration_s": (30.0, 10.0),
    "testbed_studies": (True, False),
}
"""What `reproduce --quick` changes: (full, quick) per setting. The velocity simulation
(10 s at 1 kHz) runs in full either way."""


def quick_help() -> str:
    """What `reproduce --quick` shortens (the command line's help)."""

    def show(v):
        return "all" if v is None else ("/".join(v) if isinstance(v, list) else f"{v:g}")

    changes = ", ".join(
        f"{k.replace('_', ' ')} {show(full)} -> {show(quick)}"
        for k, (full, quick) in QUICK.items()
        if not isinstance(full, bool)
    )
    return (
        f"shorter runs: {changes}, and the testbed without its studies (the camera matrix "
        "of section 2.3, the v_py sensitivity); the velocity simulation runs in full. "
        "results/ then differs from the documentation's tables, which are full runs"
    )


def reproduce(out="results", quick: bool = False, quiet: bool = False, formats=("png",)) -> dict:
    """Every paper's main experiment into one folder, then a summary table (`summary.json`,
    kind `reproduce`, and `summary.parquet`: one row per figure, its value as a number,
    its unit, the reference as a number and the reference's kind: published, truth, bound
    or OpenCV; the rows come from each paper's `reproduce_rows`). `quick` shortens the
    runs as `QUICK` says."""
    import pandas as pd

    from .io import command_summary
    from .papers import chitrakaran, jang, nath

    started = time.perf_counter()
    q = {k: v[1] if quick else v[0] for k, v in QUICK.items()}
    settings = dict(out=str(out), quick=quick, formats=list(formats), **q)
    out = Path(out)
    r = {}
    print("== Chitrakaran et al., section 6: the velocity estimator ==")
    r["velocity"] = velocity_report(out=out / "velocity", quiet=quiet, formats=formats)
    print("\n== Chitrakaran et al., section 3: Euclidean reconstruction vs OpenCV ==")
    r["geometry"] = geometry_report(
        scenes=q["geometry_scenes"], out=out / "geometry", quiet=quiet, formats=formats
    )
    print("\n== Jang's thesis: the unknown input observer on the seven sets (simulated) ==")
    r["structure"] = moving_point_report(
        duration=q["structure_duration_s"], out=out / "structure", quiet=quiet, formats=formats
    )
    print("\n== Nath et al.: Euclidean structure from an uncalibrated moving camera ==")
    r["euclidean"] = static_points_report(
        duration=q["euclidean_duration_s"], out=out / "euclidean", quiet=quiet, formats=formats
    )
    print("\n== Jang's thesis, chapters 4-5: the testbed twin (PUMA 560, rendered video, KLT) ==")
    r["testbed"] = testbed_report(
        q["testbed_sets"], "cm", q["testbed_duration_s"], studies=q["testbed_studies"],
        out=out / "testbed", quiet=quiet, formats=formats,
    )  # fmt: skip
    rows = chitrakaran.reproduce_rows(r["velocity"], r["geometry"])
    rows += jang.reproduce_rows(r["structure"], r["testbed"])
    rows += nath.reproduce_rows(r["euclidean"])
    columns = ("what", "value", "unit", "reference", "reference_kind")
    table = [dict(zip(columns, row)) for row in rows]
    print("\n== summary ==")
    for row in table:
        value = "infeasible" if row["value"] is None else f"{row['value']:.4g}"
        bound = "< " if row["reference_kind"] == "bound" else ""
        reference = f"{row['reference_kind']} {bound}{row['reference']:.4g}"
        print(f"{row['what']:<62}{value:>12} {row['unit']:<13}({reference})")
    out.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(table, columns=list(columns)).astype(
        {"value": float, "reference": float}
    ).to_parquet(out / "summary.parquet", index=False)
    command_summary(
        "reproduce", {"quick": quick, "rows": table}, settings=settings, seed=None,
        started=started, out=out,
    )  # fmt: skip
    print(f"wrote {out}/ (velocity/, geometry/, structure/, euclidean/, testbed/, summary.json, "
          "summary.parquet)")  # fmt: skip
    return r
