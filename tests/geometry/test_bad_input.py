"""Bad input never comes back as a finite value reported as success (issue: no silent
garbage). Each case failed before its fix."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax import RESULTS, result_names
from visjax.geometry import (
    camera_matrix,
    camera_matrix_lstsq,
    euclidean_reconstruction,
    feature_in_camera,
    find_homography,
    intrinsic_matrix,
    intrinsics_from_camera,
    known_feature_regressors,
    pixel_to_normalized,
    project,
    so3_exp,
    so3_log,
)
from visjax.geometry._camera import _project_checked
from visjax.sim import random_planar_scenes

recon = jax.jit(jax.vmap(lambda a, b, c: euclidean_reconstruction(a, b, c, throw=False)))


@pytest.fixture(scope="module")
def batch():
    sc = random_planar_scenes(1000, 4, seed=3)
    A = sc.A.copy()
    p_cur = sc.p_cur.copy()
    A[[5, 400, 999], 0, 0] = np.nan  # NaN intrinsics
    A[[7, 600], 1, 1] = 0.0  # a zero focal length
    p_cur[[11, 700], 2, 0] = np.inf  # a non-finite pixel
    return sc, A, p_cur, {5, 400, 999, 7, 600, 11, 700}


@pytest.mark.parametrize("size", [1, pytest.param(300, marks=pytest.mark.slow), 1000])
def test_a_batch_flags_every_bad_element_and_keeps_the_good_ones(batch, size):
    """XLA's CPU max under vmap drops a NaN from batch ~511 on: version 1 then called a
    NaN-intrinsics reconstruction successful. Every bad element is flagged at every batch
    size, and the good ones equal their reconstruction in a batch of good ones only."""
    sc, A, p_cur, bad = batch
    idx = np.array([5]) if size == 1 else np.arange(size)
    rec = recon(sc.p_ref[idx], p_cur[idx], A[idx])
    ok = np.asarray(rec.result._value) == int(RESULTS.successful._value)
    is_bad = np.array([i in bad for i in idx])
    assert not np.any(ok & is_bad)
    assert np.all(ok | is_bad)
    good = idx[~is_bad]
    if good.size:
        clean = recon(sc.p_ref[good], sc.p_cur[good], sc.A[good])
        np.testing.assert_allclose(rec.R_bar[~is_bad], clean.R_bar, rtol=0, atol=1e-12)
        np.testing.assert_allclose(rec.alpha[~is_bad], clean.alpha, rtol=1e-12)
    # a successful element is finite everywhere
    assert np.all(np.isfinite(np.asarray(rec.H)[ok]))


def test_so3_log_never_turns_nan_into_a_finite_vector():
    R = np.asarray(so3_exp(jnp.array([0.3, -1.2, 1.9])))
    for i in range(3):
        for j in range(3):
            for bad in (np.nan, np.inf):
                Rb = R.copy()
                Rb[i, j] = bad
                assert np.all(np.isnan(so3_log(Rb).omega))
    with pytest.raises(RuntimeError, match="not a rotation"):
        so3_log(np.diag([1.0, 1.0, 2.0]))
    with pytest.raises(RuntimeError, match="not a rotation"):
        so3_log(np.diag([1.0, 1.0, -1.0]))  # a reflection
    np.testing.assert_allclose(so3_log(R).omega, [0.3, -1.2, 1.9], rtol=1e-12)


def test_projection_with_unusable_intrinsics():
    A = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
    X = np.array([[0.1, 0.2, 1.0]])
    for bad in (np.nan, 0.0):
        Ab = A.copy()
        Ab[0, 0] = bad
        pixels, result = _project_checked(X, Ab)
        assert result == RESULTS.invalid_intrinsics and np.all(np.isnan(pixels))
        with pytest.raises(RuntimeError, match="intrinsic matrix"):
            project(X, Ab)
        assert np.all(np.isnan(pixel_to_normalized(np.array([[1.0, 2.0]]), Ab)))
    assert np.all(np.isnan(pixel_to_normalized(np.array([[np.nan, 2.0]]), A)[..., 0]))


def test_camera_matrix_lstsq_checks_its_data():
    m = np.random.default_rng(0).uniform(-0.3, 0.3, (50, 2))
    p = m * np.array([550.0, 730.0]) + np.array([300.0, 330.0])
    bad = p.copy()
    bad[3, 1] = np.nan
    with pytest.raises(RuntimeError, match="not finite"):
        camera_matrix_lstsq(m, bad)
    # offset, narrow data: the centred solve keeps the digits the raw sums lost
    narrow = 1e3 + 1e-3 * m
    theta = camera_matrix_lstsq(narrow, narrow * 550.0 + 300.0).theta
    np.testing.assert_allclose(theta[:2], [550.0, 550.0], rtol=1e-7)


def test_shapes_that_were_accepted_silently(no_jaxtyping):
    with pytest.raises(ValueError, match=r"`theta` must have shape \(4,\)"):
        camera_matrix(np.ones(3))
    with pytest.raises(ValueError, match=r"`theta` must have shape \(4,\)"):
        camera_matrix(np.ones(5))
    with pytest.raises(ValueError, match=r"`x_b` must have shape \(3,\)"):
        known_feature_regressors(np.eye(3), np.ones(1), np.ones(3))
    # these raised a raw TypeError, or a ValueError that named no argument
    with pytest.raises(ValueError, match=r"`omega` must have shape \(3,\)"):
        feature_in_camera(np.zeros(2), np.eye(3), np.zeros(3), np.eye(3), np.zeros(3))
    with pytest.raises(ValueError, match=r"`fx` must have shape \(\)"):
        intrinsic_matrix(np.zeros(2), 1.0, 1.0, 1.0)
    with pytest.raises(ValueError, match=r"`f` must have shape \(\)"):
        intrinsics_from_camera(np.zeros(2), 1.0, 1.0, 1.5, 1.0, 1.0)


def test_g33_zero_is_named_and_large_pixels_are_not():
    """A homography whose g33 is 0 (the image origin maps to infinity) gets `g33_zero`; a
    pure translation of pixels near 4e5 does not (judged at the data's scale)."""
    G0 = np.array([[2.0, 0.1, 5.0], [0.2, 1.0, 3.0], [1e-3, 2e-3, 0.0]])
    p_ref = np.array([[100.0, 50.0], [300.0, 60.0], [320.0, 240.0], [90.0, 250.0]])
    h = np.c_[p_ref, np.ones(4)] @ G0.T
    out = find_homography(p_ref, h[:, :2] / h[:, 2:], throw=False)
    assert out.result == RESULTS.g33_zero and np.all(np.isnan(out.G))
    big = 4e5 + p_ref
    out = find_homography(big, big + np.array([5.0, -3.0]), throw=False)
    assert out.result == RESULTS.successful
    np.testing.assert_allclose(out.G[:2, 2], [5.0, -3.0], rtol=1e-6)


def test_what_users_catch_outside_and_inside_jit():
    """The documented contract (docs/errors.md): an `EquinoxRuntimeError` outside
    `jax.jit`; under it a `JaxRuntimeError`, or a `ValueError` once the compiled function
    already ran without error (JAX's fast path, jax-ml/jax#34083): `(RuntimeError,
    ValueError)` catches all, and the message names the cause each time."""
    import equinox as eqx

    m = np.random.default_rng(0).uniform(-1, 1, (6, 2))
    p = m * 500.0 + 300.0
    bad = p.copy()
    bad[2, 0] = np.nan
    cause = "a coordinate is not finite"
    with pytest.raises(eqx.EquinoxRuntimeError, match=cause):
        camera_matrix_lstsq(m, bad)
    first_bad = jax.jit(camera_matrix_lstsq)
    with pytest.raises(jax.errors.JaxRuntimeError, match=cause):
        first_bad(m, bad)
    warm = jax.jit(camera_matrix_lstsq)
    warm(m, p)
    with pytest.raises((RuntimeError, ValueError), match=cause):
        warm(m, bad)


def test_throw_false_keeps_a_batch_alive(no_jaxtyping):
    """Issue 44 (item 6): `project`, `so3_log` and `camera_matrix_lstsq` with `throw=False`
    return the same type as with `throw=True`, the failure as its `result` and NaN values;
    under `vmap` one bad frame leaves the others as the single calls give them."""
    from visjax.geometry import project, so3_exp, so3_log

    A = np.array([[800.0, 0, 320], [0, 790.0, 240], [0, 0, 1]])
    X = np.array([[[0.1, 0.2, 2.0]], [[0.1, 0.2, -1.0]], [[np.nan, 0.0, 1.0]]])
    out = jax.vmap(lambda x: project(x, A, throw=False))(X)
    assert result_names(out.result) == ["successful", "behind_camera", "nonfinite_pixels"]
    np.testing.assert_allclose(out.pixels[0], project(X[0], A).pixels, rtol=1e-15)
    assert np.all(np.isnan(out.pixels[1:]))
    Rs = np.stack([np.asarray(so3_exp(np.array([0.3, -0.2, 0.1]))), np.diag([1.0, 1.0, 2.0])])
    logs = jax.vmap(lambda R: so3_log(R, throw=False))(Rs)
    assert list(result_names(logs.result)) == ["successful", "not_a_rotation"]
    np.testing.assert_allclose(logs.omega[0], [0.3, -0.2, 0.1], rtol=1e-12)
    assert np.all(np.isnan(logs.omega[1]))
    assert result_names(so3_log(np.full((3, 3), np.nan)).result) == "nonfinite_matrix"
    m = np.random.default_rng(0).uniform(-0.3, 0.3, (3, 8, 2))
    m[1, :, 0] = 0.1  # no variation along x
    m[2, 0, 1] = np.nan
    p = m * [550.0, 560.0] + [300.0, 250.0]
    fits = jax.vmap(lambda a, b: camera_matrix_lstsq(a, b, throw=False))(m, p)
    assert list(result_names(fits.result)) == [
        "successful",
        "degenerate_points",
        "nonfinite_pixels",
    ]
    np.testing.assert_allclose(fits.theta[0], [550.0, 560.0, 300.0, 250.0], rtol=1e-9)
    assert np.all(np.isnan(fits.theta[1:]))
    with pytest.raises(ValueError, match="throw"):
        project(X[0], A, throw=1)
