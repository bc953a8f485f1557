"""The input formats of the three estimators: what a user with their own logged data
writes to feed them. NumPy `.npz` files (one array per key), SI units, pixels for pixels,
rotations as 3x3 matrices, NaN for a feature that was not seen. Truth keys are optional:
errors are reported only when they are present. Pixel tracks also load from and save to
CSV (one row per observation: `t, feature, u, v`).

Velocity (Chitrakaran et al., *Identification of a moving object's velocity with a fixed
camera*):

| key | shape | meaning |
| --- | --- | --- |
| `t` | (N,) | frame times, s, increasing |
| `pixels` | (N, n, 2) | n >= 4 coplanar features' pixels, feature 1 first; frame 0 the |
| | | reference image unless `reference_pixels` is given |
| `reference_pixels` | (n, 2) | optional: the reference image, taken at the pose `R_star` |
| `A` | (3, 3) | camera intrinsics |
| `R_star` | (3, 3) | the object's orientation in the camera frame at the reference image |
| `s1` | (3,) | feature 1 in the object frame, m |
| `known_length` | (3,) | `(i, j, L)`: two feature indices (0 is feature 1) and their distance, m |
| `velocity` | (N, 6) | truth, optional: $[v_e, \\omega_e]$ in the camera frame, m/s and rad/s |
| `K`, `rho` | (6,) | optional gains (default: eq. (63) of the paper) |
| `dist` | (k,) | optional: the lens' distortion (below) |

Structure (Jang's thesis, *structure of a moving point seen by a moving camera*):

| key | shape | meaning |
| --- | --- | --- |
| `t` | (N,) | frame times, s |
| `pixels` | (N, 2) | the tracked point's pixels (NaN: not seen in that frame) |
| `A` | (3, 3) | camera intrinsics |
| `camera_t` | (M,) | times of the camera velocity samples, s (any rate) |
| `camera_velocity` | (M, 6) | $[v_c, \\omega_c]$ of the camera in its own frame, m/s and rad/s |
| `D` | (3,) | direction of the unknown input (the point's own motion), thesis eq. (3.1) |
| `depth_guess` | () | optional: the observer's initial depth guess, m (default 1) |
| `position` | (N, 3) | truth, optional: the point in the camera frame, m |
| `dist` | (k,) | optional: the lens' distortion (below) |

Euclidean (Nath, Dawson, Tatlicioglu, *Euclidean position estimation of static features
using a moving uncalibrated camera*):

| key | shape | meaning |
| --- | --- | --- |
| `t` | (N,) | frame times, s |
| `pixels` | (N, n, 2) | features' pixels; the first k are the known features |
| `platform_R`, `platform_x` | (N, 3, 3), (N, 3) | the measured platform pose in the world frame |
| `known_features` | (k, 3) | world positions of the first k features, m |
| `A_nominal`, `R_c_nominal` | (3, 3) | the nominal camera: intrinsics, mounting rotation |
| `x_c_nominal` | (3,) | the nominal mounting offset (nominal: never the truth), m |
| `features` | (n - k, 3) | truth, optional: world positions of the unknown features, m |
| `dist` | (k,) | optional: the lens' distortion (below), with `A_nominal` |

**Lens distortion.** The estimators assume a pinhole camera. A file whose pixels are as a
real lens saw them gives that lens' distortion as `dist`: OpenCV's coefficients, in its
order, 4, 5, 8, 12 or 14 of them (`k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4[,
tau_x, tau_y]]]]`), what `cv2.calibrateCamera` and a ROS `CameraInfo` give with the
intrinsics. `load` checks the raw pixels, then undistorts them (`undistorted`,
`visjax.geometry.undistort_pixels`, with the file's intrinsics) before anything else sees
them; a pixel the lens model cannot have produced is refused. `load(path,
undistort=False)` keeps the raw pixels (and `dist`).

Conventions of eq. (5) of Nath et al.: a world point $w$ is at
$R_c^T(R_b^T(w - x_b) - x_c)$ in the camera frame.

**What is refused.** A loader reads nothing it has not checked, and every refusal is one
`DataFormatError` (a `ValueError`) that names the file and the key, which the command line
prints as one line:

- a file that is not a readable `.npz` archive (empty, truncated or damaged, a single `.npy`
  array renamed, a text file), and in `load_tracks_csv` an empty, binary or non-UTF-8 file,
  a row with too few or too many values, or two rows for the same feature and time;
- an archive whose arrays would take more than `MAX_DATA_BYTES` (2 GiB) uncompressed, judged
  from the zip's member headers before any array is read; the environment variable
  `VISJAX_MAX_DATA_BYTES` (read at each load) raises or lowers the limit;
- a key that is not in the format (with the closest valid key: a misspelt key is never
  silently ignored), an array of Python objects, a complex array (its imaginary part would
  be lost), dates or durations (`datetime64`, `timedelta64`) instead of seconds;
- intrinsics `A` (`A_nominal`) that are not a pinhole camera's: upper-triangular, last row
  $(0, 0, 1)$ (to 1e-9 relative), positive focal lengths `A[0, 0]`, `A[1, 1]`; the transpose
  (MATLAB's convention, $K^T$) is named as such;
- times in other units than seconds: a median sample interval of `t` (or `camera_t`)
  outside [`MIN_INTERVAL_S`, `MAX_INTERVAL_S`] = [1e-5 s, 10 s], with the rate each
  likely unit (milliseconds, microseconds, nanoseconds) would give; and, unless the file
  declares its unit, a median interval above `SLOW_INTERVAL_S` = 0.2 s (slower than 5 Hz):
  that is what a log at 200 Hz to 10 kHz in milliseconds looks like (a 1 kHz log in ms has
  intervals of 1), and a camera that slow is rare enough to ask for the declaration. A file
  declares its unit with the key `time_unit` (a string: `"s"`, `"ms"`, `"us"`, `"ns"`);
  `load` converts its times to seconds (a ROS log's nanoseconds load as they are; integer
  times are counted from the earliest of them, exactly);
- a feature (a column of `pixels`) seen in fewer than `MIN_OBSERVATIONS` = 2 images (the
  velocity format counts its reference image): one view shows no motion and no depth.

Frames where pixels are missing are not refused: `coverage` (the fraction of frames with
every feature seen) and `dropped_fraction()` (the rest) report them, and
`MAX_DROPPED_FRACTION` is the fraction above which a command should warn that its result
rests on too few frames.
"""

