"""Seed 004, sections II-III: the regressors reproduce the pixels exactly."""

import jax
import jax.numpy as jnp
import numpy as np

from tests.helpers import central_difference
from visjax.geometry import (
    camera_from_parameters,
    camera_parameters,
    feature_in_camera,
    intrinsics_from_camera,
    known_feature_regressors,
    project,
    so3_exp,
    unknown_feature_regressors,
)


def _random_configuration(rng):
    A = intrinsics_from_camera(
        rng.uniform(0.005, 0.01),
        rng.uniform(8e4, 1.2e5),
        rng.uniform(8e4, 1.2e5),
        rng.uniform(1.45, 1.65),
        rng.uniform(300, 340),
        rng.uniform(220, 260),
    )
    R_c = so3_exp(jnp.asarray(0.3 * rng.normal(size=3)))
    x_c = jnp.asarray(0.1 * rng.normal(size=3))
    R_b = so3_exp(jnp.asarray(0.5 * rng.normal(size=3)))
    x_b = jnp.asarray(rng.normal(size=3))
    # a point about 1.5 m in front of the camera, in world coordinates
    m_bar = np.array([0.2 * rng.normal(), 0.2 * rng.normal(), rng.uniform(1.0, 2.0)])
    omega = R_b @ (R_c @ m_bar + x_c) + x_b
    return A, R_c, x_c, R_b, x_b, omega, m_bar


def test_regressors_reproduce_the_projection():
    rng = np.random.default_rng(0)
    for _ in range(50):
        A, R_c, x_c, R_b, x_b, omega, m_bar = _random_configuration(rng)
        np.testing.assert_allclose(feature_in_camera(omega, R_b, x_b, R_c, x_c), m_bar, rtol=1e-12)
        pixel = project(m_bar, A).pixels  # eq. (3)
        t1, t2 = camera_parameters(A, R_c, x_c)
        theta_s = jnp.concatenate([omega, jnp.ones(1)])  # eq. (11)
        W, Pi = unknown_feature_regressors(R_b, x_b, t1, t2)
        z = (Pi @ theta_s)[0]
        np.testing.assert_allclose(z, m_bar[2], rtol=1e-12)  # eq. (7), (9)
        np.testing.assert_allclose(W @ theta_s / z, np.append(pixel, 1.0), rtol=1e-12)  # (8)
        Wx, Pix = known_feature_regressors(R_b, x_b, omega)
        np.testing.assert_allclose((Wx @ t1) / (Pix @ t2)[0], np.append(pixel, 1.0), rtol=1e-12)
        # the camera parameters are defined up to scale (section III)
        np.testing.assert_allclose(
            (Wx @ (3.0 * t1)) / (Pix @ (3.0 * t2))[0], W @ theta_s / z, rtol=1e-12
        )


def test_intrinsics_skew_angle():
    A = intrinsics_from_camera(0.008, 1e5, 1e5, np.pi / 2, 320.0, 240.0)
    np.testing.assert_allclose(
        A, [[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]], atol=1e-10
    )
    A = intrinsics_from_camera(0.008, 1e5, 1e5, np.pi / 3, 320.0, 240.0)
    np.testing.assert_allclose(A[0, 1], 800.0 / np.tan(np.pi / 3), rtol=1e-12)


def test_jit_vmap_grad():
    rng = np.random.default_rng(1)
    A, R_c, x_c, R_b, x_b, omega, _ = _random_configuration(rng)
    t1, t2 = camera_parameters(A, R_c, x_c)

    def pixel(x_b):
        W, Pi = jax.jit(unknown_feature_regressors)(R_b, x_b, t1, t2)
        th = jnp.concatenate([omega, jnp.ones(1)])
        return (W @ th / (Pi @ th))[:2]

    J = jax.jacfwd(pixel)(x_b)
    np.testing.assert_allclose(
        J, central_difference(pixel, np.asarray(x_b), 1e-6), rtol=1e-6, atol=1e-6
    )
    Ws, _ = jax.vmap(known_feature_regressors, in_axes=(None, None, 0))(
        R_b, x_b, jnp.stack([omega, omega + 1])
    )
    assert Ws.shape == (2, 3, 12)


def test_camera_back_from_its_parameters():
    """Footnote 3: A, R_c, x_c from theta_c1 at any nonzero scale (either sign), exact;
    under jit and vmap; the gradient of A_11 against a central difference."""
    rng = np.random.default_rng(21)
    configs = [_random_configuration(rng)[:3] for _ in range(6)]
    thetas = jnp.stack([camera_parameters(A, R, x)[0] for A, R, x in configs])
    scales = jnp.asarray([1.0, -1.0, 3e-4, -250.0, 7.0, -0.01])
    A, R, x = jax.jit(jax.vmap(camera_from_parameters))(thetas * scales[:, None])
    for k, (A0, R0, x0) in enumerate(configs):
        np.testing.assert_allclose(A[k], A0, rtol=1e-10, atol=1e-9)
        np.testing.assert_allclose(R[k], R0, atol=1e-12)
        np.testing.assert_allclose(x[k], x0, atol=1e-12)
        assert np.isclose(np.linalg.det(R[k]), 1.0)

    def a11(theta):
        return camera_from_parameters(theta)[0][0, 0]

    g = jax.grad(a11)(thetas[0])
    fd = central_difference(a11, thetas[0], 1e-6)
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-8)
