"""From pixel tracks (what `visjax track` writes) and a small file of the camera's
constants to a problem's data file: `data_from_tracks` (the command `visjax data`).

The camera file is YAML or JSON, one mapping. Every problem takes the intrinsics, as `A`
(3x3) or as `fx`, `fy`, `cx`, `cy` (and `skew`, default 0). Then, per problem:

- `velocity` (Chitrakaran et al.): `features`, the track indices of n >= 4 coplanar
  features, feature 1 first; or `coplanar: N` instead, to choose N tracks seen in every
  frame that follow one homography of the plane (`choose_coplanar`); or `tag: i`, the
  four corners of the AprilTag with id i of `visjax track --tags` (tracks 4 i to 4 i + 3),
  with `tag_size`, its side in m, as the known length (corners 0 and 1); `known_length`, two
  features a known distance apart: `[i, j, L]` (positions in `features`, L in m) or
  `{from_px: [u, v], to_px: [u, v], length_m: L}` (the chosen features nearest those
  pixels of the reference frame, where one knows what is what); `R_star`, the object's
  orientation at the reference frame (default the identity: the object frame's axes
  those of the camera then); `s1`, feature 1 in the object frame (default 0: the object
  frame's origin at feature 1); `K`, `rho` (optional gains).
- `moving_point` (Jang's thesis): `feature`, the track index of the point; `D`, the
  direction of the unknown input (the point's own motion, thesis eq. (3.1)); `depth_guess`
  (optional); `camera_velocity`, a file (NPZ with `t` and `velocity`, or CSV with columns
  `t, v_x, v_y, v_z, omega_x, omega_y, omega_z`) of the camera's measured velocity in its
  own frame, m/s and rad/s (in Python, also a mapping of those two arrays).
- `static_points` (Nath et al.): `known` and `unknown`, track indices; `known_features`,
  the known features' world positions (k, 3), m; `platform`, an NPZ file with the
  platform's pose at the frames (`platform_R` (N, 3, 3), `platform_x` (N, 3); in Python,
  also a mapping of those two arrays); the nominal mounting `R_c_nominal`, `x_c_nominal`
  (the intrinsics are `A_nominal`).

Every problem also takes `dist`, the lens' distortion coefficients (OpenCV's order, 4, 5,
8, 12 or 14 of them, with the intrinsics they were calibrated with): the data file keeps
the tracks as the lens saw them with `dist` beside them (its `load` undistorts them), and
`choose_coplanar` looks for the plane among the undistorted tracks.

A path in the camera file is relative to the camera file's folder. Every missing or
malformed entry is a `DataFormatError` naming it; the data file is then checked as every
data file is (`VelocityData.validate` and the others).
"""

import csv
import dataclasses
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import jax
import numpy as np

from ..geometry import DISTORTION_LENGTHS, undistort_pixels
from ._formats import (
    DataFormatError,
    MovingPointData,
    StaticPointsData,
    VelocityData,
    load_tracks_csv,
    read_npz,
)

PROBLEMS = ("velocity", "moving_point", "static_points")
"""The problems `data_from_tracks` writes a data file for."""

COPLANAR_PX = 2.0
"""`choose_coplanar`'s threshold: a track is on the plane when the homography fitted to
the plane's tracks maps its reference pixel within this many pixels of it in every
frame."""

_VELOCITY_COLUMNS = ("v_x", "v_y", "v_z", "omega_x", "omega_y", "omega_z")


def read_tracks(path) -> tuple[np.ndarray, np.ndarray]:
    """`(t (N,), pixels (N, n, 2))` of a tracks file: `.npz` with `t` and `pixels` (what
    `visjax track --out X.npz` writes) or `.csv` with `t, feature, u, v`."""
    path = Path(path)
    if path.suffix.lower() == ".csv":
        return load_tracks_csv(path)
    arrays = read_npz(path)
    missing = [k for k in ("t", "pixels") if k not in arrays]
    if missing:
        raise DataFormatError(f"{path}: a tracks file needs the keys t and pixels; no {missing}.")
    t, pixels = np.asarray(arrays["t"], float), np.asarray(arrays["pixels"], float)
    if pixels.ndim != 3 or pixels.shape[2] != 2 or t.shape != (pixels.shape[0],):
        raise DataFormatError(
            f"{path}: `pixels` must be (N, n, 2) and `t` (N,); got {pixels.shape}, {t.shape}."
        )
    return t, pixels


