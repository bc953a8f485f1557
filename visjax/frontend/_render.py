"""Synthetic images of a tracked marker, for testing the KLT front end (NumPy, not jit)."""

import numpy as np


def render_marker(
    center: np.ndarray,
    shape: tuple[int, int] = (480, 640),
    *,
    sigma: float = 4.0,
    seed: int = 0,
) -> np.ndarray:
    """An 8-bit grey image: a bright Gaussian dot (a fiducial marker, as in the thesis'
    Figs. 5-3/5-4) at `center` = (u, v) pixels on a smooth textured background.

    Everything is a smooth function of the sub-pixel centre, so the image moves exactly
    with the marker up to the 8-bit quantisation.
    """
    rng = np.random.default_rng(seed)
    h, w = shape
    v, u = np.mgrid[0:h, 0:w].astype(float)
    k = rng.uniform(0.02, 0.06, (3, 2))
    phase = rng.uniform(0, 2 * np.pi, 3)
    background = 60 + sum(15 * np.sin(k[i, 0] * u + k[i, 1] * v + phase[i]) for i in range(3))
    dot = 150 * np.exp(-((u - center[0]) ** 2 + (v - center[1]) ** 2) / (2 * sigma**2))
    ring = 40 * np.exp(-((np.hypot(u - center[0], v - center[1]) - 3 * sigma) ** 2) / (2.0))
    return np.clip(background + dot + ring, 0, 255).round().astype(np.uint8)
