"""Bundle adjustment and the EKF for the uncalibrated camera of Nath et al. on the project's
scene (`papers.nath.scenario`, 20 s, here sampled at 100 Hz): exact noise-free, within 1 mm
at 0.5 px, causal windows, result codes under vmap, gradients."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax._results import RESULTS
from visjax.baselines import bundle_adjustment, bundle_adjustment_residuals, static_points_ekf
from visjax.papers import nath

ba = eqx.filter_jit(bundle_adjustment)
ekf = eqx.filter_jit(static_points_ekf)


def errors(sol, sc, k=-1):
    return np.linalg.norm(np.asarray(sol.outputs.omega_s[k] - sc.omega_s), axis=-1)


@pytest.fixture(scope="module")
def scenes():
    clean = nath.scenario(20.0, 100.0)
    noisy = nath.scenario(20.0, 100.0, noise_px=0.5, key=jax.random.key(4))
    # the same estimator (initial guesses from the nominal camera) for both
    est = nath.initial_estimator(clean)
    return clean, noisy, est


@pytest.fixture(scope="module")
def fits(scenes):
    clean, noisy, est = scenes
    return [ba(est, nath.stream(sc), sc.omega_c, throw=False) for sc in (clean, noisy)]


def test_exact_noise_free_and_within_1mm_at_half_a_pixel(scenes, fits):
    clean, noisy, est = scenes
    exact, fit = fits
    assert exact.result == RESULTS.successful and fit.result == RESULTS.successful
    # the initial guesses are centimetres off
    start = np.linalg.norm(
        np.asarray(est.output(0.0, est.init(_y0(clean)), _y0(clean)).omega_s - clean.omega_s),
        axis=-1,
    )
    assert start.max() > 0.02
    assert errors(exact, clean).max() < 1e-8
    np.testing.assert_allclose(exact.outputs.A[-1], clean.A, rtol=1e-10)
    np.testing.assert_allclose(exact.outputs.R_c[-1], clean.R_c, atol=1e-10)
    np.testing.assert_allclose(exact.outputs.x_c[-1], clean.x_c, atol=1e-10)
    assert float(exact.diagnostics.rms_px[0]) < 1e-9
    assert errors(fit, noisy).max() < 1e-3
    # the residual at the solution is the noise level
    assert 0.45 < float(fit.diagnostics.rms_px[0]) < 0.55


def _y0(sc):
    return jax.tree_util.tree_map(lambda x: x[0], nath.stream(sc).ys)


def test_sliding_window_is_causal(scenes):
    clean, _, est = scenes
    stream = nath.stream(clean)
    sol = ba(est, stream, clean.omega_c, window=100, every=200, throw=False)
    assert sol.result == RESULTS.successful
    assert sol.diagnostics.rms_px.shape == (10,)
    assert errors(sol, clean).max() < 1e-8
    # corrupt every pixel after sample 1000: the estimates up to it are unchanged
    ys = stream.ys
    later = jnp.arange(ys.p_s.shape[0])[:, None, None] > 1000
    moved = eqx.tree_at(lambda s: s.ys.p_s, stream, jnp.where(later, ys.p_s + 5.0, ys.p_s))
    other = ba(est, moved, clean.omega_c, window=100, every=200, throw=False)
    np.testing.assert_array_equal(other.outputs.omega_s[:1001], sol.outputs.omega_s[:1001])
    assert not np.allclose(other.outputs.omega_s[-1], sol.outputs.omega_s[-1])


@pytest.mark.slow
def test_vmap_over_noise_seeds_flags_the_bad_one(scenes, fits):
    clean, noisy, est = scenes
    streams = [nath.stream(sc) for sc in (clean, noisy, noisy)]
    bad = streams[2].ys.p_s.at[50, 1, 0].set(jnp.inf)
    streams[2] = eqx.tree_at(lambda s: s.ys.p_s, streams[2], bad)
    batch = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *streams)
    sols = eqx.filter_jit(
        jax.vmap(lambda s: bundle_adjustment(est, s, clean.omega_c, throw=False))
    )(batch)
    codes = np.asarray(sols.result._value)
    assert list(codes) == [
        RESULTS.successful._value,
        RESULTS.successful._value,
        RESULTS.nonfinite_measurement._value,
    ]
    for i in range(2):
        np.testing.assert_allclose(sols.outputs.omega_s[i], fits[i].outputs.omega_s, atol=1e-12)
    with pytest.raises(RuntimeError):
        jax.block_until_ready(ba(est, streams[2], clean.omega_c))


def test_ekf_converges_and_flags_a_bad_pose(scenes):
    clean, noisy, est = scenes
    sol = ekf(est, nath.stream(clean), clean.omega_c, r_px=0.05, throw=False)
    assert sol.result == RESULTS.successful
    e = errors(sol, clean)
    assert e.max() < 1e-3, e  # from 2-9 cm, noise-free (the filter assumes 0.05 px)
    assert np.all(errors(sol, clean, 100) > e)  # still improving after 1 s
    noisy_sol = ekf(est, nath.stream(noisy), clean.omega_c, r_px=0.5, throw=False)
    assert errors(noisy_sol, noisy).max() < 3e-3
    stream = nath.stream(clean)
    broken = eqx.tree_at(lambda s: s.ys.x_b, stream, stream.ys.x_b.at[700, 0].set(jnp.nan))
    bad = ekf(est, broken, clean.omega_c, throw=False)
    assert bad.result == RESULTS.nonfinite_measurement and int(bad.failed_sample) == 700


def test_gradient_of_the_loss_with_respect_to_the_pixels(scenes, fits):
    clean, noisy, est = scenes
    out = fits[1].outputs
    stream = nath.stream(noisy)

    def loss(p_s):
        s = eqx.tree_at(lambda s: s.ys.p_s, stream, p_s)
        r = bundle_adjustment_residuals(
            out.A[-1], out.R_c[-1], out.x_c[-1], out.omega_s[-1], s, clean.omega_c
        )
        return jnp.sum(r**2)

    g = jax.jit(jax.grad(loss))(stream.ys.p_s)
    assert np.all(np.isfinite(g))
    # d/dp of the squared residual is 2 r
    r = bundle_adjustment_residuals(
        out.A[-1], out.R_c[-1], out.x_c[-1], out.omega_s[-1], stream, clean.omega_c
    )
    np.testing.assert_allclose(g[..., :2], 2 * r[:, : g.shape[1]], atol=1e-9)


def test_bad_arguments(scenes, no_jaxtyping):
    clean, _, est = scenes
    stream = nath.stream(clean)
    with pytest.raises(ValueError, match="omega_c"):
        bundle_adjustment(est, stream, clean.omega_c[:2])
    with pytest.raises(ValueError, match="window"):
        bundle_adjustment(est, stream, clean.omega_c, window=0)
    with pytest.raises(ValueError, match="estimator"):
        static_points_ekf(None, stream, clean.omega_c)
