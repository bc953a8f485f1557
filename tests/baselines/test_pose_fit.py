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
from visjax.estimators import fixed_camera
from visjax.papers import chitrakaran as ch
from visjax.sim import (
    CameraRig,
    Trajectory,
    constant_twist_trajectory,
    object_points,
    points_in_camera,
    view,
)

TWIST = jnp.array([0.05, -0.03, 0.02, 0.1, -0.05, 0.08])
TS = jnp.arange(300.0) / 1000.0
X0, R0 = jnp.array(ch.X_F_STAR_EQ60), jnp.array(ch.R_STAR_EQ61)
smoother = eqx.filter_jit(velocity_smoother)
EKF = dict(r_px=0.1, max_jerk=0.1, max_angular_jerk=0.1)  # one compiled filter
ekf = eqx.filter_jit(velocity_ekf)


def scene(body):
    """Pixels of the section-6 target (Chitrakaran et al., eqs. (60)-(62)) on `body`, the
    fixed camera's frame the world's; the camera's n* and z1* measured from them."""
    A = jnp.array(ch.A_EQ62)
    rig = CameraRig(A=A, image_size=None)
    pixels = view(rig, points_in_camera(rig, object_points(body, jnp.array(ch.FEATURES))))
    R_star, s1 = jnp.array(ch.R_STAR_EQ61), jnp.array(ch.FEATURES[0])
    return body, (pixels, fixed_camera(pixels, A, R_star, s1))


@pytest.fixture(scope="module")
def constant():
    # in closed form (no ODE to compile): x = x0 + v t, R = exp(t [w]) R0
    return scene(constant_twist_trajectory(TWIST, X0, R0, TS))


@pytest.fixture(scope="module")
def poses(constant):
    return eqx.filter_jit(frame_poses)(*constant[1])


