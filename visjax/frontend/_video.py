"""Grey video files in and out: MP4 through OpenCV, or a lossless NPZ (never jit)."""

import contextlib
import os
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

from ..io import MAX_INTERVAL_S, MIN_INTERVAL_S, DataFormatError, max_data_bytes, read_npz

# a line of FFmpeg's log: `[mpeg4 @ 0x55d1c0a3e780] ac-tex damaged at 3 0`
_DECODER_LINE = re.compile(r"^\[[^\]]+ @ 0x[0-9a-fA-F]+\] ")


def check_frames(frames, name: str = "frames") -> np.ndarray:
    """`frames` as an (N, H, W) uint8 array with N >= 1, or a `ValueError` naming it."""
    arr = np.asarray(frames)
    if arr.ndim != 3 or arr.dtype != np.uint8 or min(arr.shape) < 1:
        raise ValueError(
            f"`{name}` must be (N, H, W) uint8 grey frames with N >= 1; "
            f"got shape {arr.shape} dtype {arr.dtype}."
        )
    return arr


def _check_fps(fps) -> float:
    try:
        value = float(fps)
    except (TypeError, ValueError):
        raise ValueError(f"`fps` must be a positive number; got {fps!r}.") from None
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"`fps` must be a positive number; got {fps!r}.")
    low, high = 1.0 / MAX_INTERVAL_S, 1.0 / MIN_INTERVAL_S
    if not low <= value <= high:
        raise ValueError(
            f"`fps` is {value:g}, outside the plausible {low:g} to {high:g} frames per "
            "second (visjax.io.MAX_INTERVAL_S, MIN_INTERVAL_S): frames per second?"
        )
    return value


def write_video(path, frames, fps) -> Path:
    """Write grey (or BGR colour) frames as a video.

    **Arguments:** `path` ending in `.npz` (lossless: keys `frames` and `fps`) or anything
    else (MP4, the `mp4v` fourcc, lossy); `frames` (N, H, W) uint8 grey, or (N, H, W, 3)
    uint8 BGR colour; `fps` frames per second.

    **Returns:** the path written. Raises `ValueError` on bad frames or fps, and
    `OSError` when OpenCV cannot open the file for writing (a missing folder, no encoder).
    """
    colour = np.ndim(frames) == 4 and np.shape(frames)[-1] == 3
    if colour:  # BGR frames (N, H, W, 3), e.g. grey frames with overlays drawn in colour
        frames = np.asarray(frames)
        check_frames(frames[..., 0])
    else:
        frames = check_frames(frames)
    fps = _check_fps(fps)
    path = Path(path)
    if path.suffix.lower() == ".npz":
        with path.open("wb") as f:
            np.savez(f, frames=frames, fps=np.float64(fps))
        return path
    import cv2

    n, h, w = frames.shape[:3]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h), colour)
    if not writer.isOpened():
        raise OSError(f"{path}: OpenCV could not open an mp4v video for writing.")
    try:
        for frame in frames:
            writer.write(np.ascontiguousarray(frame))
    finally:
        writer.release()
    return path


@contextlib.contextmanager
def _decoder_log():
    """What C code (FFmpeg's log, inside OpenCV) writes to file descriptor 2 during the
    block: `box["lines"]` after it. The descriptor is restored at the end of the block;
    lines that are not FFmpeg's are written back to it then (delayed, never lost)."""
    box = {"lines": []}
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):  # no descriptor 2: nothing to read
        yield box
        return
    with tempfile.TemporaryFile() as log:
        os.dup2(log.fileno(), 2)
        try:
            yield box
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            log.seek(0)
            lines = log.read().decode("utf-8", "replace").splitlines()
            box["lines"] = [ln for ln in lines if _DECODER_LINE.match(ln)]
            others = [ln for ln in lines if not _DECODER_LINE.match(ln)]
            if others:
                os.write(2, ("\n".join(others) + "\n").encode())


