"""A registered toy problem whose every chunk takes a while (a host sleep per chunk), for
the tests that interrupt a sweep in a subprocess: `visjax --import tests.studies.slow_toy
sweep slow-toy ...`."""

import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from visjax import studies
from visjax._results import RESULTS


class Estimate(eqx.Module):
    value: jax.Array
    result: RESULTS


def _sleep(x):
    time.sleep(0.25)
    return np.asarray(x)


class SlowMean(studies.AbstractProblem):
    """A weighted mean of noisy samples of 2 (as `tests.studies.test_problem.Mean`), each
    chunk held 0.25 s on the host."""

    methods = ("estimator",)
    metric = "error"
    grid = "gain=0.1:10:3"

    samples: jax.Array
    noise: float = eqx.field(static=True, default=0.1)

    def parameters(self):
        return {"gain": studies.Parameter(1.0, "-", True, "the weights' decay")}

    def inputs(self, key):
        return self.samples + self.noise * jax.random.normal(key, self.samples.shape)

    def solve(self, method, params, inputs, *, outputs=False):
        inputs = jax.pure_callback(
            _sleep, jax.ShapeDtypeStruct(inputs.shape, inputs.dtype), inputs,
            vmap_method="expand_dims",
        )  # fmt: skip
        i = jnp.arange(inputs.shape[0], dtype=inputs.dtype)
        w = jnp.exp(-params["gain"] * i / inputs.shape[0])
        return Estimate(jnp.sum(w * inputs) / jnp.sum(w), RESULTS.successful)

    def metrics(self, method, solution):
        return {"error": jnp.abs(solution.value - 2.0)}


def slow_toy(*, noise_px: float = 0.1):
    return SlowMean(samples=jnp.full(16, 2.0), noise=float(noise_px))


studies.register_problem("slow-toy", slow_toy, summary="a toy whose chunks are slow")
