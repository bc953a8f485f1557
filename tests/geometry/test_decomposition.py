import cv2
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.helpers import central_difference
from visjax.geometry import (
    decompose_homography,
    decompose_homography_known_normal,
    select_solution,
    so3_exp,
)
from visjax.sim import random_planar_scenes

decompose_batch = jax.jit(jax.vmap(decompose_homography))
decompose_euclid = jax.jit(jax.vmap(lambda H: decompose_homography(H)))


@pytest.fixture(scope="module")
def scenes():
    return random_planar_scenes(100, 4, seed=21)


def _match_sets(ours, theirs, count):
    """Largest distance from each of OpenCV's solutions to the nearest of ours."""
    R, t, n = ours
    Rc, tc, nc = theirs
    worst = 0.0
    for j in range(count):
        d = [
            max(
                np.max(np.abs(Rc[j] - R[k])),
                np.max(np.abs(tc[j].ravel() - t[k])),
                np.max(np.abs(nc[j].ravel() - n[k])),
            )
            for k in range(4)
        ]
        worst = max(worst, min(d))
    return worst


def test_solution_set_matches_opencv(scenes):
    R, t, n = decompose_batch(scenes.G_n, scenes.A)
    for i in range(len(scenes)):
        count, Rc, tc, nc = cv2.decomposeHomographyMat(scenes.G_n[i], scenes.A[i])
        assert count == 4
        assert _match_sets((R[i], t[i], n[i]), (Rc, tc, nc), count) < 1e-6
        # and each of ours is one of OpenCV's
        cv = (np.stack(Rc), np.stack(tc)[..., 0], np.stack(nc)[..., 0])
        assert _match_sets(cv, (R[i], t[i], n[i]), 4) < 1e-6


def test_invariants_and_ground_truth(scenes):
    # any scale and sign of the input
    scale = np.linspace(-3.0, 3.0, len(scenes))
    scale[scale == 0] = 1.0
    R, t, n = decompose_euclid(scenes.H * scale[:, None, None])
    eye = np.broadcast_to(np.eye(3), R.shape)
    np.testing.assert_allclose(np.swapaxes(R, -1, -2) @ R, eye, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-12)
    recomposed = R + t[..., :, None] * n[..., None, :]
    np.testing.assert_allclose(recomposed, np.broadcast_to(scenes.H[:, None], R.shape), atol=1e-12)
    # the ground truth is one of the four, and the selection finds it
    m_ref = np.linalg.solve(
        scenes.A,
        np.concatenate([scenes.p_ref, np.ones_like(scenes.p_ref[..., :1])], -1).swapaxes(1, 2),
    ).swapaxes(1, 2)
    prior = scenes.n_star + 0.02 * np.random.default_rng(0).normal(size=scenes.n_star.shape)
    Rs, ts, ns, ok = jax.vmap(select_solution)(R, t, n, m_ref, prior)
    assert np.all(ok)
    np.testing.assert_allclose(Rs, scenes.R_bar, atol=1e-10)
    np.testing.assert_allclose(ts, scenes.x_h, atol=1e-10)
    np.testing.assert_allclose(ns, scenes.n_star, atol=1e-10)


def test_known_normal_path(scenes):
    f = jax.jit(jax.vmap(decompose_homography_known_normal))
    R, x_h = f(scenes.G_n, scenes.n_star, scenes.A)
    np.testing.assert_allclose(R, scenes.R_bar, atol=1e-10)
    np.testing.assert_allclose(x_h, scenes.x_h, atol=1e-10)


