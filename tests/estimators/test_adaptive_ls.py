"""Seed 004: the adaptive camera law and the least-squares structure law (noise-free sim)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax.estimators import AdaptiveStructureEstimator, Stream, platform_measurements, run
from visjax.sim import uncalibrated_scenario
from visjax.studies import DEFAULT_GAINS, euclidean_experiment, final_errors, initial_estimator


@pytest.fixture(scope="module")
def runs():
    return {exc: euclidean_experiment(20.0, exciting=exc) for exc in (True, False)}


def test_structure_converges_noise_free(runs):
    """Initial errors 10-16 cm; after 20 s every feature within 1.5 mm (measured 0.4-1.1)."""
    r = runs[True]
    err0 = np.linalg.norm(np.asarray(r.omega_s[0] - r.omega_true), axis=-1)
    assert np.all(err0 > 0.09)
    final = final_errors(r)
    assert np.all(final < 1.5e-3), final
    # the camera-parameter prediction error goes to zero: from ~22 px to below 1.5 px
    pc = np.asarray(r.p_tilde_c)
    assert pc[0].max() > 15.0
    assert pc[-200:].max() < 1.5
    assert pc[-200:].max() < 0.1 * pc[0].max()


def test_resetting_and_projection(runs):
    r = runs[True]
    assert float(r.resets[-1]) >= 5  # eq. (39): the covariance is reset, about once a second
    lam = np.asarray(r.lambda_min_gamma_c)
    assert np.all(lam >= DEFAULT_GAINS["eta1"] * (1 - 1e-9))
    assert np.all(lam <= DEFAULT_GAINS["eta0"] * (1 + 1e-9))
    for run_ in runs.values():  # every predicted depth stays above the projection margin
        assert np.asarray(run_.depth_s).min() > DEFAULT_GAINS["eps_s"]
        assert np.asarray(run_.depth_c).min() > DEFAULT_GAINS["eps_c"]


def test_pe_measure_detects_a_non_exciting_trajectory(runs):
    """Pure translation along the optical axis: eq. (49) fails, the structure stalls."""
    exciting = np.nanmedian(np.asarray(runs[True].pe), axis=0)
    flat = np.nanmedian(np.asarray(runs[False].pe), axis=0)
    assert np.all(exciting > 1e-3)
    assert np.all(flat < 1e-4) and np.all(flat < 0.05 * exciting)  # measured ~3e-5 vs 4e-3
    assert final_errors(runs[False]).max() > 0.02  # centimetres off after 20 s


def test_vmap_over_noise_seeds_and_grad():
    sc = uncalibrated_scenario(1.0)

    def final_error(key, gamma_s0):
        p_s = sc.p_s + 0.5 * jax.random.normal(key, sc.p_s.shape)
        ys = platform_measurements(sc.R_b, sc.x_b, p_s, sc.p_c, sc.omega_c)
        est = initial_estimator(sc)
        est = AdaptiveStructureEstimator(
            **{**{f: getattr(est, f) for f in est.__dataclass_fields__}, "gamma_s0": gamma_s0}
        )
        out = run(est, Stream(ts=sc.ts, ys=ys), save_every=None).final_state
        theta_s = out[2]
        return jnp.sum((theta_s[:, :3] / theta_s[:, 3:] - sc.omega_s) ** 2)

    keys = jax.random.split(jax.random.key(0), 2)
    g0 = jnp.asarray(DEFAULT_GAINS["gamma_s0"])
    batched = jax.jit(jax.vmap(final_error, in_axes=(0, None)))(keys, g0)
    np.testing.assert_allclose(batched[1], final_error(keys[1], g0), rtol=1e-9)
    grad = jax.grad(final_error, argnums=1)(keys[0], g0)
    assert np.isfinite(grad) and grad != 0


def test_bad_settings():
    sc = uncalibrated_scenario(0.01)
    with pytest.raises(ValueError, match="eta0 > eta1"):
        initial_estimator(sc, {"eta0": 1e-8, "eta1": 1e-7})
    with pytest.raises(ValueError, match="known features"):
        platform_measurements(sc.R_b, sc.x_b, sc.p_s, sc.p_c, sc.omega_c[:2])