import csv
import dataclasses
import math
import os
import zipfile
import zlib
from dataclasses import dataclass, fields
from pathlib import Path

import jax
import numpy as np
import numpy.lib.format as npy_format

from .._util import did_you_mean
from ..geometry import DISTORTION_LENGTHS, undistort_pixels

MAX_DATA_BYTES = 2 * 1024**3
"""The most bytes a data file's arrays may take once read (the sum of the uncompressed
sizes of an `.npz` archive's members, a CSV file's size): 2 GiB, far above any realistic
log, well below what would exhaust a laptop's memory. The environment variable
`VISJAX_MAX_DATA_BYTES`, read at each load, replaces it."""

MIN_INTERVAL_S = 1e-5
"""The shortest plausible median interval between samples, s (100 kHz): faster is not a
camera or a motion log in seconds."""

MAX_INTERVAL_S = 10.0
"""The longest plausible median interval between samples, s (0.1 Hz): longer is, in
practice, milliseconds, microseconds or nanoseconds given as seconds."""

SLOW_INTERVAL_S = 0.2
"""The longest median interval between samples, s (5 Hz), that a file may have without
declaring its unit (`time_unit`): between it and `MAX_INTERVAL_S` lie both rare slow
cameras in seconds and every log from 100 Hz to 5 kHz in milliseconds, which only the
file's author can tell apart."""

TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
"""The units a file's `time_unit` key may declare, with their length in seconds."""

_TIME_KEYS = ("t", "camera_t")

MIN_OBSERVATIONS = 2
"""The fewest images a feature must be seen in, counting the velocity format's reference
image: one view shows neither motion (the velocity's homography needs the reference and a
second view) nor depth (the structure of a point needs two views)."""

MAX_DROPPED_FRACTION = 0.5
"""The largest fraction of frames with a feature missing (`dropped_fraction()`) that a
command reports as a plain result: above it, most of the estimate rests on held or
extrapolated frames and the summary should warn."""

MIN_LENGTH_M = 1e-4
"""The shortest plausible known length, m (0.1 mm): shorter is in other units, or a typo,
and every depth and velocity would be off by as much."""

MAX_LENGTH_M = 1e4
"""The longest plausible known length, m (10 km)."""

_INTRINSICS_TOL = 1e-9  # relative: the last row (0, 0, 1) and the zero below the diagonal
_NPY_MAGIC = b"\x93NUMPY"


class DataFormatError(ValueError):
    """A data file does not follow its documented format (the message says what)."""


def max_data_bytes() -> int:
    """`MAX_DATA_BYTES`, or the environment variable `VISJAX_MAX_DATA_BYTES` when set
    (read now, not at import); a value that is not a positive number is an error."""
    text = os.environ.get("VISJAX_MAX_DATA_BYTES", "").strip()
    if not text:
        return MAX_DATA_BYTES
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (np.isfinite(value) and value > 0):
        raise DataFormatError(
            f"VISJAX_MAX_DATA_BYTES must be a positive number of bytes; got {text!r}."
        )
    return int(value)


def _size(n: int) -> str:
    return f"{n / 1024**3:.3g} GiB" if n >= 1024**3 else f"{n / 1024**2:.3g} MiB"


def _check_size(path, n: int, what: str) -> None:
    limit = max_data_bytes()
    if n > limit:
        raise DataFormatError(
            f"{path}: {what} would take {_size(n)} (limit {_size(limit)}; set "
            "VISJAX_MAX_DATA_BYTES to raise it)."
        )


def _dtype_problem(key: str, dtype: np.dtype) -> str | None:
    """Why an array of this dtype cannot be a key's value (`None`: it can be)."""
    if key == "time_unit" and dtype.kind == "U":
        return None
    if dtype.hasobject:
        return f"`{key}` holds Python objects (an object array); save numeric arrays."
    if np.issubdtype(dtype, np.complexfloating):
        return f"`{key}` is complex: its imaginary part would be lost."
    if np.issubdtype(dtype, np.timedelta64):
        return (
            f"`{key}` holds durations (timedelta64); give seconds as floats, e.g. "
            f"{key} / np.timedelta64(1, 's')."
        )
    if np.issubdtype(dtype, np.datetime64):
        return (
            f"`{key}` holds dates (datetime64); give seconds as floats, e.g. "
            f"({key} - {key}[0]) / np.timedelta64(1, 's')."
        )
    if not np.issubdtype(dtype, np.number):
        return f"`{key}` must be numeric; got {dtype}."
    return None


def _unreadable(path, why: str) -> DataFormatError:
    return DataFormatError(f"{path}: not a readable .npz file ({why}).")


# what reading a damaged archive or member can raise (never numpy's own hints: see `_why`)
_READ_ERRORS = (
    zipfile.BadZipFile,
    zlib.error,
    EOFError,
    OSError,
    ValueError,
    KeyError,
    NotImplementedError,  # a compression method zipfile does not know
    RuntimeError,  # an encrypted member
)


