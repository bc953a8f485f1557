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

Conventions of eq. (5) of Nath et al.: a world point $w$ is at
$R_c^T(R_b^T(w - x_b) - x_c)$ in the camera frame.
"""

import csv
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np


class DataFormatError(ValueError):
    """A data file does not follow its documented format (the message says what)."""


def _rotation_ok(R) -> bool:
    R = np.asarray(R)
    eye = np.broadcast_to(np.eye(3), R.shape)
    return bool(
        np.all(np.isfinite(R))
        and np.allclose(np.swapaxes(R, -1, -2) @ R, eye, atol=1e-6)
        and np.all(np.linalg.det(R) > 0)
    )


class _Format:
    """Shared load/save/validate for a dataclass of NumPy arrays."""

    REQUIRED: tuple[str, ...] = ()
    NAME = ""

    @classmethod
    def load(cls, path):
        """Read and validate a `.npz` file; a missing required key, a wrong shape or a bad
        value raises `DataFormatError` naming the key."""
        path = Path(path)
        if not path.exists():
            raise DataFormatError(f"{path}: no such file.")
        try:
            with np.load(path, allow_pickle=False) as z:
                arrays = {k: np.asarray(z[k]) for k in z.files}
        except (OSError, ValueError) as e:
            raise DataFormatError(f"{path}: not a readable .npz file ({e}).") from None
        missing = [k for k in cls.REQUIRED if k not in arrays]
        if missing:
            raise DataFormatError(
                f"{path}: the {cls.NAME} format needs the keys {list(cls.REQUIRED)}; "
                f"missing {missing}."
            )
        known = {f.name for f in fields(cls)}
        data = cls(**{k: v for k, v in arrays.items() if k in known})
        data.validate()
        return data

    def save(self, path) -> Path:
        """Write the arrays that are not `None` to a `.npz` file (validated first)."""
        self.validate()
        path = Path(path)
        arrays = {f.name: getattr(self, f.name) for f in fields(self)}
        np.savez(path, **{k: np.asarray(v) for k, v in arrays.items() if v is not None})
        return path

    def _shape(self, key, shape):
        v = getattr(self, key)
        if v is None:
            return
        v = np.asarray(v)
        ok = v.ndim == len(shape) and all(s is None or s == d for s, d in zip(shape, v.shape))
        if not ok:
            want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
            raise DataFormatError(f"`{key}` must have shape {want}; got {v.shape}.")
        if not np.issubdtype(v.dtype, np.number):
            raise DataFormatError(f"`{key}` must be numeric; got {v.dtype}.")

    def _finite(self, *keys):
        for key in keys:
            v = getattr(self, key)
            if v is not None and not np.all(np.isfinite(v)):
                raise DataFormatError(f"`{key}` must be finite (NaN is allowed in pixels only).")

    def _times(self, key="t"):
        t = np.asarray(getattr(self, key))
        if t.shape[0] < 2 or not np.all(np.diff(t) > 0):
            raise DataFormatError(f"`{key}` must hold at least 2 strictly increasing times.")


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

    REQUIRED = ("t", "pixels", "A", "R_star", "s1", "known_length")
    NAME = "velocity"

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
        self._times()
        self._finite("t", "A", "R_star", "s1", "known_length", "velocity", "K", "rho")
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
        ref = self.pixels[0] if self.reference_pixels is None else self.reference_pixels
        if not np.all(np.isfinite(ref)):
            raise DataFormatError(
                "the reference image (frame 0, or `reference_pixels`) must show every feature."
            )
        for key in ("K", "rho"):
            v = getattr(self, key)
            if v is not None and not np.all(np.asarray(v) > 0):
                raise DataFormatError(f"`{key}` must be positive.")

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

    REQUIRED = ("t", "pixels", "A", "camera_t", "camera_velocity", "D")
    NAME = "structure"

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
        self._times()
        self._times("camera_t")
        self._finite("t", "A", "camera_t", "camera_velocity", "D", "position", "depth_guess")
        if self.depth_guess is not None and not float(self.depth_guess) > 0:
            raise DataFormatError(f"`depth_guess` must be positive; got {self.depth_guess}.")
        if not np.linalg.norm(self.D) > 0:
            raise DataFormatError("`D` must be a nonzero direction.")
        if not np.all(np.isfinite(np.asarray(self.pixels)[0])):
            raise DataFormatError("the first frame must show the point (`pixels[0]` finite).")
        if np.asarray(self.camera_t)[0] > np.asarray(self.t)[0]:
            raise DataFormatError(
                "the camera velocity must be known from the first frame on: `camera_t[0]` > `t[0]`."
            )


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
    NAME = "euclidean"

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


def load_tracks_csv(path, n_features: int | None = None):
    """The inverse of `save_tracks_csv`: `(t (N,), pixels (N, n, 2))`, NaN where a feature
    has no row at a time. `n_features` fixes n (default: the largest index + 1)."""
    path = Path(path)
    try:
        with path.open(newline="") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        raise DataFormatError(f"{path}: {e}") from None
    if not rows or set(rows[0]) != {"t", "feature", "u", "v"}:
        raise DataFormatError(f"{path}: expected the columns t, feature, u, v.")
    try:
        t_all = np.array([float(r["t"]) for r in rows])
        idx = np.array([int(r["feature"]) for r in rows])
        uv = np.array([[float(r["u"]), float(r["v"])] for r in rows])
    except ValueError as e:
        raise DataFormatError(f"{path}: a value is not a number ({e}).") from None
    if np.any(idx < 0):
        raise DataFormatError(f"{path}: feature indices must be non-negative.")
    t, k = np.unique(t_all, return_inverse=True)
    n = int(idx.max()) + 1 if n_features is None else n_features
    if np.any(idx >= n):
        raise DataFormatError(f"{path}: a feature index is >= n_features = {n}.")
    pixels = np.full((t.shape[0], n, 2), np.nan)
    pixels[k, idx] = uv
    return t, pixels
