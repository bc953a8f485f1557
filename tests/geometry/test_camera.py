import cv2
import jax
import numpy as np
import pytest

from tests.helpers import central_difference
from visjax import RESULTS
from visjax.geometry import (
    extended_intrinsics,
    intrinsic_matrix,
    normalized_to_pixel,
    pixel_to_normalized,
    project,
    to_homogeneous,
)
from visjax.geometry._camera import _project_checked

# The camera of Chitrakaran et al., eq. (62).
A62 = np.array([[1268.16, 0.0, 257.49], [0.0, 1267.50, 253.10], [0.0, 0.0, 1.0]])


def test_intrinsic_matrix_and_extended():
    A = intrinsic_matrix(1268.16, 1267.50, 257.49, 253.10)
    np.testing.assert_array_equal(A, A62)
    Ae = extended_intrinsics(A)
    np.testing.assert_array_equal(Ae, np.diag([1268.16, 1267.50, 1.0]))  # eq. (22)
    A_skew = intrinsic_matrix(800.0, 780.0, 320.0, 240.0, skew=3.0)
    np.testing.assert_array_equal(
        extended_intrinsics(A_skew), [[800.0, 3.0, 0.0], [0.0, 780.0, 0.0], [0.0, 0.0, 1.0]]
    )


def test_pixel_normalized_round_trip_against_numpy():
    rng = np.random.default_rng(0)
    A = np.array([[800.0, 2.5, 320.0], [0.0, 780.0, 240.0], [0.0, 0.0, 1.0]])
    p = rng.uniform(0, 640, (20, 2))
    m = pixel_to_normalized(p, A)
    ref = np.linalg.solve(A, to_homogeneous(p).T).T
    np.testing.assert_allclose(m, ref[:, :2], rtol=1e-14)
    np.testing.assert_allclose(normalized_to_pixel(m, A), p, rtol=1e-14)


def test_project_matches_opencv():
    rng = np.random.default_rng(1)
    X = np.c_[rng.uniform(-0.5, 0.5, (30, 2)), rng.uniform(1.0, 3.0, 30)]
    ref, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), A62, None)
    np.testing.assert_allclose(jax.jit(project)(X, A62).pixels, ref[:, 0, :], rtol=1e-12)


def test_project_jit_vmap_grad():
    rng = np.random.default_rng(2)
    X = np.concatenate([rng.uniform(-0.5, 0.5, (8, 5, 2)), rng.uniform(1.0, 3.0, (8, 5, 1))], -1)
    batched = jax.jit(jax.vmap(project, in_axes=(0, None)))(X, A62)
    for i in range(8):
        np.testing.assert_allclose(batched.pixels[i], project(X[i], A62).pixels, rtol=1e-15)
    x0 = X[0, 0]
    J = jax.jit(jax.jacrev(lambda x: project(x, A62).pixels))(x0)
    np.testing.assert_allclose(
        J, central_difference(lambda x: project(x, A62).pixels, x0, 1e-6), rtol=1e-7
    )


def test_project_behind_camera():
    X = np.array([[0.1, 0.2, 1.0], [0.0, 0.1, -0.5]])
    with pytest.raises(RuntimeError, match="behind the camera"):
        jax.jit(project)(X, A62)
    pixels, result = _project_checked(X, A62)
    assert result == RESULTS.behind_camera
    assert np.all(np.isfinite(pixels[0])) and np.all(np.isnan(pixels[1]))
    _, result = _project_checked(X[:1], A62)
    assert result == RESULTS.successful
    with pytest.raises(RuntimeError, match="not finite"):
        project(np.array([[np.nan, 0.0, 1.0]]), A62)


def test_shape_errors(no_jaxtyping):
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        project(np.zeros((4, 2)), A62)
    with pytest.raises(ValueError, match=r"shape \(3, 3\)"):
        pixel_to_normalized(np.zeros((4, 2)), np.eye(4))