def _why(error: Exception) -> str:
    text = " ".join(str(error).split()) or type(error).__name__
    if "pickle" in text:  # numpy's hint to load unsafely: never passed on
        return "it holds Python objects (pickled data)"
    return text if len(text) <= 200 else text[:200] + "..."


def read_npz(path) -> dict[str, np.ndarray]:
    """The arrays of an `.npz` file, checked before they are read: an empty, truncated or
    damaged archive, a single `.npy` array renamed, a text file, a member that is not a
    `.npy` array, object, complex, date or non-numeric arrays, and an archive whose arrays
    would take more than `max_data_bytes()` uncompressed all raise `DataFormatError` with a
    one-line message naming the file (and the key)."""
    path = Path(path)
    with _open_npz(path) as zf:
        return _read_members(path, zf, _npz_keys(path, zf))


def _open_npz(path: Path) -> zipfile.ZipFile:
    if not path.exists():
        raise DataFormatError(f"{path}: no such file.")
    if path.is_dir():
        raise DataFormatError(f"{path}: a folder, not an .npz file.")
    try:
        with path.open("rb") as f:
            head = f.read(8)
    except OSError as e:
        raise DataFormatError(f"{path}: cannot be read ({_why(e)}).") from None
    if not head:
        raise _unreadable(path, "the file is empty")
    if head.startswith(_NPY_MAGIC):
        raise _unreadable(
            path,
            "it is a single .npy array, not an archive of named arrays: write it with np.savez",
        )
    if path.suffix.lower() == ".csv" or not head.startswith(b"PK"):
        hint = "; pixel tracks in CSV load with visjax.io.load_tracks_csv" if b"," in head else ""
        raise _unreadable(path, f"not a zip archive{hint}")
    try:
        zf = zipfile.ZipFile(path)
    except _READ_ERRORS as e:
        raise _unreadable(path, f"a truncated or damaged zip archive: {_why(e)}") from None
    try:
        # before any array is read: the sizes the members' headers declare (a member is
        # never inflated past its declared size, so the sum bounds what loading takes)
        _check_size(path, sum(info.file_size for info in zf.infolist()), "its arrays")
    except BaseException:
        zf.close()
        raise
    return zf


def _npz_keys(path: Path, zf: zipfile.ZipFile) -> dict[str, zipfile.ZipInfo]:
    keys = {}
    for info in zf.infolist():
        if info.is_dir():
            continue
        if not info.filename.endswith(".npy"):
            raise _unreadable(path, f"its member `{info.filename}` is not a .npy array")
        keys[info.filename[: -len(".npy")]] = info
    return keys


def _read_members(path: Path, zf: zipfile.ZipFile, keys: dict) -> dict[str, np.ndarray]:
    arrays = {}
    for key, info in keys.items():
        try:
            with zf.open(info) as f:
                version = npy_format.read_magic(f)
                if version == (1, 0):
                    shape, fortran, dtype = npy_format.read_array_header_1_0(f)
                elif version == (2, 0):
                    shape, fortran, dtype = npy_format.read_array_header_2_0(f)
                else:  # (3, 0): utf-8 field names, which no visjax key has
                    raise ValueError(f"unsupported .npy format version {version}")
                problem = _dtype_problem(key, dtype)
                if problem is not None:
                    raise DataFormatError(f"{path}: {problem}")
                claimed = math.prod(shape) * dtype.itemsize
            if claimed > info.file_size:
                raise ValueError(f"it declares {claimed} bytes but holds {info.file_size}")
            with zf.open(info) as f:
                array = npy_format.read_array(f, allow_pickle=False)
        except DataFormatError:
            raise
        except _READ_ERRORS as e:
            raise _unreadable(path, f"`{key}`: {_why(e)}") from None
        arrays[key] = np.asarray(array)
    return arrays


def _rotation_ok(R) -> bool:
    R = np.asarray(R)
    eye = np.broadcast_to(np.eye(3), R.shape)
    return bool(
        np.all(np.isfinite(R))
        and np.allclose(np.swapaxes(R, -1, -2) @ R, eye, atol=1e-6)
        and np.all(np.linalg.det(R) > 0)
    )


def _check_intrinsics(A, key: str) -> None:
    """A pinhole camera's intrinsics: upper-triangular, last row (0, 0, 1) to
    `_INTRINSICS_TOL` relative, positive focal lengths; its transpose is named."""
    A = np.asarray(A, float)
    tol = _INTRINSICS_TOL * max(1.0, float(np.max(np.abs(A))))
    last = ", ".join(f"{x:g}" for x in A[2])
    row_ok = abs(A[2, 0]) <= tol and abs(A[2, 1]) <= tol and abs(A[2, 2] - 1) <= _INTRINSICS_TOL
    if not row_ok:
        if abs(A[0, 2]) <= tol and abs(A[1, 2]) <= tol and abs(A[2, 2] - 1) <= _INTRINSICS_TOL:
            raise DataFormatError(
                f"`{key}` looks transposed (MATLAB's convention: K'): its last row must be "
                f"(0, 0, 1) and its last column the principal point (cx, cy, 1); got the last "
                f"row ({last}): give {key}.T."
            )
        raise DataFormatError(
            f"`{key}` must be a pinhole camera's intrinsics, its last row (0, 0, 1); got ({last})."
        )
    if abs(A[1, 0]) > tol:
        raise DataFormatError(
            f"`{key}` must be upper-triangular (a pinhole camera's intrinsics); "
            f"got {key}[1, 0] = {A[1, 0]:g}."
        )
    if not (A[0, 0] > 0 and A[1, 1] > 0):
        raise DataFormatError(
            f"`{key}`'s focal lengths {key}[0, 0] and {key}[1, 1] must be positive (pixels); "
            f"got {A[0, 0]:g} and {A[1, 1]:g}."
        )


