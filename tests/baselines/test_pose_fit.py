"""The velocity baselines for the fixed camera of Chitrakaran et al.: per-frame poses, the
local least-squares fit (centred and causal) at a stated bandwidth, the constant-
acceleration EKF; exact where the fit's model is, result codes under vmap, gradients."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax._results import RESULTS
from visjax.baselines import (
    fit_bandwidth_hz,
    frame_poses,
    half_width_for_bandwidth,
    object_features,
    reprojection_residuals,
    velocity_ekf,
    velocity_smoother,
)
from visjax.estimators import fixed_camera_stream
from visjax.papers.chitrakaran import section6_scenario

TWIST = jnp.array([0.05, -0.03, 0.02, 0.1, -0.05, 0.08])
smoother = eqx.filter_jit(velocity_smoother)
ekf = eqx.filter_jit(velocity_ekf)


def scene(velocity, noise=0.0, key=None):
    sc = section6_scenario(1.0, 1000.0, velocity=velocity, noise_px=noise, key=key)
    clean = section6_scenario(1.0, 1000.0, velocity=velocity)
    _, n_star, z1_star = fixed_camera_stream(clean.ts, clean.pixels, sc.A, sc.R_star, sc.s[0])
    return sc, (sc.pixels, sc.A, sc.R_star, sc.s[0], n_star, z1_star)


@pytest.fixture(scope="module")
def constant():
    return scene(lambda t: TWIST)


@pytest.fixture(scope="module")
def poses(constant):
    return eqx.filter_jit(frame_poses)(*constant[1])


def test_poses_and_fits_exact_on_a_constant_twist(constant, poses):
    sc, args = constant
    assert np.all(np.asarray(poses.result._value) == RESULTS.successful._value)
    np.testing.assert_allclose(poses.R, sc.R, atol=1e-8)
    np.testing.assert_allclose(poses.x_f, sc.x_f, atol=1e-8)
    for causal in (False, True):
        sol = smoother(
            sc.ts, *args, bandwidth_hz=5.0, causal=causal, sample_interval=1e-3, poses=poses
        )
        assert sol.result == RESULTS.successful
        v = np.asarray(sol.outputs.v_hat)
        # a causal fit has seen one frame at the start: zero velocity, then exact
        start = 1 if causal else 0
        np.testing.assert_allclose(v[start:], np.broadcast_to(TWIST, v[start:].shape), atol=1e-8)
        R = np.asarray(sc.R)
        np.testing.assert_allclose(
            sol.outputs.v_object[start:, :3],
            np.einsum("nji,j->ni", R, TWIST[:3])[start:],
            atol=1e-8,
        )
    assert np.all(v[0] == 0.0)


def test_stated_bandwidth_is_the_minus_3db_point():
    """On a pose oscillating at the stated bandwidth, the fit's velocity has 1/sqrt(2) of
    the true amplitude (the sinusoid is not the fit's model: this checks the bandwidth)."""
    f = 5.0
    M = half_width_for_bandwidth(f, 1e-3)
    assert fit_bandwidth_hz(M, 1e-3) <= f < fit_bandwidth_hz(M - 1, 1e-3)
    sc, args = scene(lambda t: jnp.array([0.02, 0, 0, 0, 0, 0]) * jnp.sin(2 * jnp.pi * f * t))
    sol = smoother(sc.ts, *args, bandwidth_hz=f, sample_interval=1e-3)
    inner = slice(M, len(sc.ts) - M)  # full windows only
    ratio = np.ptp(np.asarray(sol.outputs.v_hat[inner, 0])) / np.ptp(
        np.asarray(sc.velocity[inner, 0])
    )
    assert abs(ratio - 1 / np.sqrt(2)) < 0.03, ratio


def test_causal_fit_and_filter_use_only_the_past(constant):
    sc, args = constant
    later = (jnp.arange(len(sc.ts)) > 600)[:, None, None]
    moved = (jnp.where(later, args[0] + 3.0, args[0]),) + args[1:]
    for f in (
        lambda a: smoother(sc.ts, *a, bandwidth_hz=5.0, causal=True, sample_interval=1e-3),
        lambda a: ekf(sc.ts, *a, r_px=0.1, throw=False),
    ):
        one, two = f(args), f(moved)
        np.testing.assert_array_equal(one.outputs.v_hat[:601], two.outputs.v_hat[:601])
        assert not np.allclose(one.outputs.v_hat[-1], two.outputs.v_hat[-1])


def test_ekf_converges_noise_free(constant):
    sc, args = constant
    sol = ekf(sc.ts, *args, r_px=0.1, max_jerk=0.1, max_angular_jerk=0.1)
    err = np.abs(np.asarray(sol.outputs.v_hat) - np.asarray(TWIST))
    assert err[-1].max() < 1e-3, err[-1]  # from zero velocity
    assert err[-1].max() < 0.1 * err[20].max()


def test_vmap_over_noise_seeds_flags_the_bad_seed(constant):
    sc, args = constant
    keys = jax.random.split(jax.random.key(0), 3)
    pixels = jax.vmap(lambda k: args[0] + 0.2 * jax.random.normal(k, args[0].shape))(keys)
    pixels = pixels.at[2, 300, 1, 0].set(jnp.inf)

    def both(p):
        a = (p,) + args[1:]
        s = velocity_smoother(
            sc.ts, *a, bandwidth_hz=5.0, causal=True, sample_interval=1e-3, throw=False
        )
        e = velocity_ekf(sc.ts, *a, r_px=0.2, throw=False)
        return s, e

    s, e = eqx.filter_jit(jax.vmap(both))(pixels)
    for sol in (s, e):
        codes = np.asarray(sol.result._value)
        assert codes[0] == codes[1] == RESULTS.successful._value
        assert codes[2] != RESULTS.successful._value
        assert int(sol.failed_sample[2]) == 300
    one = smoother(sc.ts, pixels[1], *args[1:], bandwidth_hz=5.0, causal=True, sample_interval=1e-3)
    # equal up to the pose fits' tolerance (1e-9, batched and unbatched linear algebra
    # round differently), amplified by differentiation over a full window (0.29 s)
    full = 2 * half_width_for_bandwidth(5.0, 1e-3, causal=True)
    np.testing.assert_allclose(s.outputs.v_hat[1, full:], one.outputs.v_hat[full:], atol=1e-6)
    with pytest.raises(RuntimeError):
        jax.block_until_ready(ekf(sc.ts, pixels[2], *args[1:]))


def test_gradient_of_the_pose_fit_loss_with_respect_to_the_pixels(constant, poses):
    sc, args = constant
    s, _ = object_features(args[0][0], *args[1:])
    R, x_f = poses.R[500], poses.x_f[500]

    def loss(p):
        return jnp.sum(reprojection_residuals(R, x_f, p, args[1], s) ** 2)

    p = args[0][500] + 0.3  # off the exact pose: a non-zero residual
    g = jax.grad(loss)(p)
    r = reprojection_residuals(R, x_f, p, args[1], s)
    np.testing.assert_allclose(g, -2 * r, rtol=1e-12)
    assert np.all(np.isfinite(g)) and np.abs(g).min() > 0


def test_bad_arguments(constant, no_jaxtyping):
    sc, args = constant
    with pytest.raises(ValueError, match="pixels"):
        frame_poses(args[0][:, :3], *args[1:])
    with pytest.raises(ValueError, match="ts"):
        velocity_smoother(sc.ts[:-1], *args, bandwidth_hz=5.0)
    with pytest.raises(ValueError, match="bandwidth_hz"):
        velocity_smoother(sc.ts, *args, bandwidth_hz=0.0)