def read_camera_file(path) -> dict:
    """The mapping of a camera file, YAML (`.yaml`, `.yml`) or JSON (anything else)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise DataFormatError(f"{path}: cannot be read ({e.strerror or e}).") from None
    try:
        if path.suffix.lower() in (".yaml", ".yml"):
            import yaml

            content = yaml.safe_load(text)
        else:
            content = json.loads(text)
    except Exception as e:  # yaml.YAMLError, json.JSONDecodeError: the parser's own line
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise DataFormatError(f"{path}: not a readable camera file ({first}).") from None
    if not isinstance(content, dict):
        raise DataFormatError(f"{path}: a camera file holds one mapping of keys to values.")
    return content


def intrinsics(camera: Mapping[str, Any], where: str = "the camera file") -> np.ndarray:
    """The 3x3 intrinsic matrix of a camera mapping: `A`, or `fx`, `fy`, `cx`, `cy`
    (and `skew`)."""
    if "A" in camera:
        return _array(camera, "A", (3, 3), where)
    missing = [k for k in ("fx", "fy", "cx", "cy") if k not in camera]
    if missing:
        raise DataFormatError(f"{where}: the intrinsics are `A` or fx, fy, cx, cy; no {missing}.")
    fx, fy, cx, cy, skew = (float(camera.get(k, 0.0)) for k in ("fx", "fy", "cx", "cy", "skew"))
    return np.array([[fx, skew, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def choose_coplanar(
    pixels: np.ndarray, count: int, *, reference: int = 0, threshold_px: float = COPLANAR_PX
) -> list[int]:
    """`count` tracks of one plane: among the tracks seen in every frame, those that one
    homography per frame (OpenCV's RANSAC from the reference frame) maps within
    `threshold_px` in every frame, then `count` of them spread over the plane (the
    farthest-point order from the one nearest their centre), as track indices.

    **Raises:** `DataFormatError` when fewer than `count` (or 4) tracks qualify."""
    import cv2

    count = int(count)
    if count < 4:
        raise DataFormatError(f"`coplanar` must be at least 4 features; got {count}.")
    complete = np.flatnonzero(np.all(np.isfinite(pixels), axis=(0, 2)))
    if complete.size < count:
        raise DataFormatError(
            f"`coplanar: {count}`: only {complete.size} tracks are seen in every frame."
        )
    ref = pixels[reference, complete].astype(np.float64)
    inlier = np.ones(complete.size, bool)
    for k in range(pixels.shape[0]):
        if k == reference:
            continue
        H, _ = cv2.findHomography(ref, pixels[k, complete], cv2.RANSAC, threshold_px)
        if H is None:
            raise DataFormatError(f"`coplanar`: no homography fits frame {k}'s tracks.")
        mapped = cv2.perspectiveTransform(ref[:, None, :], H)[:, 0]
        inlier &= np.linalg.norm(mapped - pixels[k, complete], axis=1) <= threshold_px
    plane = complete[inlier]
    if plane.size < count:
        raise DataFormatError(
            f"`coplanar: {count}`: only {plane.size} tracks follow one homography within "
            f"{threshold_px:g} px in every frame."
        )
    at = pixels[reference, plane]
    chosen = [int(np.argmin(np.linalg.norm(at - at.mean(axis=0), axis=1)))]
    while len(chosen) < count:
        gap = np.min(np.linalg.norm(at[:, None] - at[chosen][None], axis=2), axis=1)
        chosen.append(int(np.argmax(gap)))
    return [int(plane[i]) for i in chosen]


def data_from_tracks(problem: str, tracks, camera, *, base: Path | None = None):
    """The data file of `problem` (`velocity`, `moving_point`, `static_points`) from pixel
    tracks and the camera's constants (the module docstring).

    **Arguments:** `tracks`: a tracks file (`read_tracks`) or `(t, pixels)`; `camera`: a
    camera file (YAML or JSON) or its mapping; `base`: the folder its paths are relative
    to (default the camera file's). **Returns:** a `VelocityData`, `MovingPointData` or
    `StaticPointsData`, validated; `.save(path)` writes it.

    **Raises:** `DataFormatError` naming what is missing or wrong."""
    if problem not in PROBLEMS:
        raise DataFormatError(f"no data file for problem {problem!r}; choose from {PROBLEMS}.")
    t, pixels = read_tracks(tracks) if isinstance(tracks, str | Path) else tracks
    t, pixels = np.asarray(t, float), np.asarray(pixels, float)
    where = "the camera file"
    if isinstance(camera, str | Path):
        base = Path(camera).parent if base is None else base
        where = str(camera)
        camera = read_camera_file(camera)
    base = Path(".") if base is None else Path(base)
    A = intrinsics(camera, where)
    dist = _distortion(camera, where)
    if problem == "velocity":
        ideal = pixels  # the plane is one homography of the undistorted tracks only
        if dist is not None:
            with jax.enable_x64(True):
                ideal = np.asarray(undistort_pixels(pixels, A, dist))
        data = _velocity(t, pixels, A, camera, where, ideal)
    else:
        build = {"moving_point": _moving_point, "static_points": _static}
        data = build[problem](t, pixels, A, camera, where, base)
    if dist is not None:
        data = dataclasses.replace(data, dist=dist)
    data.validate()
    return data


def _distortion(camera: Mapping, where: str) -> np.ndarray | None:
    if "dist" not in camera:
        return None
    given = camera["dist"]
    dist = np.asarray(given, float) if isinstance(given, list | tuple | np.ndarray) else None
    if dist is None or dist.ndim != 1 or dist.shape[0] not in DISTORTION_LENGTHS:
        raise DataFormatError(
            f"{where}: `dist` must be a list of 4, 5, 8, 12 or 14 numbers (OpenCV's order: "
            "k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4[, tau_x, tau_y]]]])."
        )
    if not np.all(np.isfinite(dist)):
        raise DataFormatError(f"{where}: `dist` has a value that is not finite.")
    return dist


def _velocity(t, pixels, A, camera, where, ideal) -> VelocityData:
    if sum(k in camera for k in ("features", "coplanar", "tag")) != 1:
        raise DataFormatError(
            f"{where}: the velocity problem needs one of `features`, `coplanar` or `tag`."
        )
    if "tag" in camera:  # an AprilTag's corners (visjax track --tags): features 4 i + c
        tag = _int(camera, "tag", where)
        features = [_track(pixels, 4 * tag + c, where) for c in range(4)]
        if "tag_size" in camera and "known_length" not in camera:
            size = _array(camera, "tag_size", (), where)
            camera = {**camera, "known_length": [0, 1, float(size)]}  # corners 0 and 1
    elif "coplanar" in camera:
        features = choose_coplanar(ideal, _int(camera, "coplanar", where))
    else:
        features = [_track(pixels, f, where) for f in _list(camera, "features", where)]
        if len(features) < 4:
            raise DataFormatError(f"{where}: `features` needs at least 4 tracks.")
    chosen = pixels[:, features]
    known = camera.get("known_length")
    if isinstance(known, Mapping):
        need = [k for k in ("from_px", "to_px", "length_m") if k not in known]
        if need:
            raise DataFormatError(f"{where}: `known_length` as a mapping needs {need}.")
        ref = chosen[0]

        def nearest(px):
            d = np.linalg.norm(ref - np.asarray(px, float), axis=1)
            return int(np.nanargmin(d))

        i, j = nearest(known["from_px"]), nearest(known["to_px"])
        if i == j:
            raise DataFormatError(f"{where}: `known_length`'s two pixels pick one feature.")
        length = np.array([i, j, float(known["length_m"])])
    elif known is not None:
        length = _array(camera, "known_length", (3,), where)
    else:
        raise DataFormatError(f"{where}: the velocity problem needs `known_length`.")
    optional = {k: _array(camera, k, (6,), where) for k in ("K", "rho") if k in camera}
    return VelocityData(
        t=t, pixels=chosen, A=A,
        R_star=_array(camera, "R_star", (3, 3), where) if "R_star" in camera else np.eye(3),
        s1=_array(camera, "s1", (3,), where) if "s1" in camera else np.zeros(3),
        known_length=length, **optional,
    )  # fmt: skip


def _moving_point(t, pixels, A, camera, where, base) -> MovingPointData:
    feature = _track(pixels, _need(camera, "feature", where), where)
    D = _array(camera, "D", (3,), where)
    given = _need(camera, "camera_velocity", where)
    if isinstance(given, Mapping):  # in Python: the arrays themselves (`import_bag`)
        camera_t, velocity = (np.asarray(given[k], float) for k in ("t", "velocity"))
    else:
        camera_t, velocity = _camera_velocity(base / str(given))
    optional = {}
    if "depth_guess" in camera:
        optional["depth_guess"] = np.asarray(float(camera["depth_guess"]))
    return MovingPointData(
        t=t, pixels=pixels[:, feature], A=A, camera_t=camera_t, camera_velocity=velocity, D=D,
        **optional,
    )  # fmt: skip


def _static(t, pixels, A, camera, where, base) -> StaticPointsData:
    known = [_track(pixels, f, where) for f in _list(camera, "known", where)]
    unknown = [_track(pixels, f, where) for f in _list(camera, "unknown", where)]
    given = _need(camera, "platform", where)
    if isinstance(given, Mapping):  # in Python: the arrays themselves (`import_bag`)
        platform_file, platform = where, given
    else:
        platform_file = base / str(given)
        platform = read_npz(platform_file)
    for key in ("platform_R", "platform_x"):
        if key not in platform:
            raise DataFormatError(f"{platform_file}: no `{key}` (the platform's pose).")
    return StaticPointsData(
        t=t, pixels=pixels[:, known + unknown],
        platform_R=np.asarray(platform["platform_R"], float),
        platform_x=np.asarray(platform["platform_x"], float),
        known_features=_array(camera, "known_features", (len(known), 3), where),
        A_nominal=A, R_c_nominal=_array(camera, "R_c_nominal", (3, 3), where),
        x_c_nominal=_array(camera, "x_c_nominal", (3,), where),
    )  # fmt: skip


def _camera_velocity(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """`(t (M,), velocity (M, 6))` of a camera-velocity file (NPZ or CSV)."""
    if path.suffix.lower() == ".csv":
        try:
            with path.open(newline="", encoding="utf-8-sig") as f:
                rows = list(csv.DictReader(f))
        except OSError as e:
            raise DataFormatError(f"{path}: cannot be read ({e.strerror or e}).") from None
        need = ["t", *_VELOCITY_COLUMNS]
        if not rows or any(c not in rows[0] for c in need):
            raise DataFormatError(f"{path}: expected the columns {', '.join(need)}.")
        try:
            table = np.array([[float(r[c]) for c in need] for r in rows])
        except ValueError as e:
            raise DataFormatError(f"{path}: a value is not a number ({e}).") from None
        return table[:, 0], table[:, 1:]
    arrays = read_npz(path)
    if "t" not in arrays or "velocity" not in arrays:
        raise DataFormatError(f"{path}: a camera-velocity NPZ needs `t` and `velocity`.")
    return np.asarray(arrays["t"], float), np.asarray(arrays["velocity"], float)


def _need(camera: Mapping, key: str, where: str):
    if key not in camera:
        raise DataFormatError(f"{where}: no `{key}`.")
    return camera[key]


def _array(camera: Mapping, key: str, shape: tuple, where: str) -> np.ndarray:
    try:
        a = np.asarray(camera[key], dtype=float)
    except KeyError:
        raise DataFormatError(f"{where}: no `{key}`.") from None
    except (TypeError, ValueError):
        raise DataFormatError(f"{where}: `{key}` must be numbers.") from None
    if a.shape != shape:
        raise DataFormatError(f"{where}: `{key}` must have shape {shape}; got {a.shape}.")
    if not np.all(np.isfinite(a)):
        raise DataFormatError(f"{where}: `{key}` has a value that is not finite.")
    return a


def _list(camera: Mapping, key: str, where: str) -> list:
    value = camera.get(key)
    if not isinstance(value, list) or not value:
        raise DataFormatError(f"{where}: `{key}` must be a non-empty list of track indices.")
    return value


def _int(camera: Mapping, key: str, where: str) -> int:
    value = camera.get(key)
    if isinstance(value, bool) or not isinstance(value, int):
        raise DataFormatError(f"{where}: `{key}` must be a whole number; got {value!r}.")
    return value


def _track(pixels: np.ndarray, index, where: str) -> int:
    if isinstance(index, bool) or not isinstance(index, int):
        raise DataFormatError(f"{where}: a track index must be a whole number; got {index!r}.")
    if not 0 <= index < pixels.shape[1]:
        raise DataFormatError(
            f"{where}: track {index} is not in the tracks file (tracks 0 to {pixels.shape[1] - 1})."
        )
    return index
