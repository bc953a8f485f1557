"""jit, vmap and grad of the seed-000 helper functions, against finite differences."""

import jax
import jax.numpy as jnp
import numpy as np

from tests.helpers import central_difference
from visjax.estimators import depth_from_known_length, diagonal_intersection, kinematics_jacobian
from visjax.papers.chitrakaran import section6_scenario as fixed_camera_scenario


def test_depth_and_diagonal_jit_vmap_grad():
    sc = fixed_camera_scenario(0.2, 1000.0)

    def z1(p_ref):
        p0 = diagonal_intersection(p_ref)
        return depth_from_known_length(p_ref[0], p0, sc.A, sc.n_star, sc.R_star, sc.s[0])

    p_ref = np.asarray(sc.pixels[0])
    np.testing.assert_allclose(jax.jit(z1)(p_ref), sc.z1_star, rtol=1e-10)
    g = jax.jit(jax.grad(z1))(p_ref)
    np.testing.assert_allclose(g, central_difference(z1, p_ref, 1e-4), rtol=1e-6, atol=1e-10)
    batched = jax.jit(jax.vmap(diagonal_intersection))(sc.pixels[::50])
    for i, p in enumerate(sc.pixels[::50]):
        np.testing.assert_allclose(batched[i], diagonal_intersection(p), rtol=1e-14)


def test_kinematics_jacobian_grad():
    A = jnp.array([[1268.16, 0.0, 257.49], [0.0, 1267.50, 253.10], [0.0, 0.0, 1.0]])

    def f(x):
        J, J_inv = kinematics_jacobian(
            A, x[:2], x[2], 1.99, jnp.eye(3), jnp.array([-0.1, 0.1, 0.01]), x[3:]
        )
        return jnp.concatenate([J.ravel(), J_inv.ravel()])

    x0 = np.array([0.05, -0.03, 1.1, 0.2, -0.1, 0.3])
    np.testing.assert_allclose(
        jax.jit(jax.jacfwd(f))(x0), central_difference(f, x0, 1e-6), rtol=1e-6, atol=1e-6
    )
