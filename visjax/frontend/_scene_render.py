"""Camera views of textured planes by projective warps, for testing the tracking front end
(NumPy and OpenCV, never jit).

Convention (every function here):

- Image pixels: OpenCV's, the centre of pixel (row v, column u) at $(u, v)$; a point is
  written $(u, v)$ = (column, row).
- Camera: intrinsics `K` (3 x 3, pixels), pose `R_world_cam` (3 x 3) and `p_world_cam`
  (3,); the camera frame's $z$ is the optical axis, and a world point $w$ is at
  $R_{world,cam}^T (w - p_{world,cam})$ in the camera frame.
- Planes: a texture (uint8 grey, H x W) of `scale` metres per texture pixel, placed at
  `T_world_plane` (4 x 4). Texture pixel (row i, column j) covers the plane square
  $[j s, (j + 1) s] \\times [i s, (i + 1) s]$ at $z = 0$, so its centre is at
  $x = (j + 0.5) s$, $y = (i + 0.5) s$: the texture's corner (not its centre) is the
  plane's origin, its rows run along the plane's $y$ and its columns along $x$.
  Texture coordinates $(x_t, y_t)$ follow the image convention (pixel centres at integers),
  so the plane point is $(x, y) = s\\,(x_t + 0.5, y_t + 0.5)$.
- Lens: `dist` (optional), OpenCV's distortion coefficients (`visjax.geometry.distort_pixels`):
  the view and the projected points are those of a camera with that lens; without it, of
  a pinhole camera.
"""

import functools
from dataclasses import dataclass

import jax
import numpy as np

from ..geometry import distort_pixels, undistort_pixels


def _pose(T, name):
    T = np.asarray(T, float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"`{name}` must be a finite (4, 4) pose; got shape {T.shape}.")
    R = T[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise ValueError(f"`{name}`'s rotation block is not a rotation.")
    return T


def _camera(K, R_world_cam, p_world_cam):
    K = np.asarray(K, float)
    R = np.asarray(R_world_cam, float)
    p = np.asarray(p_world_cam, float)
    if K.shape != (3, 3) or R.shape != (3, 3) or p.shape != (3,):
        raise ValueError(
            "expected K (3, 3), R_world_cam (3, 3) and p_world_cam (3,); "
            f"got {K.shape}, {R.shape}, {p.shape}."
        )
    if not (np.all(np.isfinite(K)) and np.all(np.isfinite(R)) and np.all(np.isfinite(p))):
        raise ValueError("K, R_world_cam and p_world_cam must be finite.")
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise ValueError("`R_world_cam` is not a rotation.")
    return K, R, p


@dataclass(frozen=True)
class Plane:
    """A textured rectangle in the world.

    **Arguments:**

    - `texture`: (H, W) uint8 grey image.
    - `scale`: metres per texture pixel (positive).
    - `T_world_plane`: (4, 4) pose of the plane's frame in the world.

    Convention: texture pixel (i, j) has its centre at plane coordinates
    $((j + 0.5) s, (i + 0.5) s, 0)$ (see the module docstring).
    """

    texture: np.ndarray
    scale: float
    T_world_plane: np.ndarray

    def __post_init__(self):
        tex = np.asarray(self.texture)
        if tex.ndim != 2 or tex.dtype != np.uint8 or min(tex.shape) < 1:
            raise ValueError(
                f"`texture` must be a non-empty (H, W) uint8 image; got {tex.shape} {tex.dtype}."
            )
        if not (np.isfinite(self.scale) and self.scale > 0):
            raise ValueError(f"`scale` must be a positive number of metres; got {self.scale}.")
        object.__setattr__(self, "texture", tex)
        object.__setattr__(self, "scale", float(self.scale))
        object.__setattr__(self, "T_world_plane", _pose(self.T_world_plane, "T_world_plane"))

    @property
    def S(self) -> np.ndarray:
        """(3, 3) map from homogeneous texture coordinates to plane coordinates (metres)."""
        s = self.scale
        return np.array([[s, 0.0, 0.5 * s], [0.0, s, 0.5 * s], [0.0, 0.0, 1.0]])

    def corners_texture(self) -> np.ndarray:
        """(4, 2) the texture's outer corners in texture coordinates (x_t, y_t): top-left,
        top-right, bottom-right, bottom-left (clockwise in the image, as ArUco orders)."""
        h, w = self.texture.shape
        return np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]])

    def world_points(self, xy_texture) -> np.ndarray:
        """World points (n, 3) of texture coordinates `xy_texture` (n, 2) = (x_t, y_t)."""
        xy = np.asarray(xy_texture, float).reshape(-1, 2)
        plane = (xy + 0.5) * self.scale
        local = np.concatenate([plane, np.zeros((len(xy), 1)), np.ones((len(xy), 1))], axis=1)
        return (local @ self.T_world_plane.T)[:, :3]