def test_identity_and_pure_rotation():
    R, t, n = decompose_homography(jnp.eye(3))
    assert np.all(np.isfinite(R)) and np.all(np.isfinite(t)) and np.all(np.isfinite(n))
    np.testing.assert_allclose(R, np.broadcast_to(np.eye(3), (4, 3, 3)), atol=0)
    np.testing.assert_array_equal(t, 0.0)
    Rot = np.asarray(so3_exp(jnp.array([0.1, -0.2, 0.3])))
    R, t, n = decompose_homography(2.5 * Rot)
    np.testing.assert_allclose(R[0], Rot, atol=1e-14)
    np.testing.assert_array_equal(t, 0.0)
    # OpenCV agrees: one solution, the rotation
    count, Rc, _, _ = cv2.decomposeHomographyMat(2.5 * Rot, np.eye(3))
    assert count == 1
    np.testing.assert_allclose(Rc[0], Rot, atol=1e-12)
    # finite gradients at the identity on both paths
    g = jax.jit(jax.jacrev(lambda H: decompose_homography(H)[0][0]))(jnp.eye(3))
    assert np.all(np.isfinite(g))
    n_star = jnp.array([0.1, -0.2, 1.0])
    g = jax.jit(jax.jacrev(lambda H: decompose_homography_known_normal(H, n_star)))(jnp.eye(3))
    assert all(np.all(np.isfinite(x)) for x in g)


def test_known_normal_is_smooth_at_identity():
    """Value and derivative of the known-normal path exist at H = I and match differences."""
    n_star = np.array([0.1, -0.2, 1.0])
    n_unit = n_star / np.linalg.norm(n_star)

    def f(x):  # a 6-parameter motion around the identity: H = exp(w) + v n^T
        H = so3_exp(x[:3]) + jnp.outer(x[3:], n_unit)
        R, x_h = decompose_homography_known_normal(H, n_star)
        return jnp.concatenate([R.ravel(), x_h])

    x0 = np.zeros(6)
    J = jax.jit(jax.jacfwd(f))(x0)
    np.testing.assert_allclose(J, central_difference(f, x0, 1e-6), atol=1e-9)
    np.testing.assert_allclose(jax.jit(jax.jacrev(f))(x0), J, atol=1e-13)


def test_general_gradient_matches_finite_differences(scenes):
    H0 = scenes.H[3]

    def f(H):
        R, t, n = decompose_homography(H)
        return jnp.concatenate([R.ravel(), t.ravel(), n.ravel()])

    J = jax.jit(jax.jacrev(f))(H0)
    np.testing.assert_allclose(J, central_difference(f, H0, 1e-6), atol=1e-7)


def test_near_pi_and_tiny_rotations():
    n_star = np.array([0.05, -0.1, 1.0])
    n_star /= np.linalg.norm(n_star)
    for omega, x_h in [
        ((np.pi - 1e-6) * np.array([0.0, 0.0, 1.0]), np.array([0.05, -0.03, 0.1])),
        ((np.pi - 1e-3) * np.array([0.1, 0.0, 0.995]), np.array([-0.1, 0.02, 0.05])),
        (1e-9 * np.array([0.3, 0.5, -0.8]), np.array([0.05, -0.03, 0.1])),
        (np.zeros(3), np.array([0.2, 0.0, 0.1])),
    ]:
        R_true = np.asarray(so3_exp(jnp.asarray(omega)))
        H = R_true + np.outer(x_h, n_star)
        R, t, n = decompose_homography(H)
        d = [np.max(np.abs(R[k] - R_true)) + np.max(np.abs(t[k] - x_h)) for k in range(4)]
        assert min(d) < 1e-10
        Rk, xk = decompose_homography_known_normal(H, n_star)
        np.testing.assert_allclose(Rk, R_true, atol=1e-12)
        np.testing.assert_allclose(xk, x_h, atol=1e-12)


def test_shape_errors(no_jaxtyping):
    with pytest.raises(ValueError, match=r"`H` must have shape \(3, 3\)"):
        decompose_homography(np.eye(4))
    with pytest.raises(ValueError, match=r"`K` must have shape \(3, 3\)"):
        decompose_homography(np.eye(3), np.eye(2))
    with pytest.raises(ValueError, match=r"`n_star` must have shape \(3,\)"):
        decompose_homography_known_normal(np.eye(3), np.ones(2))