def _rates(interval: float) -> str:
    """`as ms 1 kHz, as us 1 MHz`: the sample rate `interval` gives in each unit of
    `TIME_UNITS` but seconds, those within 0.1 Hz to 100 kHz (or all, if none is)."""
    named = {"ms": "milliseconds", "us": "microseconds", "ns": "nanoseconds"}
    rates = [(named[u], 1 / (interval * TIME_UNITS[u])) for u in named]
    plausible = [(u, r) for u, r in rates if 0.1 <= r <= 1e5] or rates
    return ", ".join(f"in {u} {_hz(r)}" for u, r in plausible)


def _hz(rate: float) -> str:
    for scale, prefix in ((1e6, "M"), (1e3, "k")):
        if rate >= scale:
            return f"{rate / scale:.3g} {prefix}Hz"
    return f"{rate:.3g} Hz"


def _check_time_units(t, key: str, declared: bool = False) -> None:
    """The median sample interval within [`MIN_INTERVAL_S`, `MAX_INTERVAL_S`] and, when the
    unit is not `declared`, at most `SLOW_INTERVAL_S`: seconds."""
    t = np.asarray(t, float)
    if t.shape[0] < 2:
        return
    interval = float(np.median(np.diff(t)))
    declare = '; if they are seconds, add the key time_unit="s" to the file'
    if interval > MAX_INTERVAL_S or (interval > SLOW_INTERVAL_S and not declared):
        longest = MAX_INTERVAL_S if declared else SLOW_INTERVAL_S
        raise DataFormatError(
            f"`{key}` does not look like seconds: its median interval {interval:g} would be "
            f"{_hz(1 / interval)} in seconds, {_rates(interval)}; give seconds (a median "
            f"interval of {MIN_INTERVAL_S:g} to {longest:g} s) or declare the unit with "
            f'the key time_unit ("ms", "us", "ns"){"" if declared else declare}.'
        )
    if interval < MIN_INTERVAL_S:
        raise DataFormatError(
            f"`{key}`'s median interval is {interval:g} s, faster than {_hz(1 / MIN_INTERVAL_S)}"
            ": likely not seconds; give seconds."
        )


def _declared_unit(path, arrays: dict) -> bool:
    """Converts `arrays`' times to seconds by their `time_unit` key (then `"s"`); returns
    whether the file declared a unit."""
    if "time_unit" not in arrays:
        return False
    unit = arrays["time_unit"]
    if unit.shape != () or unit.dtype.kind != "U" or str(unit) not in TIME_UNITS:
        raise DataFormatError(
            f"{path}: `time_unit` must be one string among {', '.join(map(repr, TIME_UNITS))}; "
            f"got {unit.tolist()!r}."
        )
    factor = TIME_UNITS[str(unit)]
    keys = [k for k in _TIME_KEYS if k in arrays and np.issubdtype(arrays[k].dtype, np.number)]
    origin = 0
    if keys and all(np.issubdtype(arrays[k].dtype, np.integer) and arrays[k].size for k in keys):
        # integer clocks (a ROS log's nanoseconds since the epoch, ~1.7e18) counted from
        # their earliest time in integers: as float64 seconds since the epoch, they would
        # keep only ~0.2 us
        origin = min(int(arrays[k].min()) for k in keys)
    for key in keys:
        v = arrays[key]
        if origin:  # exactly, whatever the integer type (uint64 near its limit too)
            span = int(v.max()) - origin
            if span > np.iinfo(np.int64).max:
                raise DataFormatError(
                    f"{path}: `{key}` spans {span} {unit} (more than 2^63): not one "
                    "recording's clock"
                )
            if v.dtype.kind == "u":
                v = (v - v.dtype.type(origin)).astype(np.int64)
            else:
                v = v.astype(np.int64) - np.int64(origin)
        arrays[key] = np.asarray(v, np.float64) * factor
    arrays["time_unit"] = "s"
    return True


def _declared_missing(path, arrays: dict) -> None:
    """A file's `missing_value` key (a number: the mark its exporter writes for a lost
    feature, e.g. 0 or -1): every pixel observation with both coordinates equal to it
    becomes NaN (a feature out of view), and the key is dropped."""
    if "missing_value" not in arrays:
        return
    mark = arrays.pop("missing_value")
    if mark.shape != () or mark.dtype.kind not in "iuf" or not np.isfinite(mark):
        raise DataFormatError(
            f"{path}: `missing_value` must be one finite number (the mark of a lost feature, "
            f"e.g. 0); got {mark.tolist()!r}."
        )
    for key in ("pixels", "reference_pixels"):
        if key in arrays:
            p = np.asarray(arrays[key], np.float64)
            lost = np.all(p == float(mark), axis=-1)
            arrays[key] = np.where(lost[..., None], np.nan, p)


def _check_observations(seen, extra: int = 0, what: str = "feature") -> None:
    """Every column of `seen` (N, n) true in at least `MIN_OBSERVATIONS - extra` rows."""
    counts = np.sum(seen, axis=0) + extra
    bad = np.flatnonzero(counts < MIN_OBSERVATIONS)
    if bad.size == 0:
        return
    i, c = int(bad[0]), int(counts[bad[0]])
    more = f" (and {bad.size - 1} more)" if bad.size > 1 else ""
    name = f"{what} {i} (column {i} of `pixels`, 0-based)" if seen.shape[1] > 1 else what
    counted = ", counting the reference image" if extra else ""
    if c == 0:
        raise DataFormatError(
            f"{name} is never seen (NaN in every frame){more}: drop it from `pixels`."
        )
    raise DataFormatError(
        f"{name} is seen in {c} image(s){counted}{more}; each needs at least "
        f"MIN_OBSERVATIONS = {MIN_OBSERVATIONS} (one view shows no motion): drop it from "
        "`pixels` or track it longer."
    )


