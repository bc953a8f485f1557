"""The covariances the batch baselines return, against the spread of their estimates over
200 noise seeds, and their robust losses on tracks with outlier observations (Nath et al.'s
scene for the bundle adjustment; a static point seen by a moving camera for the
triangulation)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax.baselines import bundle_adjustment, cauchy, huber, triangulate_point
from visjax.estimators import moving_point_stream, static_points_stream
from visjax.papers import nath

SEEDS = 200
NOISE = 0.5  # px


@pytest.fixture(scope="module")
def scene():
    sc = nath.scenario(4.0, 10.0)  # 40 frames
    return sc, nath.initial_estimator(sc)


def _ba(sc, est, noise, loss=None, reject_px=None):
    stream = static_points_stream(
        sc.ts, sc.R_b, sc.x_b, sc.p_s + noise[:, : sc.p_s.shape[1]],
        sc.p_c + noise[:, sc.p_s.shape[1] :], sc.omega_c,
    )  # fmt: skip
    return bundle_adjustment(est, stream, sc.omega_c, loss=loss, reject_px=reject_px, throw=False)


@pytest.mark.slow  # the unit tier's time: a velocity compile or 200 fits
def test_bundle_adjustment_covariance_predicts_the_spread(scene):
    """Each unknown feature coordinate's predicted standard deviation (the root of the
    mean predicted variance over the seeds) is within 20% of the spread of the 200 fits."""
    sc, est = scene
    n = sc.p_s.shape[1] + sc.p_c.shape[1]
    noise = NOISE * jax.random.normal(jax.random.key(0), (SEEDS, sc.ts.shape[0], n, 2))

    @eqx.filter_jit
    def fits(noise):
        sols = jax.vmap(lambda z: _ba(sc, est, z))(noise)
        return sols.result._value, sols.outputs.omega_s[:, -1], sols.diagnostics.omega_s_std[:, 0]

    codes, omega, std = fits(noise)
    assert np.all(np.asarray(codes) == 0)
    predicted = np.sqrt(np.mean(np.asarray(std) ** 2, axis=0))
    spread = np.asarray(omega).std(axis=0, ddof=1)
    np.testing.assert_allclose(predicted, spread, rtol=0.2)


@pytest.mark.slow  # the unit tier's time: five bundle adjustments compiled (robust losses
# keep unit tests in test_losses.py and test_triangulation_robust.py)
def test_robust_bundle_adjustment_on_tracks_with_outliers(scene):
    """One track in ten (an unknown feature's) thrown 17 px off for a third of its frames
    (a false match that the tracker followed), 0.5 px noise: least squares is off by
    more than 20 times its outlier-free error; Huber's loss (scale 1 px: a bounded
    influence) cuts that by more than 5 times, and the Cauchy loss (scale 1 px: an
    influence that vanishes for large residuals) keeps the worst feature error within 2
    times the outlier-free least squares (measured over 5 seeds: 0.8-2.3 times, and 0.9-1.6
    times the Cauchy fit's own outlier-free error). The Cauchy fit followed by least
    squares without the observations it puts beyond 3 px finds exactly the outliers and
    is the fit told which they are (the observations left out, NaN)."""
    sc, est = scene
    n_s, n = sc.p_s.shape[1], sc.p_s.shape[1] + sc.p_c.shape[1]
    noise = NOISE * jax.random.normal(jax.random.key(1), (sc.ts.shape[0], n, 2))
    outliers = noise.at[10:23, 1].add(jnp.array([15.0, -9.0]))

    @eqx.filter_jit
    def worst(noise, loss, reject_px=None):
        sol = _ba(sc, est, noise, loss, reject_px)
        return jnp.max(jnp.linalg.norm(sol.outputs.omega_s[-1] - sc.omega_s, axis=-1)), sol

    clean = float(worst(noise, None)[0])
    plain = float(worst(outliers, None)[0])
    bounded = float(worst(outliers, huber(1.0))[0])
    redescending = float(worst(outliers, cauchy(1.0))[0])
    _, two_stage = worst(outliers, cauchy(1.0), 3.0)
    _, told = worst(noise.at[10:23, 1].set(jnp.nan), None)
    assert int(two_stage.diagnostics.rejected[0]) == 13
    np.testing.assert_allclose(two_stage.outputs.omega_s[-1], told.outputs.omega_s[-1], rtol=1e-6)
    assert plain > 20.0 * clean, (clean, plain)
    assert bounded < plain / 5.0, (plain, bounded)
    assert redescending < 2.0 * clean, (clean, redescending)
    assert n_s < n


@pytest.fixture(scope="module")
def moving_camera():
    """A static point 2 m ahead, a camera translating sideways and turning, 30 frames."""
    from visjax.baselines import camera_poses

    ts = jnp.linspace(0.0, 1.0, 30)
    u = jnp.broadcast_to(jnp.array([0.6, 0.2, 0.1, 0.05, -0.1, 0.02]), (30, 6))
    R, c = camera_poses(ts, u)
    P = jnp.array([0.2, -0.1, 2.0])
    m = jnp.einsum("nji,nj->ni", R, P[None] - c)  # R^T (P - c): the point in each frame
    y = m[:, :2] / m[:, 2:]
    return ts, u, y, m


@pytest.mark.slow  # the unit tier's time: a velocity compile or 200 fits
def test_triangulation_covariance_predicts_the_spread(moving_camera):
    ts, u, y, m = moving_camera
    K = jnp.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
    pixels = y @ K[:2, :2].T + K[None, :2, 2]
    noise = NOISE * jax.random.normal(jax.random.key(2), (SEEDS,) + pixels.shape)

    @eqx.filter_jit
    def fits(noise):
        def one(z):
            s = moving_point_stream(ts, pixels + z, u, K)
            sol = triangulate_point(s, window=30, refine=True, throw=False)
            return sol.outputs.position[-1], sol.diagnostics.cov[-1], sol.result._value

        return jax.vmap(one)(noise)

    pos, cov, codes = fits(noise)
    assert np.all(np.asarray(codes) == 0)
    predicted = np.sqrt(np.mean(np.diagonal(np.asarray(cov), axis1=1, axis2=2), axis=0))
    spread = np.asarray(pos).std(axis=0, ddof=1)
    np.testing.assert_allclose(predicted, spread, rtol=0.2)
    # the estimate is the truth within a few predicted deviations
    assert np.all(np.abs(np.asarray(pos).mean(0) - np.asarray(m[-1])) < 4 * spread)
