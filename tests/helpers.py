"""Shared test helpers: tree comparison and finite differences."""

import jax
import numpy as np


def tree_allclose(a, b, *, rtol=1e-12, atol=0.0) -> bool:
    """Whether two pytrees have the same structure and allclose leaves."""
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    if ta != tb:
        return False
    return all(np.allclose(x, y, rtol=rtol, atol=atol, equal_nan=False) for x, y in zip(la, lb))


_BATCHED: dict = {}


def central_difference(f, x, h):
    """Central finite-difference Jacobian of `f` at `x`, all perturbations in one vmapped call."""
    x = np.asarray(x, dtype=np.float64)
    E = np.eye(x.size).reshape((x.size,) + x.shape) * h
    fb = _BATCHED.get(f)
    if fb is None:  # compiled once per function (and shape), not once per call
        fb = _BATCHED[f] = jax.jit(jax.vmap(f))
    d = (np.asarray(fb(x + E)) - np.asarray(fb(x - E))) / (2 * h)  # (x.size, *out)
    return np.moveaxis(d, 0, -1).reshape(d.shape[1:] + x.shape)


class without_jaxtyping:
    """The user's view: jaxtyping's runtime checks (on for the test run) off inside the
    block, so that the library's own `ValueError` for a wrong shape is what is tested."""

    def __enter__(self):
        import jaxtyping

        jaxtyping.config.update("jaxtyping_disable", True)

    def __exit__(self, *exc):
        import jaxtyping

        jaxtyping.config.update("jaxtyping_disable", False)
        return False
