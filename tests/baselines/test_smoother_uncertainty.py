"""The velocity smoother's predicted spread (`SmootherDiagnostics.cov`) against a Monte
Carlo over noise seeds, its robust loss on a track with outliers, its gradients under jit
and vmap, and the velocity problem's `uncertainty` and `robust` settings."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax import papers, studies
from visjax._results import RESULTS
from visjax.baselines import (
    SmootherDiagnostics,
    cauchy,
    frame_poses,
    half_width_for_bandwidth,
    velocity_covariance,
    velocity_smoother,
)
from visjax.estimators import FixedCamera
from visjax.papers import chitrakaran as ch
from visjax.sim import CameraRig, constant_twist_trajectory, object_points, points_in_camera, view

TWIST = jnp.array([0.05, -0.03, 0.02, 0.1, -0.05, 0.08])
RATE_HZ, N, BANDWIDTH_HZ, NOISE_PX = 200.0, 40, 10.0, 0.5
TS = jnp.arange(float(N)) / RATE_HZ
FIT = dict(bandwidth_hz=BANDWIDTH_HZ, sample_interval=1.0 / RATE_HZ, throw=False)
fit = eqx.filter_jit(velocity_smoother)  # one compiled fit per loss for the module


@pytest.fixture(scope="module")
def scene():
    """A 3 x 3 grid of features, 0.6 m wide, on the plane of the section-6 target
    (Chitrakaran et al., eqs. (60)-(62)) moving with a constant twist; the camera's
    constants those of the scene (the reference image the first frame, $n^*$ the plane's
    unit normal in it with $n^{*T}\\bar m_i^* = d^* > 0$, $z_1^*$ the first feature's
    depth: what `fixed_camera` measures from the noise-free pixels). Nine features rather
    than the paper's four: at 0.5 px the four leave the rotation about the image axes so
    weakly determined that each frame's fit is no longer linear over the noise (the
    spread of the rotation rates is then about 1.8 times the first-order prediction;
    `tests/baselines/test_losses.py`)."""
    g = jnp.array([-0.3, 0.0, 0.3])
    xy = jnp.stack(jnp.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    features = jnp.concatenate([xy, (0.05 * (xy[:, 1] - xy[:, 0]))[:, None]], 1)
    x0, R0 = jnp.array(ch.X_F_STAR_EQ60), jnp.array(ch.R_STAR_EQ61)
    body = constant_twist_trajectory(TWIST, x0, R0, TS)
    A = jnp.array(ch.A_EQ62)
    rig = CameraRig(A=A, image_size=None)
    pixels = view(rig, points_in_camera(rig, object_points(body, features)))
    normal = R0 @ jnp.array([0.05, -0.05, 1.0])  # the plane's, in the reference frame
    normal = normal / jnp.linalg.norm(normal) * jnp.sign(normal @ x0)
    z1 = (x0 + R0 @ features[0])[2]
    return pixels, FixedCamera(pixels[0], A, R0, features[0], normal, z1)


@pytest.mark.slow  # the unit tier's time: a Monte Carlo of 200 draws of three fits
def test_predicted_spread_matches_the_monte_carlo(scene):
    """200 draws of 0.5 px noise, the centred and the causal fit: the predicted standard
    deviation of each component of $\\hat v$ (the root of the mean predicted variance)
    at frames with one-sided, partial and full windows is within 20% of the spread of the
    200 estimates."""
    pixels, camera = scene
    keys = jax.random.split(jax.random.key(0), 200)

    def fits(key):
        noisy = pixels + NOISE_PX * jax.random.normal(key, pixels.shape)
        poses = frame_poses(noisy, camera)
        sols = tuple(
            velocity_smoother(TS, noisy, camera, causal=causal, poses=poses, **FIT)
            for causal in (False, True)
        )
        # the velocity problem's fit: components from fits of different widths
        slow = velocity_smoother(TS, noisy, camera, poses=poses, **dict(FIT, bandwidth_hz=4.0))
        widths = (M,) * 3 + (M_SLOW,) * 3
        return sols + (slow.diagnostics.cov, velocity_covariance(poses, TS, widths))

    M = half_width_for_bandwidth(BANDWIDTH_HZ, 1.0 / RATE_HZ)
    M_SLOW = half_width_for_bandwidth(4.0, 1.0 / RATE_HZ)
    assert M < M_SLOW
    # `velocity_covariance` differentiable in the pixels (through the frames' poses)
    grad = jax.grad(
        lambda p: jnp.sum(velocity_covariance(frame_poses(p, camera), TS, (M,) * 6)[20])
    )(pixels)
    assert np.all(np.isfinite(grad)) and np.any(grad != 0)
    with pytest.raises(ValueError, match="six positive ints"):
        velocity_covariance(frame_poses(pixels, camera), TS, (M,) * 5)
    centred, causal, slow, mixed = eqx.filter_jit(jax.vmap(fits))(keys)
    np.testing.assert_allclose(mixed[:, :, :3, :3], centred.diagnostics.cov[:, :, :3, :3])
    np.testing.assert_allclose(mixed[:, :, 3:, 3:], slow[:, :, 3:, 3:], rtol=1e-12)
    for sol, frames in ((centred, [0, 3, 20, 39]), (causal, [2, 20, 39])):
        assert isinstance(sol.diagnostics, SmootherDiagnostics)
        assert np.all(np.asarray(sol.result._value) == RESULTS.successful._value)
        v, cov = np.asarray(sol.outputs.v_hat), np.asarray(sol.diagnostics.cov)
        predicted = np.sqrt(np.mean(np.diagonal(cov[:, frames], axis1=2, axis2=3), axis=0))
        spread = v[:, frames].std(axis=0, ddof=1)
        np.testing.assert_allclose(predicted, spread, rtol=0.2)
        # symmetric, and the fit is unbiased (the twist is the fit's model)
        np.testing.assert_allclose(cov, np.swapaxes(cov, -1, -2), rtol=1e-12, atol=0.0)
        bias = np.abs(v[:, frames].mean(axis=0) - np.asarray(TWIST))
        assert np.all(bias < 4.0 * spread / np.sqrt(200)), bias / spread
    # a causal fit that has seen one frame: zero velocity, no spread
    assert np.all(np.asarray(causal.diagnostics.cov[:, 0]) == 0.0)


@pytest.mark.slow  # the unit tier's time (velocity fits compiled anew)
def test_cauchy_loss_takes_an_outlier_track(scene):
    """One feature 20 px off in every third frame: least squares' velocity error grows
    several times over; with `loss=cauchy(1.0)` it stays near that on clean pixels."""
    pixels, camera = scene
    noisy = pixels + NOISE_PX * jax.random.normal(jax.random.key(3), pixels.shape)
    bad = noisy.at[::3, 8].add(jnp.array([20.0, 0.0]))

    def error(p, loss=None):
        sol = fit(TS, p, camera, loss=loss, **FIT)
        assert sol.result == RESULTS.successful
        e = np.asarray(sol.outputs.v_hat) - np.asarray(TWIST)
        return np.sqrt(np.mean(e**2, axis=0)), sol  # per component, over the frames

    (clean, sol), (plain, _), (robust, _) = error(noisy), error(bad), error(bad, cauchy(1.0))
    # (measured: plain up to 13 times the clean error, robust at most 1.44 times: the
    # outlier frames lose a corner feature)
    assert np.max(plain / clean) > 5.0, plain / clean
    assert np.max(robust / clean) < 2.0, robust / clean
    with pytest.raises(ValueError, match="loss"):
        poses = sol.diagnostics.poses
        velocity_smoother(TS, noisy, camera, poses=poses, loss=cauchy(1.0), **FIT)


@pytest.mark.slow  # the unit tier's time (velocity fits compiled anew)
def test_gradient_under_jit_and_vmap(scene):
    """The derivative of a frame's velocity with respect to the pixels, through the robust
    pose fits (`loss=cauchy`), under jit and vmap over two draws: finite, and along a random
    direction equal to a central difference."""
    pixels, camera = scene
    k = 20

    def of(sol):
        return jnp.sum(sol.outputs.v_hat[k])

    def scalar(p):
        return of(velocity_smoother(TS, p, camera, loss=cauchy(1.0), **FIT))

    noise = NOISE_PX * jax.random.normal(jax.random.key(1), (2,) + pixels.shape)
    noisy = pixels[None] + noise
    grads = eqx.filter_jit(jax.vmap(jax.grad(scalar)))(noisy)
    assert np.all(np.isfinite(np.asarray(grads)))
    assert np.max(np.abs(np.asarray(grads[0]))) > 0.0
    d = jax.random.normal(jax.random.key(2), pixels.shape)
    d = d / jnp.linalg.norm(d)
    h = 1e-3
    up, down = (of(fit(TS, noisy[0] + e, camera, loss=cauchy(1.0), **FIT)) for e in (h * d, -h * d))
    difference = float(up - down) / (2.0 * h)
    np.testing.assert_allclose(float(jnp.sum(grads[0] * d)), difference, rtol=1e-3)


@pytest.mark.slow  # the unit tier's time (velocity fits compiled anew)
def test_velocity_problem_uncertainty_and_robust_settings():
    """`robust=True`: the Cauchy loss in the fits, the gate in the EKF, stated; its batch
    method solves. `uncertainty`: the batch fit's predicted RMS per component over the
    metric's window, of the size of its error; NaN for the estimator and the EKF."""
    robust = papers.velocity_problem(noise_px=0.5, duration=0.2, robust=True)
    plain = dataclasses.replace(robust, robust=False)
    assert not plain.robust and "none" in plain.settings()["robust"]
    assert robust.robust and robust.title == plain.title + ", robust baselines"
    assert "Cauchy" in robust.settings()["robust"] and "0.9999" in robust.settings()["robust"]
    inputs, params = robust.inputs(jax.random.key(0)), robust.resolve()
    sol = eqx.filter_jit(lambda i: robust.solve("batch", params, i))(inputs)
    assert sol.result == RESULTS.successful
    std = np.asarray(robust.uncertainty("batch", sol)["rms_std"])
    rms = np.asarray(robust.metrics("batch", sol)["rms"])
    assert std.shape == (6,) and np.all(std > 0.0), std
    # the noise's share of the error (a lagging fit adds bias): within a factor of 3 of it
    # per component (measured: 0.6 to 1.7)
    assert np.all((rms / std > 1 / 3) & (rms / std < 3.0)), rms / std
    for method in ("estimator", "ekf"):
        assert np.all(np.isnan(np.asarray(robust.uncertainty(method, None)["rms_std"])))


@pytest.mark.slow  # four methods compiled: about 40 s on 2 cores
def test_compare_reports_the_velocity_predicted_spread():
    problem = papers.velocity_problem(noise_px=0.5, duration=0.2)
    records = studies.compare(problem, range(2), study=studies.Study(repeats=1))
    by = {(r["method"], r["seed"]): r for r in records}
    for seed in (0, 1):
        for method in ("batch", "batch_window"):
            r = by[(method, seed)]
            assert r["result"] == "successful"
            std = np.asarray(r["rms_std"], float)
            assert std.shape == (6,) and np.all(std > 0.0)
        for method in ("estimator", "ekf"):
            assert by[(method, seed)]["rms_std"] == [None] * 6