class _Format:
    """Shared load/save/validate for a dataclass of NumPy arrays."""

    REQUIRED: tuple[str, ...] = ()
    NAME = ""
    PIXELS: tuple[str, ...] = ("pixels",)  # the keys of pixels, undistorted by `undistorted`
    INTRINSICS = "A"  # the key of the intrinsics `dist` goes with

    @classmethod
    def load(cls, path, *, undistort: bool = True):
        """Read and validate a `.npz` file (`read_npz`'s checks, then the format's): an
        unknown or missing key, a wrong shape or a bad value raises `DataFormatError`
        naming the file and the key. With `dist` in the file, the pixels are then
        undistorted (`undistorted`) unless `undistort=False`."""
        path = Path(path)
        known = [f.name for f in fields(cls)]
        with _open_npz(path) as zf:
            keys = _npz_keys(path, zf)
            unknown = [k for k in keys if k not in known and k != "missing_value"]
            if unknown:
                named = ", ".join(f"`{k}`{did_you_mean(k, known)}" for k in unknown)
                raise DataFormatError(
                    f"{path}: unknown key{'s' if len(unknown) > 1 else ''} {named}; the "
                    f"{cls.NAME} format's keys are {', '.join(known)} (and missing_value)."
                )
            missing = [k for k in cls.REQUIRED if k not in keys]
            if missing:
                raise DataFormatError(
                    f"{path}: the {cls.NAME} format needs the keys {list(cls.REQUIRED)}; "
                    f"missing {missing}."
                )
            arrays = _read_members(path, zf, keys)
        _declared_unit(path, arrays)
        _declared_missing(path, arrays)
        data = cls(**arrays)
        try:
            data.validate()
            return data.undistorted() if undistort else data
        except DataFormatError as e:
            raise DataFormatError(f"{path}: {e}") from None

    def undistorted(self):
        """The same data as a pinhole camera would have recorded it: every pixel key
        undistorted (`visjax.geometry.undistort_pixels`, in float64, with the format's
        intrinsics and `dist`), and no `dist`; itself when it has no `dist`.

        **Raises:** `DataFormatError` for a seen pixel that the lens model cannot have
        produced (beyond the largest radius its distortion reaches: coefficients of
        another camera, or of another image size)."""
        if self.dist is None:
            return self
        A = np.asarray(getattr(self, self.INTRINSICS), float)
        dist = np.asarray(self.dist, float)
        changes = {"dist": None}
        for key in self.PIXELS:
            p = getattr(self, key)
            if p is None or not np.any(dist):
                continue
            p = np.asarray(p, float)
            with jax.enable_x64(True):  # the file's precision, whatever the caller's
                q = np.asarray(undistort_pixels(p, A, dist))
            lost = np.all(np.isfinite(p), axis=-1) & ~np.all(np.isfinite(q), axis=-1)
            if lost.any():
                first = tuple(int(i) for i in np.argwhere(lost)[0])
                raise DataFormatError(
                    f"`{key}`: {int(lost.sum())} observation(s) (the first at index {first}, "
                    f"{p[first]} px) lie where the lens model `dist` maps no point: the "
                    "coefficients of another camera, or of another image size?"
                )
            changes[key] = q
        return dataclasses.replace(self, **changes)

    def _distortion(self):
        if self.dist is None:
            return
        self._shape("dist", (None,))
        if np.shape(self.dist)[0] not in DISTORTION_LENGTHS:
            raise DataFormatError(
                f"`dist` must hold 4, 5, 8, 12 or 14 coefficients (OpenCV's order: k1, k2, "
                f"p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4[, tau_x, tau_y]]]]); got "
                f"{np.shape(self.dist)[0]}."
            )
        self._finite("dist")

    def save(self, path) -> Path:
        """Write the arrays that are not `None` to a `.npz` file (validated first)."""
        self.validate()
        path = Path(path)
        arrays = {f.name: getattr(self, f.name) for f in fields(self)}
        np.savez(path, **{k: np.asarray(v) for k, v in arrays.items() if v is not None})
        return path

    def _seen(self) -> np.ndarray:
        """(N, n) booleans: feature i seen (both pixel coordinates finite) in frame k."""
        p = np.asarray(self.pixels, float)
        seen = np.all(np.isfinite(p), axis=-1)
        return seen[:, None] if seen.ndim == 1 else seen

    def dropped_fraction(self) -> float:
        """The fraction of frames in which a feature is missing (a NaN pixel): any of the
        n features (velocity, euclidean), the point (structure). Compare it with
        `MAX_DROPPED_FRACTION`."""
        return float(np.mean(~np.all(self._seen(), axis=1)))

    @property
    def coverage(self) -> float:
        """The fraction of frames in which every feature is seen: `1 - dropped_fraction()`."""
        return 1.0 - self.dropped_fraction()

    def _shape(self, key, shape):
        v = getattr(self, key)
        if v is None:
            return
        v = np.asarray(v)
        problem = _dtype_problem(key, v.dtype)
        if problem is not None:
            raise DataFormatError(problem)
        ok = v.ndim == len(shape) and all(s is None or s == d for s, d in zip(shape, v.shape))
        if not ok:
            want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
            raise DataFormatError(f"`{key}` must have shape {want}; got {v.shape}.")

    def _finite(self, *keys):
        for key in keys:
            v = getattr(self, key)
            if v is not None and not np.all(np.isfinite(v)):
                raise DataFormatError(f"`{key}` must be finite (NaN is allowed in pixels only).")

    def _pixels_in_image(self, A, *keys):
        """Pixels inside the image that the intrinsics imply, [0, 2 c] for a principal
        point c (a pinhole camera's principal point lies near the image's centre), and no
        observation exactly at (0, 0): a tracker's or an exporter's mark for a lost
        feature, which a file must declare (`missing_value`), not pass off as a pixel."""
        A = np.asarray(A, float)
        top = 2.0 * np.array([A[0, 2], A[1, 2]])
        for key in keys:
            v = getattr(self, key)
            if v is None:
                continue
            p = np.asarray(v, float)
            seen = np.all(np.isfinite(p), axis=-1)
            if not seen.any():
                continue
            q = p[seen]
            if np.any(np.all(q == 0.0, axis=-1)):
                count = int(np.sum(np.all(q == 0.0, axis=-1)))
                raise DataFormatError(
                    f"`{key}` holds {count} observation(s) at exactly (0, 0): the mark of a "
                    "lost feature in many exports, not a pixel; give lost features as NaN, or "
                    "declare the mark with the key missing_value (e.g. missing_value=0)."
                )
            low = q.min(axis=0)
            high = q.max(axis=0)
            if np.any(low < 0.0) or np.any(high > top):
                axis = int(np.argmax((low < 0.0) | (high > top)))
                name = "uv"[axis]
                raise DataFormatError(
                    f"`{key}`'s {name} coordinates span {low[axis]:.6g} to {high[axis]:.6g} px, "
                    f"outside the image the intrinsics imply (0 to {top[axis]:.6g} px: twice "
                    "the principal point): mirrored, offset or in other units than pixels?"
                )

    def _times(self, key="t"):
        t = np.asarray(getattr(self, key))
        if t.shape[0] < 2 or not np.all(np.diff(t) > 0):
            raise DataFormatError(f"`{key}` must hold at least 2 strictly increasing times.")
        _check_time_units(t, key, declared=self.time_unit is not None)

    def _check_unit(self):
        if self.time_unit is not None and str(self.time_unit) != "s":
            raise DataFormatError(
                f"`time_unit` is {str(self.time_unit)!r}: in memory, times are seconds "
                '(`time_unit` "s" or None); `load` converts a file\'s declared unit.'
            )


