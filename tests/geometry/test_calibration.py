"""Seed 003, section 2.3: least-squares camera matrix, and its effect on the position RMS."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.helpers import without_jaxtyping
from visjax.geometry import camera_matrix, camera_matrix_lstsq
from visjax.papers.jang import (
    KC_REFINED,
    KC_TOOLBOX,
    moving_point_experiment,
    scenario as moving_camera_scenario,
)


def test_recovers_a_known_camera_from_noisy_correspondences():
    rng = np.random.default_rng(0)
    Kc = np.array(KC_REFINED)
    m = rng.uniform(-0.5, 0.5, (400, 2))
    sigma = 0.5
    p = m * np.diag(Kc)[:2] + Kc[:2, 2] + sigma * rng.normal(size=m.shape)
    theta = jax.jit(camera_matrix_lstsq)(m, p).theta
    # standard errors: sigma / (sqrt(n) std(m)) for f, sigma / sqrt(n) for c
    np.testing.assert_allclose(theta[:2], np.diag(Kc)[:2], atol=5 * sigma / (20 * 0.29))
    np.testing.assert_allclose(theta[2:], Kc[:2, 2], atol=5 * sigma / 20)
    np.testing.assert_allclose(camera_matrix(theta)[2], [0.0, 0.0, 1.0])
    # noise-free: exact; and the gradient of theta in the pixels matches differences
    exact = camera_matrix_lstsq(m, m * np.diag(Kc)[:2] + Kc[:2, 2]).theta
    np.testing.assert_allclose(exact, [Kc[0, 0], Kc[1, 1], Kc[0, 2], Kc[1, 2]], rtol=1e-12)
    g = jax.grad(lambda p: camera_matrix_lstsq(m[:10], p).theta[0])(p[:10])
    assert np.all(np.isfinite(g))
    batch = jax.vmap(camera_matrix_lstsq)(jnp.stack([m, m]), jnp.stack([p, p + 1.0]))
    np.testing.assert_allclose(batch.theta[1, 2:], theta[2:] + 1.0, rtol=1e-12)
    with without_jaxtyping(), pytest.raises(ValueError, match=r"shape \(n, 2\)"):
        camera_matrix_lstsq(m[:, :1], p[:, :1])
    with pytest.raises(RuntimeError, match="do not vary"):
        camera_matrix_lstsq(np.ones((5, 2)), p[:5])


@pytest.mark.slow
def test_refined_camera_matrix_reduces_the_position_error():
    """In the style of Tables 5-1/5-2: the observer given the toolbox K_c (a perturbed
    nominal) versus K_c refined by least squares on correspondences from set I.1 (as the
    thesis did): the y error drops, as in the thesis (0.0349 -> 0.0179 m in set I.2)."""
    calib = moving_camera_scenario("I.1", 30.0, noise_px=0.5, key=jax.random.key(3))
    m = np.asarray(calib.x[::33, :2])  # the true normalized coordinates (ground truth)
    p = np.asarray(calib.frame_pixels[calib.frame_index][::33])
    theta = camera_matrix_lstsq(m, p).theta
    # x1 spans little in set I.1 (v_cx = 0.3 cm/s), so f is the loosest parameter
    np.testing.assert_allclose(theta, [551.9794, 737.5125, 304.0282, 331.5052], rtol=1e-2)
    Kc_refined = np.asarray(camera_matrix(theta))
    nominal = moving_point_experiment("I.2", 20.0, noise_px=0.1, Kc_observer=KC_TOOLBOX)
    refined = moving_point_experiment("I.2", 20.0, noise_px=0.1, Kc_observer=Kc_refined)
    assert refined.rms[1] < 0.6 * nominal.rms[1]  # y
    assert refined.rms[2] < nominal.rms[2]  # z
