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


def euclidean_scene_file(path, duration: float, rate_hz: float):
    """The project's scene of Nath et al. (`papers.nath.scenario`) written as a
    `StaticPointsData` file at `path`, with its nominal camera and true features."""
    import jax.numpy as jnp
    import numpy as np

    from visjax.io import StaticPointsData
    from visjax.papers import nath

    sc = nath.scenario(duration, rate_hz)
    A0, R0, x0 = nath.nominal_camera()
    return StaticPointsData(
        t=np.asarray(sc.ts),
        pixels=np.asarray(jnp.concatenate([sc.p_c, sc.p_s], 1)),
        platform_R=np.asarray(sc.R_b),
        platform_x=np.asarray(sc.x_b),
        known_features=np.asarray(sc.omega_c),
        A_nominal=np.asarray(A0),
        R_c_nominal=np.asarray(R0),
        x_c_nominal=np.asarray(x0),
        features=np.asarray(sc.omega_s),
    ).save(path)