@dataclass
class VelocityData(_Format):
    """The velocity estimator's input (module docstring); arrays as NumPy."""

    t: np.ndarray
    pixels: np.ndarray
    A: np.ndarray
    R_star: np.ndarray
    s1: np.ndarray
    known_length: np.ndarray
    reference_pixels: np.ndarray | None = None
    velocity: np.ndarray | None = None
    K: np.ndarray | None = None
    rho: np.ndarray | None = None
    dist: np.ndarray | None = None
    time_unit: str | None = None

    REQUIRED = ("t", "pixels", "A", "R_star", "s1", "known_length")
    NAME = "velocity"
    PIXELS = ("pixels", "reference_pixels")

    def validate(self) -> None:
        n_t = np.shape(self.t)[0] if np.ndim(self.t) == 1 else None
        self._shape("t", (None,))
        n = np.shape(self.pixels)[1] if np.ndim(self.pixels) == 3 else None
        self._shape("pixels", (n_t, None, 2))
        if n < 4:
            raise DataFormatError(f"`pixels` must hold at least 4 features; got {n}.")
        for key, shape in (
            ("A", (3, 3)),
            ("R_star", (3, 3)),
            ("s1", (3,)),
            ("known_length", (3,)),
            ("reference_pixels", (n, 2)),
            ("velocity", (n_t, 6)),
            ("K", (6,)),
            ("rho", (6,)),
        ):
            self._shape(key, shape)
        self._check_unit()
        self._distortion()
        self._times()
        self._finite("t", "A", "R_star", "s1", "known_length", "velocity", "K", "rho")
        _check_intrinsics(self.A, "A")
        if not _rotation_ok(self.R_star):
            raise DataFormatError("`R_star` must be a rotation matrix.")
        i, j, length = np.asarray(self.known_length, float)
        if not (i == int(i) and j == int(j) and 0 <= i < n and 0 <= j < n and i != j):
            raise DataFormatError(
                f"`known_length` must name two different features among the {n} "
                f"(0-based indices); got ({i:g}, {j:g})."
            )
        if not length > 0:
            raise DataFormatError(f"`known_length[2]` (metres) must be positive; got {length}.")
        if not MIN_LENGTH_M <= length <= MAX_LENGTH_M:
            raise DataFormatError(
                f"`known_length[2]` is {length:g} m, outside the plausible {MIN_LENGTH_M:g} to "
                f"{MAX_LENGTH_M:g} m: metres, not millimetres or another unit?"
            )
        self._pixels_in_image(self.A, "pixels", "reference_pixels")
        ref = self.pixels[0] if self.reference_pixels is None else self.reference_pixels
        if not np.all(np.isfinite(ref)):
            raise DataFormatError(
                "the reference image (frame 0, or `reference_pixels`) must show every feature."
            )
        for key in ("K", "rho"):
            v = getattr(self, key)
            if v is not None and not np.all(np.asarray(v) > 0):
                raise DataFormatError(f"`{key}` must be positive.")
        _check_observations(self._seen(), extra=int(self.reference_pixels is not None))

    @property
    def length(self) -> tuple[int, int, float]:
        i, j, length = np.asarray(self.known_length, float)
        return int(i), int(j), float(length)