def project_points(K, R_world_cam, p_world_cam, points, *, dist=None) -> np.ndarray:
    """Pixels of world points seen by a pinhole camera (with `dist`, through that lens).

    **Arguments:** `K` (3, 3); `R_world_cam` (3, 3); `p_world_cam` (3,); `points` (n, 3)
    world points; `dist` OpenCV's distortion coefficients, or `None` (a pinhole).

    **Returns:** (n, 2) pixels $(u, v)$; NaN for a point on or behind the camera's plane
    ($z \\le 0$ in the camera frame).

    Convention: $m = K\\, R_{world,cam}^T (w - p_{world,cam})$, $(u, v) = (m_1, m_2) / m_3$,
    pixel centres at integers (OpenCV's).
    """
    K, R, p = _camera(K, R_world_cam, p_world_cam)
    w = np.asarray(points, float)
    if w.ndim != 2 or w.shape[1] != 3:
        raise ValueError(f"`points` must be (n, 3); got {w.shape}.")
    cam = (w - p) @ R
    m = cam @ K.T
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = m[:, :2] / m[:, 2:]
    uv[cam[:, 2] <= 0] = np.nan
    if dist is not None:
        with jax.enable_x64(True):
            uv = np.asarray(distort_pixels(uv, K, np.asarray(dist, float)))
    return uv


def plane_homography(plane: Plane, K, R_world_cam, p_world_cam) -> np.ndarray:
    """The homography from the plane's texture coordinates to image pixels.

    **Arguments:** `plane` a `Plane`; the camera `K`, `R_world_cam`, `p_world_cam`.

    **Returns:** $H = K [r_1\\ r_2\\ t] S$ (3, 3), with $(R, t)$ the plane's pose in the
    camera frame and $S$ = `plane.S`; not normalised, so that the third homogeneous
    coordinate of $H x$ is positive exactly for texture points in front of the camera.

    Raises `ValueError` when the camera centre lies in the plane (edge-on view: the plane
    projects onto a line and $H$ is singular).
    """
    K, R_wc, p_wc = _camera(K, R_world_cam, p_world_cam)
    T = plane.T_world_plane
    R_cp = R_wc.T @ T[:3, :3]
    t_cp = R_wc.T @ (T[:3, 3] - p_wc)
    # distance from the camera centre to the plane, n . t in the camera frame
    distance = abs(R_cp[:, 2] @ t_cp)
    extent = plane.scale * max(plane.texture.shape)
    if distance <= 1e-9 * max(extent, np.linalg.norm(t_cp)):
        raise ValueError("the camera centre lies in the plane (edge-on view).")
    return K @ np.column_stack([R_cp[:, 0], R_cp[:, 1], t_cp]) @ plane.S


