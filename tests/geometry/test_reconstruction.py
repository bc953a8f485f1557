import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.helpers import central_difference
from visjax import RESULTS
from visjax.geometry import euclidean_reconstruction, so3_exp
from visjax.sim import random_planar_scenes


def _general(p_ref, p_cur, A, n_prior):
    return euclidean_reconstruction(p_ref, p_cur, A, n_prior)


def _known(p_ref, p_cur, A, n_star):
    return euclidean_reconstruction(p_ref, p_cur, A, n_star=n_star)


general_batch = jax.jit(jax.vmap(_general))
known_batch = jax.jit(jax.vmap(_known))
general_j = jax.jit(_general)


@pytest.fixture(scope="module")
def scenes():
    return random_planar_scenes(100, 4, seed=31)


def _prior(sc, size=0.005):
    return sc.n_star + size * np.random.default_rng(1).normal(size=sc.n_star.shape)


def _check(rec, sc, tol):
    np.testing.assert_allclose(rec.R_bar, sc.R_bar, atol=tol)
    np.testing.assert_allclose(rec.x_h, sc.x_h, atol=tol)
    np.testing.assert_allclose(rec.n_star, sc.n_star, atol=tol)
    np.testing.assert_allclose(rec.alpha, sc.alpha, rtol=tol)
    np.testing.assert_allclose(rec.g33, sc.g33, rtol=tol)
    np.testing.assert_allclose(rec.H, sc.H, atol=tol)
    np.testing.assert_allclose(rec.G_n, sc.G_n, rtol=tol, atol=tol)


def test_round_trip_float64(scenes):
    """Section 3 end to end on 100 random planar scenes, both paths, to 1e-8."""
    _check(general_batch(scenes.p_ref, scenes.p_cur, scenes.A, _prior(scenes)), scenes, 1e-8)
    _check(known_batch(scenes.p_ref, scenes.p_cur, scenes.A, scenes.n_star), scenes, 1e-8)


def test_round_trip_more_points():
    sc = random_planar_scenes(30, 9, seed=32)
    _check(general_batch(sc.p_ref, sc.p_cur, sc.A, _prior(sc)), sc, 1e-8)


def test_vmap_over_frames_equals_loop(scenes):
    """One reference image, a batch of current frames (the estimator's use)."""
    sc = scenes
    batch = jax.jit(jax.vmap(_general, in_axes=(None, 0, None, None)))
    p_ref, A, prior = sc.p_ref[0], sc.A[0], sc.n_star[0]
    # frames of the same plane: transfer the reference points through H of other scenes
    Gs = sc.A[0] @ sc.H[:6] @ np.linalg.inv(sc.A[0])
    q = np.einsum("bij,nj->bni", Gs, np.c_[p_ref, np.ones(4)])
    p_cur = q[..., :2] / q[..., 2:]
    rec = batch(p_ref, p_cur, A, prior)
    for i in range(6):
        one = general_j(p_ref, p_cur[i], A, prior)
        np.testing.assert_allclose(rec.R_bar[i], one.R_bar, atol=1e-13)
        np.testing.assert_allclose(rec.alpha[i], one.alpha, rtol=1e-12)


def _flat(rec):
    return jnp.concatenate([rec.R_bar.ravel(), rec.x_h, rec.n_star, rec.alpha, rec.g33[None]])


def _flat_general(p_cur, p_ref, A, prior):
    return _flat(_general(p_ref, p_cur, A, prior))


def _flat_known(p_cur, p_ref, A, n_star):
    return _flat(_known(p_ref, p_cur, A, n_star))


# each Jacobian with respect to the current pixels compiled once, reused at every point
_jacobians = {f: jax.jit(jax.jacrev(f)) for f in (_flat_general, _flat_known)}


@pytest.mark.slow  # unit tier's time: the test at the identity checks both paths too
def test_gradient_matches_finite_differences(scenes):
    p_ref, p_cur, A, prior = scenes.p_ref[5], scenes.p_cur[5], scenes.A[5], scenes.n_star[5]
    for f, jac in _jacobians.items():
        J = jac(p_cur, p_ref, A, prior)
        assert np.all(np.isfinite(J))
        np.testing.assert_allclose(
            J, central_difference(f, p_cur, 1e-4, p_ref, A, prior), atol=1e-8
        )


