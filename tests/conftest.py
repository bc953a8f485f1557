"""Tests run in float64 with strict dtype promotion (no silent float32 -> float64)."""

import jax
import numpy as np
import pytest

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")


@pytest.fixture
def getkey():
    """A fresh PRNG key per call, deterministic per test."""
    state = {"key": jax.random.key(0)}

    def _getkey():
        state["key"], sub = jax.random.split(state["key"])
        return sub

    return _getkey


def central_difference(f, x, h):
    """Central finite-difference Jacobian of `f` at `x`, all perturbations in one vmapped call."""
    x = np.asarray(x, dtype=np.float64)
    E = np.eye(x.size).reshape((x.size,) + x.shape) * h
    fb = jax.jit(jax.vmap(f))
    d = (np.asarray(fb(x + E)) - np.asarray(fb(x - E))) / (2 * h)  # (x.size, *out)
    return np.moveaxis(d, 0, -1).reshape(d.shape[1:] + x.shape)
