"""The reproduction report: `reproduce` runs every registered reproduction
(`visjax.studies.reproduction_names`: the papers' and a user's) into one folder, then writes
the summary table; `track_report`, `visjax track`. The command line calls these.

Every `summary.json` follows its schema in `visjax.io.SUMMARIES` (checked when it is
written) and records the visjax version, the settings, the seed and the wall time;
estimated trajectories go to NPZ files and tables to Parquet (`visjax.io.TABLES`,
`visjax.io.ARRAYS`); figures are written in every format of `formats` (png, pdf, svg).
"""

import math
import time
from pathlib import Path

import numpy as np

from . import recording
from .frontend import import_bag, read_video, track_frames, track_tags
from .io import DataFormatError, command_summary, data_from_tracks, save_tracks_csv
from .studies import (
    ROW_KEYS,
    RunFailed as RunFailed,  # raised by a command's failed run
    registered_reproduction,
    reproduction_names,
)

FORMATS = ("png", "pdf", "svg")


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
    tags=None,
) -> dict:
    """Jang's thesis, sections 2.4 and 5.1: a video to pixel tracks by pyramidal KLT with a
    forward-backward check (`visjax.frontend.track_frames`); with `tags` (an AprilTag
    family), the corners of the tags of that family found in every frame instead
    (`visjax.frontend.track_tags`: feature 4 i + c is corner c of tag i).

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
    if tags is not None:
        tracks = track_tags(frames, tags, fps=rate, progress=not quiet)
    else:
        tracks = track_frames(
            frames, fps=rate, detector=detector, max_features=max_features,
            fb_threshold=fb_threshold, planar=planar, homography_threshold=homography_threshold,
            progress=not quiet,
        )  # fmt: skip
    if tracks.pixels.shape[1] == 0:
        raise DataFormatError(
            f"{video}: no {tags} AprilTag in any frame."
            if tags is not None
            else f"{video}: the {detector!r} detector found no feature to track (blank frames?)."
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
    if tags is not None:
        seen = tracks.alive.reshape(tracks.pixels.shape[0], -1, 4).all(axis=-1)  # (N, tags)
        summary["tags"] = {
            int(i): round(float(seen[:, i].mean()), 4) for i in np.flatnonzero(seen.any(axis=0))
        }  # id -> the fraction of frames it was found in
    if not quiet:
        lost = ", ".join(f"{k} {v}" for k, v in summary["lost_tracks"].items() if v)
        if tags is not None:
            found = ", ".join(f"{i} ({f:.0%} of frames)" for i, f in summary["tags"].items())
            print(f"{tags} tags found: {found}; tag i's corners are features 4 i to 4 i + 3")
        print(
            f"tracked {summary['frames']} frames at {rate:g} Hz: {summary['features']} features "
            f"({summary['features_frame0']} in frame 0), "
            f"{summary['fraction_tracked']:.1%} of feature-frames since detection tracked; "
            f"tracks ended by: {lost or 'none'}; wrote {out}"
        )
    return summary


def data_report(problem, tracks, camera, out, *, quiet=False) -> dict:
    """Pixel tracks (`visjax track`'s file) and the camera's constants (a YAML or JSON
    file, `visjax.io.data_from_tracks`) to `problem`'s data file `out` (`.npz`), checked
    as every data file is; prints what it chose. **Returns:** `{"problem", "frames",
    "features", "dropped_fraction"}`. Raises `visjax.io.DataFormatError` naming what is
    missing or wrong (nothing written)."""
    out = Path(out)
    if out.suffix.lower() != ".npz":
        raise ValueError(f"{out}: the data file must end in .npz.")
    data = data_from_tracks(problem, tracks, camera)
    data.save(out)
    n = 1 if data.pixels.ndim == 2 else data.pixels.shape[1]
    summary = {
        "problem": problem, "frames": int(data.t.shape[0]), "features": int(n),
        "dropped_fraction": float(data.dropped_fraction()),
    }  # fmt: skip
    if not quiet:
        print(
            f"{problem} data: {summary['frames']} frames, {n} feature(s), "
            f"{summary['dropped_fraction']:.1%} of frames missing one; wrote {out}; "
            f"next: visjax run {problem} --data {out}"
        )
    return summary


def import_bag_report(
    bag, problem, image_topic, camera_info, out, *, twist=None, odometry=None,
    joint_states=None, robot=None, tags=None, camera=None, camera_from_body=None, quiet=False,
) -> dict:  # fmt: skip
    """A ROS bag to `problem`'s data file `out` (`.npz`): `visjax.frontend.import_bag`,
    then saved (checked as every data file is); prints what it read. **Returns:**
    `{"problem", "frames", "features", "dropped_fraction", "distortion"}`. Raises
    `visjax.io.DataFormatError` naming what is missing or wrong (nothing written)."""
    out = Path(out)
    if out.suffix.lower() != ".npz":
        raise ValueError(f"{out}: the data file must end in .npz.")
    data = import_bag(
        bag, problem, image_topic=image_topic, camera_info=camera_info, twist=twist,
        odometry=odometry, joint_states=joint_states, robot=robot, tags=tags, camera=camera,
        camera_from_body=camera_from_body, progress=not quiet,
    )  # fmt: skip
    data.save(out)
    n = 1 if data.pixels.ndim == 2 else data.pixels.shape[1]
    summary = {
        "problem": problem, "frames": int(data.t.shape[0]), "features": int(n),
        "dropped_fraction": float(data.dropped_fraction()),
        "distortion": None if data.dist is None else [float(x) for x in data.dist],
    }  # fmt: skip
    if not quiet:
        lens = "no distortion" if data.dist is None else f"{len(data.dist)} distortion terms"
        print(
            f"{problem} data from {bag}: {summary['frames']} frames, {n} feature(s), {lens}, "
            f"{summary['dropped_fraction']:.1%} of frames missing one; wrote {out}; "
            f"next: visjax run {problem} --data {out}"
        )
    return summary


def quick_help() -> str:
    """What `reproduce --quick` shortens (the command line's help), from each registered
    reproduction's own `quick`."""
    parts = [
        f"{name}: {registered_reproduction(name).quick}"
        for name in reproduction_names()
        if registered_reproduction(name).quick
    ]
    return "shorter runs (" + "; ".join(parts) + ")"


def reproduce(
    out="results", quick: bool = False, quiet: bool = False, formats=("png",), only=None,
    rerun=None,
) -> list[dict]:  # fmt: skip
    """Every registered reproduction (`visjax.studies.reproduction_names`, in order; `only`:
    those named) into its folder of `out`, then the summary table: `summary.json` (kind
    `reproduce`) and `summary.parquet`, one row per number (`visjax.studies.ROW_KEYS`: its
    `name`, `value`, `reference`, the reference's kind and the `unit`). `quick` runs each
    with its shorter settings (`RegisteredReproduction.quick`). `rerun`: also a Rerun
    recording (`visjax.recording.log_reproduction`) at that path. **Returns:** the rows."""
    import pandas as pd

    started = time.perf_counter()
    names = reproduction_names() if only is None else list(only)
    entries = [registered_reproduction(n) for n in names]
    settings = dict(out=str(out), quick=quick, formats=list(formats), reproductions=names)
    out = Path(out)
    table, rec = [], None if rerun is None else recording.open_recording(rerun)
    for i, entry in enumerate(entries):
        print(("\n" if i else "") + f"== {entry.title} ==")
        table += entry.rows(out / entry.folder, quick=quick, quiet=quiet, formats=formats)
        if rec is not None:
            recording.log_reproduction(rec, out / entry.folder, entry.name)
    if rec is not None:
        rec.disconnect()  # the recording's file finished
    print("\n== summary ==")
    for row in table:
        value = "infeasible" if row["value"] is None else f"{row['value']:.4g}"
        bound = "< " if row["reference_kind"] == "bound" else ""
        reference = f"{row['reference_kind']} {bound}{row['reference']:.4g}"
        print(f"{row['name']:<72}{value:>12} {row['unit']:<13}({reference})")
    out.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(table, columns=list(ROW_KEYS)).astype(
        {"value": float, "reference": float}
    ).to_parquet(out / "summary.parquet", index=False)
    command_summary(
        "reproduce", {"quick": quick, "rows": table}, settings=settings, seed=None,
        started=started, out=out,
    )  # fmt: skip
    folders = ", ".join(f"{e.folder}/" for e in entries)
    print(f"wrote {out}/ ({folders}, summary.json, summary.parquet)")
    return table
