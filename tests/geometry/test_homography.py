import cv2
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.helpers import central_difference
from visjax import RESULTS, result_names
from visjax.geometry import (
    Homography,
    alpha_g33,
    euclidean_homography,
    find_homography,
    projective_homography,
)
from visjax.sim import random_planar_scenes


def _G(p_ref, p_cur):
    return find_homography(p_ref, p_cur).G


find_j = jax.jit(find_homography)
find_batch = jax.jit(jax.vmap(_G))
find_batch_unchecked = jax.jit(jax.vmap(lambda a, b: find_homography(a, b, throw=False)))


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
            G[i], find_homography(scenes8.p_ref[i], scenes8.p_cur[i]).G, rtol=1e-11, atol=1e-13
        )


def test_gradient_matches_finite_differences(scenes8):
    p_ref, p_cur = scenes8.p_ref[0], scenes8.p_cur[0]
    f = lambda pc: find_homography(p_ref, pc).G  # noqa: E731
    J = jax.jit(jax.jacrev(f))(p_cur)
    np.testing.assert_allclose(J, central_difference(f, p_cur, 1e-4), atol=1e-9)
    np.testing.assert_allclose(jax.jit(jax.jacfwd(f))(p_cur), J, atol=1e-13)


def test_gradient_at_symmetric_square_target():
    """The paper's noise-free four-corner target: singular values of the DLT repeat."""
    p_ref = np.array([[200.0, 200.0], [300.0, 200.0], [300.0, 300.0], [200.0, 300.0]])
    # each derivative compiled once, evaluated at the three points
    for f in (_G, _find_homography_of_current):
        jac = jax.jit(jax.jacrev(f))
        for p_cur in (p_ref, p_ref + np.array([10.0, -5.0]), p_ref * 1.1 + 3.0):
            x, other = (p_ref, p_cur) if f is _G else (p_cur, p_ref)
            J = jac(x, other)
            assert np.all(np.isfinite(J))
            np.testing.assert_allclose(J, central_difference(f, x, 1e-4, other), atol=1e-9)


def _find_homography_of_current(p_cur, p_ref):
    return find_homography(p_ref, p_cur).G


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
    out = find_homography(p_ref, bad, throw=False)
    assert out.result == RESULTS.nonfinite_pixels and np.all(np.isnan(out.G))
    out = find_homography(collinear, p_cur, throw=False)
    assert out.result == RESULTS.degenerate_points and np.all(np.isnan(out.G))


@pytest.mark.parametrize("bad", ["collinear", "nan"])
def test_a_batch_survives_one_degenerate_frame(scenes4, bad):
    """`throw=False` under `vmap`: one degenerate frame of 8 gets its result code and an
    all-NaN `G`, and the 7 others are what each gives alone (where `throw=True` on the bad
    frame raises, for it alone and so for any batch that holds it)."""
    p_ref, p_cur = np.array(scenes4.p_ref[:8]), np.array(scenes4.p_cur[:8])
    k = 5
    if bad == "collinear":
        p_ref[k, 3] = p_ref[k, 0] + 2.5 * (p_ref[k, 1] - p_ref[k, 0])
        code, cause = RESULTS.degenerate_points, "collinear or coincident"
    else:
        p_cur[k, 2, 1] = np.nan
        code, cause = RESULTS.nonfinite_pixels, "not finite"
    out = find_batch_unchecked(p_ref, p_cur)
    assert isinstance(out, Homography) and out.G.shape == (8, 3, 3)
    names = result_names(out.result)
    assert names[k] == result_names(code)
    assert np.all(np.isnan(np.asarray(out.G[k])))
    for i in range(8):
        if i == k:
            continue
        assert names[i] == "successful", (i, names)
        alone = find_j(p_ref[i], p_cur[i])
        # the same type, whatever `throw` says
        assert jax.tree_util.tree_structure(alone) == jax.tree_util.tree_structure(
            jax.tree_util.tree_map(lambda x: x[i], out)
        )
        np.testing.assert_allclose(out.G[i], alone.G, rtol=1e-10, atol=1e-10)
    with pytest.raises(Exception, match=cause):
        jax.block_until_ready(find_j(p_ref[k], p_cur[k]))


def _loss(p_cur, p_ref, weight):
    return jnp.sum(weight * find_homography(p_ref, p_cur, throw=False).G)


def test_jit_and_grad_with_throw_false(scenes8):
    """`throw=False` under `jit` gives the value of `throw=True`, and its gradient agrees
    with a central difference; on a failed frame the gradient is finite (zero)."""
    p_ref, p_cur = scenes8.p_ref[0], scenes8.p_cur[0]
    weight = np.random.default_rng(0).normal(size=(3, 3))
    out = jax.jit(lambda a, b: find_homography(a, b, throw=False))(p_ref, p_cur)
    assert out.result == RESULTS.successful
    np.testing.assert_allclose(out.G, find_homography(p_ref, p_cur).G, rtol=1e-12, atol=1e-12)
    grad = jax.jit(jax.grad(_loss))
    g = np.asarray(grad(p_cur, p_ref, weight))
    fd = central_difference(_loss, p_cur, 1e-3, p_ref, weight)
    assert np.max(np.abs(g - fd)) < 1e-6 * np.max(np.abs(fd))
    bad = np.array(p_cur)
    bad[3, 0] = np.nan
    assert np.all(np.asarray(grad(bad, p_ref, weight)) == 0.0)


def test_near_collinear_points():
    """Three of four points on a line, the fourth off it by delta (in pixels)."""
    H_true = np.array([[1.02, 0.01, 5.0], [-0.02, 0.98, -3.0], [1e-5, -2e-5, 1.0]])

    def scene(delta):
        p_ref = np.array([[100.0, 100.0], [300.0, 100.0], [200.0, 300.0], [200.0, 100.0 + delta]])
        q = np.c_[p_ref, np.ones(4)] @ H_true.T
        return p_ref, q[:, :2] / q[:, 2:]

    # off the line by a fifth of a pixel: still well determined
    G = find_j(*scene(0.2)).G
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
