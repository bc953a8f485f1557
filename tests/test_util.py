"""Helpers shared by every package (`visjax._util`): the sample interval of concrete times
reduced without a sort in the compiled program, and the "did you mean" hint."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax._util import did_you_mean, median_interval

TS = np.cumsum(np.r_[0.0, np.full(999, 1e-3), np.full(1000, 2e-3)])[:1999]


def test_median_interval_of_concrete_times_is_numpy_and_folds_nothing():
    """Concrete times, also closed over inside `jit`: NumPy's median, and no sort left in
    the program for XLA to constant-fold; traced times: the same value, under `vmap` and
    `grad` (d median / d t of the middle interval's ends)."""
    expected = np.median(np.diff(TS))
    assert float(median_interval(TS)) == expected
    times = jnp.asarray(TS)  # a JAX array made outside, closed over by the program
    closed = jax.make_jaxpr(lambda x: x * median_interval(times))(1.0)
    assert "sort" not in str(closed)
    assert float(jax.jit(lambda x: x * median_interval(times))(1.0)) == expected
    assert "sort" in str(jax.make_jaxpr(lambda x: x * jnp.median(jnp.diff(times)))(1.0))
    traced = jax.jit(median_interval)(jnp.asarray(TS))
    assert float(traced) == pytest.approx(expected, rel=1e-15)
    batch = jax.vmap(median_interval)(jnp.stack([jnp.asarray(TS), 2.0 * jnp.asarray(TS)]))
    np.testing.assert_allclose(batch, [expected, 2.0 * expected], rtol=1e-15)
    t = jnp.array([0.0, 1.0, 3.0, 6.0])  # intervals 1, 2, 3: the median is t2 - t1
    np.testing.assert_allclose(jax.grad(median_interval)(t), [0.0, -1.0, 1.0, 0.0])


@pytest.mark.parametrize(
    "name, choices, ignore_case, hint",
    [
        ("velocty", ["velocity", "moving_point"], False, " (did you mean 'velocity'?)"),
        ("k_SCALE", ["K_scale", "rho_scale"], True, " (did you mean 'K_scale'?)"),
        ("k_SCALE", ["K_scale", "rho_scale"], False, ""),
        ("nosuch", ["velocity", "moving_point"], False, ""),
    ],
)
def test_did_you_mean_names_the_closest_choice_or_nothing(name, choices, ignore_case, hint):
    assert did_you_mean(name, choices, ignore_case=ignore_case) == hint
