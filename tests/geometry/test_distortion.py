"""Lens distortion (`visjax.geometry.distort_pixels`, `undistort_pixels`) against OpenCV:
`cv2.projectPoints` forwards, `cv2.undistortPointsIter` backwards, for each length of
OpenCV's coefficient vector; the round trip; NaN where no point could have been seen."""

import cv2
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.helpers import central_difference
from visjax.geometry import DISTORTION_LENGTHS, distort_pixels, undistort_pixels

A = np.array([[800.0, 0.0, 320.0], [0.0, 790.0, 240.0], [0.0, 0.0, 1.0]])
# a wide-angle lens (k1 = -0.3), then the rational, thin-prism and tilt terms
FULL = np.array(
    [-0.3, 0.1, 1e-3, -5e-4, -0.02, 0.05, -0.01, 0.004, 1e-3, -2e-4, 5e-4, 1e-4, 0.01, -0.005]
)
RNG = np.random.default_rng(0)
PIXELS = np.stack([RNG.uniform(0, 640, 200), RNG.uniform(0, 480, 200)], axis=-1)


def _opencv_distorted(p, dist):
    m = np.linalg.solve(A, np.c_[p, np.ones(len(p))].T).T  # pinhole rays, z = 1
    out, _ = cv2.projectPoints(m, np.zeros(3), np.zeros(3), A, dist)
    return out[:, 0]


@pytest.mark.parametrize("n", DISTORTION_LENGTHS)
def test_distortion_agrees_with_opencv_both_ways(n):
    dist = FULL[:n]
    distorted = np.asarray(distort_pixels(PIXELS, A, dist))
    np.testing.assert_allclose(distorted, _opencv_distorted(PIXELS, dist), atol=1e-9)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    theirs = cv2.undistortPoints(distorted[:, None], A, dist, R=None, P=A, criteria=criteria)[:, 0]
    ours = np.asarray(undistort_pixels(distorted, A, dist))
    np.testing.assert_allclose(ours, theirs, atol=1e-6)  # OpenCV's fixed point, converged
    np.testing.assert_allclose(ours, PIXELS, atol=1e-9)  # and the round trip


def test_a_pixel_no_point_could_give_is_nan_never_a_guess():
    """Barrel distortion k1 = -0.3 maps the radius r to r (1 - 0.3 r^2), at most 0.703
    (normalized) at r = 1.054: a pixel beyond has no point; a NaN pixel stays NaN."""
    dist = np.array([-0.3, 0.0, 0.0, 0.0])
    p = np.array([[320.0 + 800 * 0.69, 240.0], [320.0 + 800 * 0.72, 240.0], [np.nan, 1.0]])
    out = np.asarray(undistort_pixels(p, A, dist))
    assert np.all(np.isfinite(out[0])) and np.all(np.isnan(out[1:]))
    r = (out[0, 0] - 320.0) / 800.0  # the physical (smaller) root of r (1 - 0.3 r^2) = 0.69
    assert r < 1.054 and abs(r * (1 - 0.3 * r * r) - 0.69) < 1e-12


def test_bad_coefficients_are_refused_with_the_lengths_allowed():
    with pytest.raises(ValueError, match="4, 5, 8, 12 or 14"):
        undistort_pixels(PIXELS, A, np.zeros(6))


def test_jit_vmap_and_grad_through_the_undistortion():
    dist = FULL[:5]
    d = np.asarray(distort_pixels(PIXELS[:8], A, dist))
    f = jax.jit(lambda k: jnp.sum(undistort_pixels(d, A, k) ** 2))
    g = jax.grad(f)(jnp.asarray(dist))
    fd = central_difference(f, np.asarray(dist), 1e-7)
    np.testing.assert_allclose(g, fd, rtol=1e-5)
    batched = jax.vmap(undistort_pixels, in_axes=(0, None, None))(d[None].repeat(3, 0), A, dist)
    np.testing.assert_allclose(batched[2], PIXELS[:8], atol=1e-9)
