"""The causal output filter: against SciPy's zero-order-hold discretisation, its stated
gain and delay, and under jit, vmap and grad."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.helpers import central_difference
from visjax.estimators import lowpass, lowpass_delay


def test_matches_scipy_zoh_and_states_its_gain_and_delay():
    import scipy.signal  # here, not at collection (a second of import in each worker)

    fc, h = 5.0, 1e-3
    ts = jnp.arange(4000, dtype=float) * h
    rng = np.random.default_rng(0)
    u = np.cumsum(rng.normal(size=(4000, 2)), axis=0) * 0.01 + 1.0
    w = 2 * np.pi * fc
    b, a, _ = scipy.signal.cont2discrete(([w**2], [1.0, np.sqrt(2) * w, w**2]), h, method="zoh")
    # SciPy's filter started at rest at u[0]: subtract it, filter, add it back
    ref = scipy.signal.lfilter(b.ravel(), a, u - u[0], axis=0) + u[0]
    np.testing.assert_allclose(lowpass(ts, u, fc), ref, atol=1e-10)
    # -3 dB at the cutoff, the stated delay well below it
    for f, gain in ((fc, 1 / np.sqrt(2)), (0.2, 1.0)):
        y = np.asarray(lowpass(ts, jnp.sin(2 * np.pi * f * ts), fc))[2000:]
        np.testing.assert_allclose(np.abs(y).max(), gain, rtol=2e-3)
    slow = np.asarray(lowpass(ts, jnp.sin(2 * np.pi * 0.2 * ts), fc))
    t_shift = np.asarray(ts) - lowpass_delay(fc)
    np.testing.assert_allclose(slow[2000:], np.sin(2 * np.pi * 0.2 * t_shift)[2000:], atol=2e-3)


def test_non_uniform_times_jit_vmap_grad():
    ts = jnp.cumsum(jnp.full(120, 2e-3).at[::7].set(3e-3))
    x = jnp.sin(3.0 * ts)
    f = jax.jit(lambda fc: jnp.sum(lowpass(ts, x, fc) ** 2))
    np.testing.assert_allclose(jax.grad(f)(4.0), central_difference(f, 4.0, 1e-4), rtol=1e-6)
    batch = jax.vmap(lambda fc: lowpass(ts, x, fc))(jnp.array([2.0, 8.0]))
    np.testing.assert_allclose(batch[1], lowpass(ts, x, 8.0), atol=1e-13)
    assert float(jnp.mean(jnp.abs(batch[0] - x))) > float(jnp.mean(jnp.abs(batch[1] - x)))


def test_errors(no_jaxtyping):
    with pytest.raises(ValueError, match="samples"):
        lowpass(jnp.arange(5.0), jnp.zeros((4, 2)), 1.0)
    with pytest.raises(ValueError, match="cutoff"):
        lowpass_delay(0.0)
