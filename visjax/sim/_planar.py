"""Random planar scenes for the Euclidean reconstruction of Chitrakaran et al., section 3.

A plane with unit normal $n^*$ at distance $d^*$ from the camera (eq. (4)) carries points
seen in a reference image; the plane then moves by $(\\bar R, \\bar x_f)$, so that
$\\bar m_i = \\bar R \\bar m_i^* + \\bar x_f$ (eq. (7)), and the points are seen again. Ground
truth follows the paper's definitions: $\\bar x_h = \\bar x_f / d^*$ (eq. (13)),
$H = \\bar R + \\bar x_h n^{*T}$ and $\\alpha_i = z_i^*/z_i$ (eq. (12)),
$G = A H A^{-1}$ (eq. (16)) and $g_{33} = G_{33}$ (eq. (17)).

This is test and demonstration data, made with NumPy and rejection sampling so that every
point is in front of both views and inside both images.
"""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PlanarScenes:
    """A batch of planar scenes; every array has the scene index first.

    **Fields:** `A` (B, 3, 3); `p_ref`, `p_cur` (B, n, 2) pixels (`p_cur` with noise, if
    any); `p_cur_clean` (B, n, 2); `R_bar` (B, 3, 3); `x_h` (B, 3); `n_star` (B, 3);
    `d_star` (B,); `alpha` (B, n); `H` (B, 3, 3) Euclidean; `G_n` (B, 3, 3) projective with
    $g_{33} = 1$; `g33` (B,).
    """

    A: np.ndarray
    p_ref: np.ndarray
    p_cur: np.ndarray
    p_cur_clean: np.ndarray
    R_bar: np.ndarray
    x_h: np.ndarray
    n_star: np.ndarray
    d_star: np.ndarray
    alpha: np.ndarray
    H: np.ndarray
    G_n: np.ndarray
    g33: np.ndarray

    def __len__(self) -> int:
        return self.A.shape[0]

    def __getitem__(self, i) -> "PlanarScenes":
        return PlanarScenes(**{k: v[i] for k, v in self.__dict__.items()})


def rotation_from_vector(omega: np.ndarray) -> np.ndarray:
    """Rodrigues' formula in NumPy (Chitrakaran et al., eq. (A.3)), for data generation."""
    theta = float(np.linalg.norm(omega))
    if theta == 0.0:
        return np.eye(3)
    u = omega / theta
    U = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
    return np.eye(3) + np.sin(theta) * U + 2.0 * np.sin(theta / 2.0) ** 2 * (U @ U)


def _unit(v):
    return v / np.linalg.norm(v)


def random_planar_scenes(
    n_scenes: int,
    n_points: int = 4,
    *,
    seed: int = 0,
    noise_px: float = 0.0,
    max_angle_deg: float = 30.0,
    translation: tuple[float, float] = (0.1, 0.4),
    max_tilt_deg: float = 40.0,
    image_size: tuple[int, int] = (640, 480),
) -> PlanarScenes:
    """Random planar scenes with random camera, plane, motion and points in the image.

    **Arguments:**

    - `n_scenes`: how many scenes.
    - `n_points`: points per scene (>= 4). With 4, they are jittered corners of a box, so
      that no three are close to collinear; with more, uniform in the image.
    - `seed`: NumPy seed.
    - `noise_px`: standard deviation of Gaussian pixel noise added to `p_cur`.
    - `max_angle_deg`: the rotation angle of $\\bar R$ is uniform in [0, this].
    - `translation`: $\\|\\bar x_h\\| = \\|\\bar x_f\\|/d^*$ is uniform in this range.
    - `max_tilt_deg`: the angle between $n^*$ and the optical axis is at most this.
    - `image_size`: (width, height) in pixels.
    """
    if n_points < 4:
        raise ValueError(f"`n_points` must be at least 4; got {n_points}.")
    rng = np.random.default_rng(seed)
    W, Hgt = image_size
    out = {k: [] for k in PlanarScenes.__dataclass_fields__}
    while len(out["A"]) < n_scenes:
        fx = rng.uniform(600.0, 1400.0)
        A = np.array(
            [
                [fx, 0.0, W / 2 + rng.uniform(-30, 30)],
                [0.0, fx * rng.uniform(0.95, 1.05), Hgt / 2 + rng.uniform(-30, 30)],
                [0.0, 0.0, 1.0],
            ]
        )
        tilt = np.deg2rad(rng.uniform(0.0, max_tilt_deg))
        phi = rng.uniform(0.0, 2 * np.pi)
        n_star = np.array([np.sin(tilt) * np.cos(phi), np.sin(tilt) * np.sin(phi), np.cos(tilt)])
        d_star = rng.uniform(1.0, 3.0)
        if n_points == 4:
            corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float)
            p_ref = np.array([W / 2, Hgt / 2]) + corners * np.array([W, Hgt]) * 0.25
            p_ref = p_ref + rng.uniform(-0.08, 0.08, (4, 2)) * np.array([W, Hgt])
        else:
            p_ref = rng.uniform([0.1 * W, 0.1 * Hgt], [0.9 * W, 0.9 * Hgt], (n_points, 2))
        m_ref = np.linalg.solve(A, np.c_[p_ref, np.ones(n_points)].T).T
        z_ref = d_star / (m_ref @ n_star)
        if np.any(z_ref <= 0):
            continue
        P_ref = m_ref * z_ref[:, None]
        angle = np.deg2rad(rng.uniform(0.0, max_angle_deg))
        R_bar = rotation_from_vector(angle * _unit(rng.normal(size=3)))
        x_h = _unit(rng.normal(size=3)) * rng.uniform(*translation)
        P_cur = P_ref @ R_bar.T + x_h * d_star
        z_cur = P_cur[:, 2]
        if np.any(z_cur <= 0.2):
            continue
        p_cur = (P_cur / z_cur[:, None]) @ A.T
        p_cur = p_cur[:, :2]
        if np.any(p_cur < 0) or np.any(p_cur[:, 0] > W) or np.any(p_cur[:, 1] > Hgt):
            continue
        H = R_bar + np.outer(x_h, n_star)
        G = A @ H @ np.linalg.inv(A)
        out["A"].append(A)
        out["p_ref"].append(p_ref)
        out["p_cur_clean"].append(p_cur)
        out["p_cur"].append(p_cur + noise_px * rng.normal(size=p_cur.shape))
        out["R_bar"].append(R_bar)
        out["x_h"].append(x_h)
        out["n_star"].append(n_star)
        out["d_star"].append(d_star)
        out["alpha"].append(z_ref / z_cur)
        out["H"].append(H)
        out["G_n"].append(G / G[2, 2])
        out["g33"].append(G[2, 2])
    return PlanarScenes(**{k: np.asarray(v) for k, v in out.items()})
