"""jit, vmap and grad of the helper functions of Chitrakaran et al., against finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.helpers import central_difference
from visjax import RESULTS
from visjax.estimators import (
    depth_from_known_length,
    diagonal_intersection,
    fixed_camera,
    kinematics_jacobian,
)
from visjax.papers.chitrakaran import section6_scenario as fixed_camera_scenario


def test_depth_and_diagonal_jit_vmap_grad():
    sc = fixed_camera_scenario(0.3, 1000.0)

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

    # fixed_camera(throw=False): the same value where the premise holds, a result code
    # where not (an origin pixel off the object origin), under vmap, no error
    def quiet(shift):
        camera = fixed_camera(
            sc.pixels[:2], sc.A, sc.R_star, sc.s[0], n_star=sc.n_star,
            origin_pixel=diagonal_intersection(p_ref) + shift, throw=False,
        )  # fmt: skip
        return camera.z1_star, camera.result._value

    shifts = np.array([[0.0, 0.0], [40.0, -25.0]])
    z, codes = jax.jit(jax.vmap(quiet))(shifts)
    np.testing.assert_allclose(z[0], sc.z1_star, rtol=1e-10)
    assert codes[0] == RESULTS.successful._value
    assert codes[1] == RESULTS.depth_recovery_failed._value


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


def test_depth_recovery_refuses_a_broken_premise():
    """An irregular quadrilateral whose plane misses the object origin by 2 cm: version 1
    returned z1* = 0.706 (true 1.302) without a word; now the residual of R* s1 = d* w
    is checked and it raises."""
    from visjax.geometry import project
    from visjax.papers.chitrakaran import A_EQ62, R_STAR_EQ61

    A, R_star = jnp.array(A_EQ62), jnp.array(R_STAR_EQ61)
    x_f_star = jnp.array([0.0, 0.0, 1.3])
    s = jnp.array([[-0.1, 0.12, 0.02], [0.13, 0.1, 0.02], [0.09, -0.1, 0.02], [-0.12, -0.08, 0.02]])
    p_ref = project(x_f_star[None, :] + s @ R_star.T, A).pixels
    n_star = R_star @ jnp.array([0.0, 0.0, 1.0])
    n_star = jnp.where(n_star @ (x_f_star + R_star @ s[0]) > 0, n_star, -n_star)
    with pytest.raises(RuntimeError, match="does not hold"):
        depth_from_known_length(p_ref[0], diagonal_intersection(p_ref), A, n_star, R_star, s[0])
    # the section-6 square (a parallelogram centred on the origin) passes, exactly
    sc = fixed_camera_scenario(0.3, 1000.0)
    z1 = depth_from_known_length(
        sc.pixels[0, 0], diagonal_intersection(sc.pixels[0]), sc.A, sc.n_star, sc.R_star, sc.s[0]
    )
    np.testing.assert_allclose(z1, sc.z1_star, rtol=1e-10)