def render_planes(
    planes,
    K,
    R_world_cam,
    p_world_cam,
    shape: tuple[int, int] = (480, 640),
    *,
    background=0.0,
    supersample: int = 4,
    dist=None,
) -> np.ndarray:
    """Render a camera view of textured planes, composited in order (later on top).

    **Arguments:**

    - `planes`: a sequence of `Plane`.
    - `K`, `R_world_cam`, `p_world_cam`: the camera (module docstring's convention).
    - `shape`: (H, W) of the image.
    - `background`: grey level where no plane is seen.
    - `supersample`: the image is rendered at this factor in each direction with
      `cv2.warpPerspective` (bilinear texture sampling) and downsampled with
      `cv2.INTER_AREA`: the anti-aliasing (a box filter over `supersample`$^2$ samples).
      The texture itself is not prefiltered, so a texture much finer than a supersampled
      pixel still aliases: keep textures smooth at the scale they are seen.
    - `dist`: OpenCV's distortion coefficients of the lens, or `None` (a pinhole): the
      pinhole view is rendered, then each supersampled pixel of the lens' view takes the
      pinhole view's value where `visjax.geometry.undistort_pixels` sends it (bilinear);
      a pixel the lens model cannot have produced shows `background`.

    **Returns:** (H, W) uint8 image.

    Each plane is warped by `plane_homography` with its coverage mask (premultiplied, so
    its edges are anti-aliased too). Honest skips: a plane entirely behind the camera and a
    plane seen edge-on are not drawn (neither is visible); a plane that crosses the
    camera's plane is drawn only where the viewing ray meets it in front of the camera
    (the sign of the homogeneous coordinate), never mirrored from behind.
    """
    import cv2

    K, R, p = _camera(K, R_world_cam, p_world_cam)
    h, w = (int(x) for x in shape)
    f = int(supersample)
    if h < 1 or w < 1 or f < 1:
        raise ValueError(f"`shape` and `supersample` must be positive; got {shape}, {f}.")
    # a low-resolution pixel centre u covers the supersampled centres f u ... f u + f - 1
    A = np.array([[f, 0.0, 0.5 * (f - 1)], [0.0, f, 0.5 * (f - 1)], [0.0, 0.0, 1.0]])
    H_img, W_img = h * f, w * f
    out = np.full((H_img, W_img), float(background), np.float32)
    for plane in planes:
        if not isinstance(plane, Plane):
            raise ValueError(f"`planes` must hold `Plane`s; got {type(plane).__name__}.")
        corners = plane.world_points(plane.corners_texture())
        depth = (corners - p) @ R[:, 2]
        if np.all(depth <= 0):
            continue  # behind the camera: not visible
        try:
            H = A @ plane_homography(plane, K, R, p)
        except ValueError:
            continue  # edge-on: a line of zero area
        H_inv = np.linalg.inv(H)
        th, tw = plane.texture.shape
        src = np.dstack([plane.texture.astype(np.float32), np.ones((th, tw), np.float32)])
        warped = cv2.warpPerspective(
            src,
            H_inv,
            (W_img, H_img),
            flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=0,
        )
        value, cover = warped[..., 0], warped[..., 1]
        if np.any(depth <= 0):
            # the ray through pixel x meets the plane in front iff (H^-1 x)_3 > 0
            v_grid, u_grid = np.mgrid[0:H_img, 0:W_img].astype(np.float32)
            c = H_inv[2, 0] * u_grid + H_inv[2, 1] * v_grid + H_inv[2, 2]
            front = (c > 0).astype(np.float32)
            value, cover = value * front, cover * front
        out = out * (1.0 - cover) + value
    if dist is not None:
        map_u, map_v = _lens_map(K.tobytes(), np.asarray(dist, float).tobytes(), h, w, f)
        out = cv2.remap(
            out, map_u, map_v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
            borderValue=float(background),
        )  # fmt: skip
    low = cv2.resize(out, (w, h), interpolation=cv2.INTER_AREA) if f > 1 else out
    return np.clip(np.rint(low), 0, 255).astype(np.uint8)


@functools.lru_cache(maxsize=4)
def _lens_map(K_bytes: bytes, dist_bytes: bytes, h: int, w: int, f: int):
    """For each supersampled pixel of a lens' view, where the pinhole view shows its point
    (`cv2.remap`'s maps, float32; -1 where the lens model has no point): once per camera,
    lens and size."""
    K = np.frombuffer(K_bytes).reshape(3, 3)
    dist = np.frombuffer(dist_bytes)
    v, u = np.mgrid[0 : h * f, 0 : w * f].astype(float)
    low = np.stack([(u - 0.5 * (f - 1)) / f, (v - 0.5 * (f - 1)) / f], axis=-1)
    with jax.enable_x64(True):
        ideal = np.asarray(undistort_pixels(low, K, dist))
    ideal = np.where(np.isfinite(ideal), f * ideal + 0.5 * (f - 1), -1.0).astype(np.float32)
    return ideal[..., 0], ideal[..., 1]