@dataclass
class MovingPointData(_Format):
    """The unknown input observer's input (module docstring); arrays as NumPy."""

    t: np.ndarray
    pixels: np.ndarray
    A: np.ndarray
    camera_t: np.ndarray
    camera_velocity: np.ndarray
    D: np.ndarray
    depth_guess: np.ndarray | None = None
    position: np.ndarray | None = None
    dist: np.ndarray | None = None
    time_unit: str | None = None

    REQUIRED = ("t", "pixels", "A", "camera_t", "camera_velocity", "D")
    NAME = "moving_point"

    def validate(self) -> None:
        self._shape("t", (None,))
        n_t = np.shape(self.t)[0]
        self._shape("pixels", (n_t, 2))
        self._shape("camera_t", (None,))
        self._shape("camera_velocity", (np.shape(self.camera_t)[0], 6))
        self._shape("A", (3, 3))
        self._shape("D", (3,))
        self._shape("position", (n_t, 3))
        self._shape("depth_guess", ())
        self._check_unit()
        self._distortion()
        self._times()
        self._times("camera_t")
        self._finite("t", "A", "camera_t", "camera_velocity", "D", "position", "depth_guess")
        _check_intrinsics(self.A, "A")
        if self.depth_guess is not None and not float(self.depth_guess) > 0:
            raise DataFormatError(f"`depth_guess` must be positive; got {self.depth_guess}.")
        if not np.linalg.norm(self.D) > 0:
            raise DataFormatError("`D` must be a nonzero direction.")
        if not np.all(np.isfinite(np.asarray(self.pixels)[0])):
            raise DataFormatError("the first frame must show the point (`pixels[0]` finite).")
        self._pixels_in_image(self.A, "pixels")
        if self.position is not None:
            z = np.asarray(self.position, float)[:, 2]
            if np.any(z <= 0.0):
                k = int(np.argmax(z <= 0.0))
                raise DataFormatError(
                    f"`position` (the truth, in the camera frame) is behind the camera at "
                    f"frame {k} (z = {z[k]:.6g} m): a point the camera sees has z > 0; "
                    "another frame or sign convention?"
                )
        if np.asarray(self.camera_t)[0] > np.asarray(self.t)[0]:
            raise DataFormatError(
                "the camera velocity must be known from the first frame on: `camera_t[0]` > `t[0]`."
            )
        _check_observations(self._seen(), what="the point")


@dataclass
class StaticPointsData(_Format):
    """The adaptive structure estimator's input (module docstring); arrays as NumPy."""

    t: np.ndarray
    pixels: np.ndarray
    platform_R: np.ndarray
    platform_x: np.ndarray
    known_features: np.ndarray
    A_nominal: np.ndarray
    R_c_nominal: np.ndarray
    x_c_nominal: np.ndarray
    features: np.ndarray | None = None
    dist: np.ndarray | None = None
    time_unit: str | None = None

    REQUIRED = (
        "t",
        "pixels",
        "platform_R",
        "platform_x",
        "known_features",
        "A_nominal",
        "R_c_nominal",
        "x_c_nominal",
    )
    NAME = "static_points"
    INTRINSICS = "A_nominal"

    def validate(self) -> None:
        self._shape("t", (None,))
        n_t = np.shape(self.t)[0]
        self._shape("pixels", (n_t, None, 2))
        n = np.shape(self.pixels)[1]
        self._shape("known_features", (None, 3))
        k = np.shape(self.known_features)[0]
        if not 0 < k < n:
            raise DataFormatError(
                f"`known_features` must give 1 to n - 1 = {n - 1} of the {n} features; got {k}."
            )
        for key, shape in (
            ("platform_R", (n_t, 3, 3)),
            ("platform_x", (n_t, 3)),
            ("A_nominal", (3, 3)),
            ("R_c_nominal", (3, 3)),
            ("x_c_nominal", (3,)),
            ("features", (n - k, 3)),
        ):
            self._shape(key, shape)
        self._check_unit()
        self._distortion()
        self._times()
        self._finite(
            "t",
            "platform_R",
            "platform_x",
            "known_features",
            "A_nominal",
            "R_c_nominal",
            "x_c_nominal",
            "features",
        )
        for key in ("platform_R", "R_c_nominal"):
            if not _rotation_ok(getattr(self, key)):
                raise DataFormatError(f"`{key}` must hold rotation matrices.")
        _check_intrinsics(self.A_nominal, "A_nominal")
        self._pixels_in_image(self.A_nominal, "pixels")
        _check_observations(self._seen())

    @property
    def n_known(self) -> int:
        return int(np.shape(self.known_features)[0])


def save_tracks_csv(path, t, pixels) -> Path:
    """Pixel tracks (N, n, 2) at times `t` (N,) as CSV rows `t, feature, u, v`, one per
    observation; a NaN pixel (not seen) has no row."""
    t, pixels = np.asarray(t, float), np.asarray(pixels, float)
    if pixels.ndim == 2:
        pixels = pixels[:, None, :]
    if pixels.ndim != 3 or pixels.shape[0] != t.shape[0] or pixels.shape[2] != 2:
        raise DataFormatError(
            f"expected t (N,) and pixels (N, n, 2); got {t.shape}, {pixels.shape}."
        )
    path = Path(path)
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", "feature", "u", "v"])
        for k in range(t.shape[0]):
            for i in range(pixels.shape[1]):
                u, v = pixels[k, i]
                if np.isfinite(u) and np.isfinite(v):
                    w.writerow([repr(float(t[k])), i, repr(float(u)), repr(float(v))])
    return path


