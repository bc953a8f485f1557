import cv2
import jax
import numpy as np
import pytest

from tests.helpers import central_difference
from visjax import RESULTS
from visjax.geometry import (
    alpha_g33,
    euclidean_homography,
    find_homography,
    projective_homography,
)
from visjax.geometry._homography import _find_homography_checked
from visjax.sim import random_planar_scenes

find_j = jax.jit(find_homography)
find_batch = jax.jit(jax.vmap(find_homography))


@pytest.fixture(scope="module")
def scenes4():
    return random_planar_scenes(100, 4, seed=11)


@pytest.fixture(scope="module")
def scenes8():
    return random_planar_scenes(100, 8, seed=12)


def _rel(a, b):
    return np.max(np.abs(np.asarray(a) - b), axis=(-2, -1)) / np.max(np.abs(b), axis=(-2, -1))


@pytest.mark.parametrize("which", ["scenes4", "scenes8"])
def test_round_trip(which, request):
    sc = request.getfixturevalue(which)
    G = find_batch(sc.p_ref, sc.p_cur)
    assert np.max(_rel(G, sc.G_n)) < 1e-8
    np.testing.assert_allclose(G[:, 2, 2], 1.0, rtol=0)
    # alpha_i g33 of eq. (17)
    beta = jax.vmap(alpha_g33)(G, sc.p_ref)
    np.testing.assert_allclose(beta, sc.alpha * sc.g33[:, None], rtol=1e-8)
    # H = A^-1 G A (eq. (16)) and back
    H = jax.vmap(euclidean_homography)(G, sc.A)
    np.testing.assert_allclose(H * sc.g33[:, None, None], sc.H, atol=1e-8)
    np.testing.assert_allclose(jax.vmap(projective_homography)(H, sc.A), G, atol=1e-8)


@pytest.mark.parametrize("which", ["scenes4", "scenes8"])
def test_agrees_with_opencv(which, request):
    sc = request.getfixturevalue(which)
    # cv2.findHomography works on float32 points: give both the same, exactly representable.
    p_ref = sc.p_ref.astype(np.float32).astype(np.float64)
    p_cur = sc.p_cur.astype(np.float32).astype(np.float64)
    G = find_batch(p_ref, p_cur)
    G_cv = np.stack([cv2.findHomography(p_ref[i], p_cur[i], 0)[0] for i in range(len(sc))])
    if sc.p_ref.shape[1] == 4:
        assert np.max(_rel(G, G_cv)) < 1e-6
    else:
        # With more than 4 points, float32 rounding makes the data slightly inconsistent:
        # OpenCV refines the reprojection error, visjax solves the algebraic least squares.
        # Both transfer every point to the same pixel to far below the rounding.
        def transfer(G):
            q = np.einsum(
                "bij,bnj->bni", G, np.concatenate([p_ref, np.ones_like(p_ref[..., :1])], -1)
            )
            return q[..., :2] / q[..., 2:]

        assert np.max(np.abs(transfer(np.asarray(G)) - transfer(G_cv))) < 1e-4


def test_vmap_equals_loop_and_jit(scenes8):
    G = find_batch(scenes8.p_ref[:5], scenes8.p_cur[:5])
    for i in range(5):
        np.testing.assert_allclose(
            G[i], find_homography(scenes8.p_ref[i], scenes8.p_cur[i]), rtol=1e-11, atol=1e-13
        )


def test_gradient_matches_finite_differences(scenes8):
    p_ref, p_cur = scenes8.p_ref[0], scenes8.p_cur[0]
    f = lambda pc: find_homography(p_ref, pc)  # noqa: E731
    J = jax.jit(jax.jacrev(f))(p_cur)
    np.testing.assert_allclose(J, central_difference(f, p_cur, 1e-4), atol=1e-9)
    np.testing.assert_allclose(jax.jit(jax.jacfwd(f))(p_cur), J, atol=1e-13)


def test_gradient_at_symmetric_square_target():
    """The paper's noise-free four-corner target: singular values of the DLT repeat."""
    p_ref = np.array([[200.0, 200.0], [300.0, 200.0], [300.0, 300.0], [200.0, 300.0]])
    # each derivative compiled once, evaluated at the three points
    for f in (find_homography, _find_homography_of_current):
        jac = jax.jit(jax.jacrev(f))
        for p_cur in (p_ref, p_ref + np.array([10.0, -5.0]), p_ref * 1.1 + 3.0):
            x, other = (p_ref, p_cur) if f is find_homography else (p_cur, p_ref)
            J = jac(x, other)
            assert np.all(np.isfinite(J))
            np.testing.assert_allclose(J, central_difference(f, x, 1e-4, other), atol=1e-9)


def _find_homography_of_current(p_cur, p_ref):
    return find_homography(p_ref, p_cur)


def test_collinear_coincident_and_nonfinite_points():
    p_ref = np.array([[100.0, 100.0], [200.0, 120.0], [150.0, 300.0], [320.0, 280.0]])
    p_cur = p_ref + np.array([[3.0, 1.0], [2.0, -1.0], [-1.0, 2.0], [0.5, 0.5]])
    collinear = p_ref.copy()
    collinear[3] = collinear[0] + 2.5 * (collinear[1] - collinear[0])
    with pytest.raises(RuntimeError, match="collinear or coincident"):
        find_j(collinear, p_cur)
    coincident = p_ref.copy()
    coincident[2] = coincident[1]
    with pytest.raises(RuntimeError, match="collinear or coincident"):
        find_j(coincident, p_cur)
    # all four on one point: the normalisation itself degenerates
    with pytest.raises(RuntimeError, match="collinear or coincident"):
        find_j(np.ones((4, 2)), p_cur)
    bad = p_cur.copy()
    bad[1, 0] = np.nan
    with pytest.raises(RuntimeError, match="not finite"):
        find_j(p_ref, bad)
    G, result = _find_homography_checked(p_ref, bad)
    assert result == RESULTS.nonfinite_pixels and np.all(np.isnan(G))
    G, result = _find_homography_checked(collinear, p_cur)
    assert result == RESULTS.degenerate_points and np.all(np.isnan(G))


def test_near_collinear_points():
    """Three of four points on a line, the fourth off it by delta (in pixels)."""
    H_true = np.array([[1.02, 0.01, 5.0], [-0.02, 0.98, -3.0], [1e-5, -2e-5, 1.0]])

    def scene(delta):
        p_ref = np.array([[100.0, 100.0], [300.0, 100.0], [200.0, 300.0], [200.0, 100.0 + delta]])
        q = np.c_[p_ref, np.ones(4)] @ H_true.T
        return p_ref, q[:, :2] / q[:, 2:]

    # off the line by a fifth of a pixel: still well determined
    G = find_j(*scene(0.2))
    np.testing.assert_allclose(G, H_true, rtol=1e-8, atol=1e-10)
    # off the line by 1e-9 px: reported, not returned as garbage
    with pytest.raises(RuntimeError, match="collinear or coincident"):
        find_j(*scene(1e-9))


def test_shape_errors(no_jaxtyping):
    p = np.zeros((4, 2))
    with pytest.raises(ValueError, match="at least 4"):
        find_homography(p[:3], p[:3])
    with pytest.raises(ValueError, match="same points"):
        find_homography(np.zeros((5, 2)), p)
    with pytest.raises(ValueError, match=r"\(n, 2\)"):
        find_homography(np.zeros((4, 3)), np.zeros((4, 3)))
    with pytest.raises(ValueError, match=r"shape \(3, 3\)"):
        euclidean_homography(np.eye(4), np.eye(3))
