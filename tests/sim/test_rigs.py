"""General scene builders: sampling, the hold, pixel noise."""

import jax
import numpy as np
import pytest

from visjax.sim import add_pixel_noise, hold_indices, sample_times


def test_hold_indices_are_exact():
    held, first = hold_indices(30_000, 1000, 30)
    assert held[-1] == 899 and first.shape == (900,)
    # frame k arrives at the first fast sample j with j * 30 >= 1000 k
    np.testing.assert_array_equal(first, -((-1000 * np.arange(900)) // 30))
    np.testing.assert_array_equal(held[first], np.arange(900))


def test_noise_and_sampling_errors():
    p = np.zeros((500, 2))
    noisy = add_pixel_noise(jax.random.key(0), p, 0.5)
    assert 0.45 < float(np.std(noisy)) < 0.55
    np.testing.assert_array_equal(add_pixel_noise(None, p, 0.0), p)
    with pytest.raises(ValueError, match="non-negative"):
        add_pixel_noise(jax.random.key(0), p, -1.0)
    with pytest.raises(ValueError, match="key"):
        add_pixel_noise(None, p, 1.0)
    with pytest.raises(ValueError, match="must be positive"):
        sample_times(-1.0, 1000.0)
    assert sample_times(1.0, 30.0).shape == (30,)