def load_tracks_csv(path, n_features: int | None = None, time_unit: str | None = None):
    """The inverse of `save_tracks_csv`: `(t (N,), pixels (N, n, 2))`, NaN where a feature
    has no row at a time. `n_features` fixes n (default: the largest index + 1);
    `time_unit` (`"s"`, `"ms"`, `"us"`, `"ns"`; default: seconds, checked as the module
    docstring says) declares the unit of the column `t`, returned in seconds. An empty,
    binary or non-UTF-8 file, a row without four values, a value that is not a number, a
    time that is not finite or not in seconds, and two rows for one feature at one time
    raise `DataFormatError` naming the file (and the line)."""
    path = Path(path)
    if not path.exists():
        raise DataFormatError(f"{path}: no such file.")
    try:
        _check_size(path, path.stat().st_size, "its rows")
        with path.open(newline="", encoding="utf-8-sig") as f:
            lines = [(k, row) for k, row in enumerate(csv.reader(f), start=1) if row]
    except UnicodeDecodeError:
        raise DataFormatError(f"{path}: not a readable CSV file (not UTF-8 text).") from None
    except csv.Error as e:
        raise DataFormatError(f"{path}: not a readable CSV file ({_why(e)}).") from None
    except OSError as e:
        raise DataFormatError(f"{path}: cannot be read ({_why(e)}).") from None
    if not lines:
        raise DataFormatError(f"{path}: the file is empty; expected the columns t, feature, u, v.")
    header = [c.strip() for c in lines[0][1]]
    if sorted(header) != ["feature", "t", "u", "v"]:
        raise DataFormatError(f"{path}: expected the columns t, feature, u, v.")
    col = {name: header.index(name) for name in header}
    rows = lines[1:]
    if not rows:
        raise DataFormatError(f"{path}: no observation after the header.")
    t_all, idx, uv = np.empty(len(rows)), np.empty(len(rows), int), np.empty((len(rows), 2))
    for r, (line, row) in enumerate(rows):
        if len(row) != 4:
            raise DataFormatError(f"{path}: line {line} has {len(row)} values; expected 4.")
        try:
            t_all[r] = float(row[col["t"]])
            idx[r] = int(row[col["feature"]])
            uv[r] = float(row[col["u"]]), float(row[col["v"]])
        except ValueError as e:
            raise DataFormatError(f"{path}: line {line}: a value is not a number ({e}).") from None
    if not np.all(np.isfinite(t_all)):
        raise DataFormatError(f"{path}: every time `t` must be finite.")
    if np.any(idx < 0):
        raise DataFormatError(f"{path}: feature indices must be non-negative.")
    t, k = np.unique(t_all, return_inverse=True)
    n = int(idx.max()) + 1 if n_features is None else n_features
    if np.any(idx >= n):
        raise DataFormatError(f"{path}: a feature index is >= n_features = {n}.")
    pairs, first = np.unique(k * n + idx, return_index=True)
    if pairs.shape[0] < idx.shape[0]:
        dup = np.setdiff1d(np.arange(idx.shape[0]), first)[0]
        raise DataFormatError(
            f"{path}: line {rows[dup][0]} repeats feature {idx[dup]} at t = {t_all[dup]!r}."
        )
    try:
        if time_unit is not None:
            if time_unit not in TIME_UNITS:
                raise DataFormatError(
                    f"`time_unit` must be one of {', '.join(map(repr, TIME_UNITS))}; "
                    f"got {time_unit!r}."
                )
            t = t * TIME_UNITS[time_unit]
        _check_time_units(t, "t", declared=time_unit is not None)
    except DataFormatError as e:
        raise DataFormatError(f"{path}: {e}") from None
    need = t.shape[0] * n * 2 * 8  # the (N, n, 2) float64 pixels, before any allocation
    if need > max_data_bytes():
        raise DataFormatError(
            f"{path}: {t.shape[0]} times x {n} features (the largest feature index + 1) make "
            f"a {_size(need)} pixel array, above the limit of {_size(max_data_bytes())} "
            "(VISJAX_MAX_DATA_BYTES); number the features 0 to n - 1"
        )
    pixels = np.full((t.shape[0], n, 2), np.nan)
    pixels[k, idx] = uv
    return t, pixels


DROPPED_RESULT = "too_many_dropped_frames"
"""The result of a run that succeeded on a data file whose frames miss a feature in more than
`MAX_DROPPED_FRACTION` of them: the estimate rests mostly on held or extrapolated frames
(the name of `visjax.RESULTS`'s item)."""

DATA_FORMATS = {
    "velocity": VelocityData,
    "moving_point": MovingPointData,
    "static_points": StaticPointsData,
}
"""The data format of each registered problem that reads one of these formats, by the
problem's name (a user's problem reads a format of its own)."""


def coverage_line(fraction: float, frames: int) -> str:
    """`frames with a feature missing or held: 1500 of 2000 (75.0%)`, and past
    `MAX_DROPPED_FRACTION` what that makes of the result."""
    missing = int(round(fraction * frames))
    line = f"frames with a feature missing or held: {missing} of {frames} ({fraction:.1%})"
    if fraction > MAX_DROPPED_FRACTION:
        line += (
            f", more than visjax.io.MAX_DROPPED_FRACTION ({MAX_DROPPED_FRACTION:.0%}): the "
            "estimate rests mostly on held frames"
        )
    return line


def file_coverage(problem: str, path) -> tuple[float, int] | None:
    """`(dropped_fraction(), frames)` of a data file of the registered problem `problem`
    (a name of `DATA_FORMATS`); `None` for another problem (its format is its own)."""
    cls = DATA_FORMATS.get(problem)
    if cls is None:
        return None
    data = cls.load(path)
    return float(data.dropped_fraction()), int(np.shape(data.pixels)[0])


def dropped_report(problem: str, path) -> dict | None:
    """What a command reports of a data file's missing frames (`file_coverage`):
    `fraction`, `over` (above `MAX_DROPPED_FRACTION`), `result` (`DROPPED_RESULT`, the
    code it makes of a successful run) and the printed `line`; `None` without a file
    (`path` `None`) or for a problem whose format is its own."""
    cover = None if path is None else file_coverage(problem, path)
    if cover is None:
        return None
    fraction, frames = cover
    return {
        "fraction": fraction,
        "over": fraction > MAX_DROPPED_FRACTION,
        "result": DROPPED_RESULT,
        "line": coverage_line(fraction, frames),
    }