def textured_table(shape: tuple[int, int] = (480, 640), seed: int = 0) -> np.ndarray:
    """A random smooth texture with many corners (for `cv2.goodFeaturesToTrack`).

    **Arguments:** `shape` (H, W) texture pixels; `seed` the NumPy seed.

    **Returns:** (H, W) uint8: white noise blurred at 1.5, 3 and 6 texture pixels, summed
    with weights and stretched to the grey levels 20-235. Smooth at about 1.5 texture
    pixels, so it renders without aliasing wherever a texture pixel covers at least about
    half an image pixel.
    """
    import cv2

    rng = np.random.default_rng(seed)
    h, w = (int(x) for x in shape)
    if h < 1 or w < 1:
        raise ValueError(f"`shape` must be positive; got {shape}.")
    total = np.zeros((h, w), np.float32)
    for sigma, weight in ((1.5, 0.6), (3.0, 1.0), (6.0, 1.0)):
        noise = rng.standard_normal((h, w)).astype(np.float32)
        blurred = cv2.GaussianBlur(noise, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
        total += weight * blurred / max(float(blurred.std()), 1e-12)
    lo, hi = np.percentile(total, [1, 99])
    return np.clip(20 + 215 * (total - lo) / (hi - lo), 0, 255).round().astype(np.uint8)


_ARUCO_DICTIONARY = "DICT_4X4_50"

TAG_FAMILIES = ("16h5", "25h9", "36h10", "36h11")
"""The AprilTag families OpenCV's ArUco module draws and detects (`DICT_APRILTAG_*`): a
family's name stands for its dictionary wherever a dictionary is asked for."""


def _aruco_dictionary(name: str):
    import cv2

    if name in TAG_FAMILIES:
        name = f"DICT_APRILTAG_{name}"
    code = getattr(cv2.aruco, name, None) if isinstance(name, str) else None
    if not isinstance(code, int) or not name.startswith("DICT_"):
        raise ValueError(
            f"unknown ArUco dictionary {name!r} (e.g. 'DICT_4X4_50', or an AprilTag family: "
            f"{', '.join(TAG_FAMILIES)})."
        )
    return cv2.aruco.getPredefinedDictionary(code)


def fiducial_marker(
    marker_id: int = 0,
    *,
    cell: int = 16,
    border_cells: int = 1,
    dictionary: str = _ARUCO_DICTIONARY,
) -> tuple[np.ndarray, np.ndarray]:
    """An ArUco marker (or AprilTag) texture with a white quiet zone.

    **Arguments:** `marker_id` in the dictionary; `cell` texture pixels per marker cell;
    `border_cells` the width of the white border in cells; `dictionary` the name of a
    `cv2.aruco` predefined dictionary, or an AprilTag family (`TAG_FAMILIES`: `"36h11"`
    draws the tag `marker_id` of the 36h11 family).

    **Returns:** `(texture, corners)`: the (H, W) uint8 texture (black 0, white 255) and
    (4, 2) the black square's outer corners in texture coordinates (x_t, y_t), top-left,
    top-right, bottom-right, bottom-left, the order in which `cv2.aruco` reports them.
    Map them to the world with `Plane.world_points`.
    """
    import cv2

    d = _aruco_dictionary(dictionary)
    bits = d.markerSize + 2  # the code cells and the black frame
    cell, border_cells = int(cell), int(border_cells)
    if cell < 1 or border_cells < 1:
        raise ValueError("`cell` and `border_cells` must be positive.")
    if not 0 <= int(marker_id) < d.bytesList.shape[0]:
        raise ValueError(f"`marker_id` {marker_id} is not in {dictionary}.")
    side = bits * cell
    marker = cv2.aruco.generateImageMarker(d, int(marker_id), side)
    b = border_cells * cell
    texture = np.full((side + 2 * b, side + 2 * b), 255, np.uint8)
    texture[b : b + side, b : b + side] = marker
    lo, hi = b - 0.5, b + side - 0.5
    corners = np.array([[lo, lo], [hi, lo], [hi, hi], [lo, hi]])
    return texture, corners