def read_video(path, *, allow_damaged: bool = False) -> tuple[np.ndarray, float]:
    """Read a video as grey frames.

    **Arguments:** `path`: a video OpenCV can decode (`cv2.VideoCapture`; colour frames are
    converted to grey with `cv2.COLOR_BGR2GRAY`), or an `.npz` with keys `frames` (N, H, W)
    uint8 and `fps`.

    **Returns:** `(frames (N, H, W) uint8, fps)`; `fps` is NaN when the container does not
    state it. Raises `FileNotFoundError` for a missing file and `visjax.io.DataFormatError`
    (a `ValueError`; one line naming the file) for a file that is not a readable video: one
    OpenCV cannot open or decode, a damaged one (fewer frames decode than its container
    declares: it is truncated or corrupt from that frame on), an NPZ without the keys, with
    no frames or frames that are not uint8, or with an `fps` that is not positive.

    A damaged stream often still decodes every frame, its broken blocks concealed (filled
    from neighbours): the decoder's complaints (FFmpeg's log lines, read from file
    descriptor 2 while decoding) then make it a `DataFormatError` too, naming the first;
    `allow_damaged=True` returns the frames anyway (the complaints still printed).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such video file.")
    if path.suffix.lower() == ".npz":
        data = read_npz(path)  # a DataFormatError (a ValueError): one line, no traceback
        if "frames" not in data or "fps" not in data:
            raise DataFormatError(f"{path}: expected the keys 'frames' and 'fps'.")
        try:
            fps = _check_fps(data["fps"])
            return check_frames(data["frames"], f"{path.name}['frames']"), fps
        except ValueError as e:
            raise DataFormatError(f"{path}: {e}") from None
    import cv2

    frames = []
    with _decoder_log() as log:
        capture = cv2.VideoCapture(str(path))
        try:
            opened = capture.isOpened()
            fps = float(capture.get(cv2.CAP_PROP_FPS))
            declared = int(max(capture.get(cv2.CAP_PROP_FRAME_COUNT), 0))
            size = int(
                capture.get(cv2.CAP_PROP_FRAME_WIDTH) * capture.get(cv2.CAP_PROP_FRAME_HEIGHT)
            )
            limit = max_data_bytes()
            if opened and 2 * declared * size > limit:  # the frames, then their stack
                raise DataFormatError(
                    f"{path}: {declared} frames of {size} pixels decode to "
                    f"{2 * declared * size / 2**30:.3g} GiB (grey, with their copy), above the "
                    f"limit of {limit / 2**30:.3g} GiB (VISJAX_MAX_DATA_BYTES): cut the "
                    "video, or raise the limit"
                )
            total = 0
            while opened:
                ok, frame = capture.read()
                if not ok:
                    break
                if frame.ndim == 3:
                    frame = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
                total += frame.nbytes
                if 2 * total > limit:  # a container that understates its frames
                    raise DataFormatError(
                        f"{path}: its frames decode past the limit of {limit / 2**30:.3g} GiB "
                        f"(VISJAX_MAX_DATA_BYTES) at frame {len(frames)}, although the "
                        f"container declares {declared}: cut the video, or raise the limit"
                    )
                frames.append(frame)
        finally:
            capture.release()
    complaints = log["lines"]
    if not opened:
        said = f" ({complaints[0]})" if complaints else ""
        raise DataFormatError(f"{path}: OpenCV cannot open it as a video{said}.")
    if complaints and allow_damaged:
        os.write(2, ("\n".join(complaints) + "\n").encode())
    elif complaints:
        raise DataFormatError(
            f"{path}: a damaged video: the decoder reported {len(complaints)} error(s), the "
            f"first `{complaints[0]}` (damaged blocks are filled in, not the scene); "
            "use an intact copy, or track it anyway (--allow-damaged)."
        )
    if not frames:
        raise DataFormatError(f"{path}: no frame could be decoded.")
    if len(frames) < declared - 1:  # a container's count may be one off, never more
        raise DataFormatError(
            f"{path}: a damaged video: its container declares {declared} frames but only "
            f"{len(frames)} decode (truncated or corrupt from frame {len(frames)} on)."
        )
    return np.stack(frames).astype(np.uint8), fps if np.isfinite(fps) and fps > 0 else np.nan


def annotate_frames(frames, tracked=None, projected=None, captions=None) -> np.ndarray:
    """Grey frames as BGR colour frames with overlays, for a video of a tracking run:
    `tracked` (N, 2) pixels drawn as green circles, `projected` (N, 2) pixels (an estimate
    projected into the image) as red crosses, `captions` (N strings) at the top left. A
    non-finite pixel, or one more than 1e4 px away, is not drawn. OpenCV, never jit.

    **Returns:** (N, H, W, 3) uint8 BGR frames (`write_video` writes them)."""
    import cv2

    frames = check_frames(frames)
    out = np.empty(frames.shape + (3,), np.uint8)
    for i, frame in enumerate(frames):
        img = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
        p = None if tracked is None else np.asarray(tracked[i], float)
        if p is not None and np.all(np.isfinite(p)):
            cv2.circle(img, (int(round(p[0])), int(round(p[1]))), 6, (0, 200, 0), 1, cv2.LINE_AA)
        q = None if projected is None else np.asarray(projected[i], float)
        if q is not None and np.all(np.isfinite(q)) and np.all(np.abs(q) < 1e4):
            centre = (int(round(q[0])), int(round(q[1])))
            cv2.drawMarker(img, centre, (0, 0, 230), cv2.MARKER_CROSS, 12, 1, cv2.LINE_AA)
        if captions is not None:
            white = (255, 255, 255)
            font = cv2.FONT_HERSHEY_SIMPLEX
            cv2.putText(img, str(captions[i]), (8, 20), font, 0.5, white, 1, cv2.LINE_AA)
        out[i] = img
    return out