@pytest.mark.slow  # the unit tier's time: 16 s of compiles; the general gradient stays in it
def test_gradient_at_identity_and_symmetric_square():
    """The paper's start: reference pose (H = I), a symmetric square target, no noise."""
    A = np.array([[1268.16, 0.0, 257.49], [0.0, 1267.50, 253.10], [0.0, 0.0, 1.0]])  # eq. (62)
    p_ref = np.array([[193.5, 189.1], [321.5, 189.1], [321.5, 317.1], [193.5, 317.1]])
    n_star = np.array([0.0, 0.0, 1.0])
    args = (p_ref, A, n_star)
    rec = _general(p_ref, p_ref, A, n_star)
    np.testing.assert_allclose(rec.R_bar, np.eye(3), atol=1e-14)
    np.testing.assert_allclose(rec.x_h, 0.0, atol=1e-14)
    np.testing.assert_allclose(rec.alpha, 1.0, rtol=1e-14)
    # known-normal path: smooth, so the derivative at the identity matches differences
    J = _jacobians[_flat_known](p_ref, *args)
    np.testing.assert_allclose(J, central_difference(_flat_known, p_ref, 1e-4, *args), atol=1e-8)
    np.testing.assert_allclose(jax.jit(jax.jacfwd(_flat_known))(p_ref, *args), J, atol=1e-12)
    # general path: not differentiable at the identity (the normal is undefined), but finite
    assert np.all(np.isfinite(_jacobians[_flat_general](p_ref, *args)))
    # away from the identity on the same square target, both match differences
    H = np.asarray(so3_exp(jnp.array([0.02, -0.03, 0.1]))) + np.outer([0.05, 0.02, -0.04], n_star)
    q = np.c_[p_ref, np.ones(4)] @ (A @ H @ np.linalg.inv(A)).T
    p_cur = q[:, :2] / q[:, 2:]
    for f, jac in _jacobians.items():
        J = jac(p_cur, *args)
        np.testing.assert_allclose(J, central_difference(f, p_cur, 1e-4, *args), atol=1e-8)


def test_near_pi_rotation_and_tiny_rotation():
    A = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
    n_star = np.array([0.05, -0.1, 1.0])
    n_star /= np.linalg.norm(n_star)
    p_ref = np.array([[250.0, 180.0], [390.0, 190.0], [400.0, 300.0], [240.0, 290.0]])
    for omega in ((np.pi - 1e-6) * np.array([0.0, 0.0, 1.0]), 1e-9 * np.array([0.3, 0.5, -0.8])):
        R_true = np.asarray(so3_exp(jnp.asarray(omega)))
        x_h = np.array([0.04, -0.03, 0.08])
        H = R_true + np.outer(x_h, n_star)
        q = np.c_[p_ref, np.ones(4)] @ (A @ H @ np.linalg.inv(A)).T
        rec = general_j(p_ref, q[:, :2] / q[:, 2:], A, n_star + 0.01)
        np.testing.assert_allclose(rec.R_bar, R_true, atol=1e-9)
        np.testing.assert_allclose(rec.x_h, x_h, atol=1e-9)
        np.testing.assert_allclose(rec.n_star, n_star, atol=1e-9)


def test_errors_and_result_codes(no_jaxtyping):
    A = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
    p_ref = np.array([[250.0, 180.0], [390.0, 190.0], [400.0, 300.0], [240.0, 290.0]])
    p_cur = p_ref + np.array([[3.0, 1.0], [2.0, -1.0], [-1.0, 2.0], [0.5, 0.5]])
    # a point behind the camera: a homography taking one point across the line at infinity
    G = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-0.004, 0.0, 1.3]])
    q = np.c_[p_ref, np.ones(4)] @ G.T
    assert np.sum(q[:, 2] < 0) == 2
    behind = q[:, :2] / q[:, 2:]
    with pytest.raises(RuntimeError, match="behind the camera"):
        general_j(p_ref, behind, A, None)
    rec = euclidean_reconstruction(p_ref, behind, A, throw=False)
    assert rec.result == RESULTS.behind_camera
    # a known normal that contradicts the image (points behind the given plane side)
    rec = euclidean_reconstruction(p_ref, p_cur, A, n_star=np.array([0.0, 0.0, -1.0]), throw=False)
    assert rec.result == RESULTS.no_physical_solution
    with pytest.raises(RuntimeError, match="No homography decomposition"):
        jax.jit(_known)(p_ref, p_cur, A, np.array([0.0, 0.0, -1.0]))
    # NaN input, collinear points
    bad = p_cur.copy()
    bad[2, 1] = np.nan
    with pytest.raises(RuntimeError, match="not finite"):
        general_j(p_ref, bad, A, None)
    rec = euclidean_reconstruction(p_ref, bad, A, throw=False)
    assert rec.result == RESULTS.nonfinite_pixels
    assert all(np.all(np.isfinite(x)) for x in (rec.R_bar, rec.x_h, rec.alpha))
    line = p_ref.copy()
    line[3] = 0.5 * (line[0] + line[1])
    with pytest.raises(RuntimeError, match="collinear"):
        general_j(line, p_cur, A, None)
    # the good case reports success
    assert euclidean_reconstruction(p_ref, p_cur, A, throw=False).result == RESULTS.successful
    # shapes, before tracing
    with pytest.raises(ValueError, match="at least 4"):
        euclidean_reconstruction(p_ref[:3], p_cur[:3], A)
    with pytest.raises(ValueError, match=r"`A` must have shape \(3, 3\)"):
        euclidean_reconstruction(p_ref, p_cur, A[:2])
    with pytest.raises(ValueError, match=r"`n_prior` must have shape \(3,\)"):
        euclidean_reconstruction(p_ref, p_cur, A, np.ones(2))