def test_poses_and_fits_exact_on_a_constant_twist(constant, poses):
    sc, args = constant
    assert np.all(np.asarray(poses.result._value) == RESULTS.successful._value)
    np.testing.assert_allclose(poses.R, sc.R, atol=1e-8)
    np.testing.assert_allclose(poses.x_f, sc.x, atol=1e-8)
    for causal in (False, True):
        sol = smoother(
            sc.ts, *args, bandwidth_hz=20.0, causal=causal, sample_interval=1e-3, poses=poses
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


@pytest.mark.slow  # a second fit's compile at another window (4 s): the unit tier keeps the
# fit's exactness on its model and its gradient
def test_stated_bandwidth_is_the_minus_3db_point():
    """On a pose oscillating at the stated bandwidth, the fit's velocity has 1/sqrt(2) of
    the true amplitude (the sinusoid is not the fit's model: this checks the bandwidth)."""
    f = 10.0
    M = half_width_for_bandwidth(f, 1e-3)
    assert fit_bandwidth_hz(M, 1e-3) <= f < fit_bandwidth_hz(M - 1, 1e-3)
    w = 2 * jnp.pi * f
    x = X0[None] + 0.02 / w * jnp.outer(1 - jnp.cos(w * TS), jnp.array([1.0, 0.0, 0.0]))
    v = 0.02 * jnp.outer(jnp.sin(w * TS), jnp.eye(6)[0])
    body = Trajectory(ts=TS, R=jnp.broadcast_to(R0, (len(TS), 3, 3)), x=x, twist=v)
    sc, args = scene(body)
    sol = smoother(sc.ts, *args, bandwidth_hz=f, sample_interval=1e-3)
    inner = slice(M, len(sc.ts) - M)  # full windows only
    ratio = np.ptp(np.asarray(sol.outputs.v_hat[inner, 0])) / np.ptp(np.asarray(sc.twist[inner, 0]))
    assert abs(ratio - 1 / np.sqrt(2)) < 0.03, ratio


@pytest.mark.slow
def test_causal_fit_and_filter_use_only_the_past(constant, poses):
    sc, args = constant
    later = (jnp.arange(len(sc.ts)) > 200)[:, None, None]
    moved = (jnp.where(later, args[0] + 3.0, args[0]),) + args[1:]
    moved_poses = eqx.filter_jit(frame_poses)(*moved)
    fit = dict(bandwidth_hz=20.0, causal=True, sample_interval=1e-3)
    pairs = [
        (
            smoother(sc.ts, *args, **fit, poses=poses),
            smoother(sc.ts, *moved, **fit, poses=moved_poses),
        ),
        (ekf(sc.ts, *args, **EKF), ekf(sc.ts, *moved, **EKF, throw=False)),
    ]
    for one, two in pairs:
        np.testing.assert_array_equal(one.outputs.v_hat[:201], two.outputs.v_hat[:201])
        assert not np.allclose(one.outputs.v_hat[-1], two.outputs.v_hat[-1])


def test_ekf_converges_noise_free(constant):
    sc, args = constant
    sol = ekf(sc.ts, *args, **EKF)
    err = np.abs(np.asarray(sol.outputs.v_hat) - np.asarray(TWIST))
    assert err[-1].max() < 1e-3, err[-1]  # from zero velocity
    assert err[-1].max() < 0.1 * err[20].max()


@pytest.mark.slow
def test_vmap_over_noise_seeds_flags_the_bad_seed(constant):
    sc, args = constant
    n, fit = len(sc.ts), dict(bandwidth_hz=20.0, causal=True, sample_interval=1e-3)
    ts = sc.ts[:n]
    keys = jax.random.split(jax.random.key(0), 3)
    pixels = jax.vmap(lambda k: args[0][:n] + 0.2 * jax.random.normal(k, (n, 4, 2)))(keys)
    pixels = pixels.at[2, 150, 1, 0].set(jnp.inf)

    def both(p):  # (the EKF core's own test covers a filter under vmap)
        return velocity_smoother(ts, p, *args[1:], **fit, throw=False)

    s = eqx.filter_jit(jax.vmap(both))(pixels)
    for sol in (s,):
        codes = np.asarray(sol.result._value)
        assert codes[0] == codes[1] == RESULTS.successful._value
        assert codes[2] == RESULTS.nonfinite_measurement._value
        assert int(sol.failed_sample[2]) == 150
    one = smoother(ts, pixels[1], *args[1:], **fit)
    # equal up to the pose fits' tolerance (1e-9, batched and unbatched linear algebra
    # round differently), amplified by differentiation over a full window
    full = 2 * half_width_for_bandwidth(20.0, 1e-3, causal=True)
    np.testing.assert_allclose(s.outputs.v_hat[1, full:], one.outputs.v_hat[full:], atol=1e-6)


def test_gradient_of_the_pose_fit_loss_with_respect_to_the_pixels(constant, poses):
    sc, args = constant
    s, _ = object_features(args[1])
    R, x_f = poses.R[200], poses.x_f[200]

    def loss(p):
        return jnp.sum(reprojection_residuals(R, x_f, p, args[1].A, s) ** 2)

    p = args[0][200] + 0.3  # off the exact pose: a non-zero residual
    g = jax.grad(loss)(p)
    r = reprojection_residuals(R, x_f, p, args[1].A, s)
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


@pytest.mark.slow  # the unit tier's time: a velocity compile or 200 fits
def test_ekf_gate_rejects_outlier_pixels(constant):
    """Three features' pixels thrown 30 px off at a few frames: with the gate the filter
    equals the one told that those pixels are missing (NaN), to 1e-10; without, it does
    not."""
    sc, (pixels, camera) = constant
    noisy = pixels + 0.1 * jax.random.normal(jax.random.key(5), pixels.shape)
    frames, features = np.array([40, 90, 150]), np.array([0, 2, 3])
    outliers = noisy.at[frames, features].add(30.0)
    missing = noisy.at[frames, features].set(jnp.nan)
    gated = ekf(sc.ts, outliers, camera, **EKF, gate=1.0 - 1e-6)
    told = ekf(sc.ts, missing, camera, **EKF)
    plain = ekf(sc.ts, outliers, camera, **EKF)
    assert gated.result == told.result == RESULTS.successful
    np.testing.assert_allclose(gated.outputs.v_hat, told.outputs.v_hat, rtol=1e-10, atol=1e-10)
    gap = np.max(np.abs(np.asarray(plain.outputs.v_hat - told.outputs.v_hat)))
    assert gap > 1e-3
