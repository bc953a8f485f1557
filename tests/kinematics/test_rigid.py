"""Rigid-body motion: the pose integrated from a twist, and its gradient."""

import jax
import jax.numpy as jnp
import numpy as np

from visjax.kinematics import integrate_pose
from visjax.sim import integrate_twist


def test_integrate_pose_gradient():
    """x_f(T) = x0 + a (1 - cos T) for v = a sin t: d x_f(T) / d a = 1 - cos T."""
    ts = jnp.linspace(0.0, 2.0, 5)

    def final_x(a):
        x, _ = integrate_pose(lambda t: a * jnp.sin(t) * jnp.ones(6), jnp.zeros(3), jnp.eye(3), ts)
        return x[-1, 0]

    np.testing.assert_allclose(jax.jit(final_x)(0.3), 0.3 * (1 - np.cos(2.0)), rtol=1e-10)
    np.testing.assert_allclose(jax.jit(jax.grad(final_x))(0.3), 1 - np.cos(2.0), rtol=1e-8)
    xs = jax.jit(jax.vmap(final_x))(jnp.array([0.1, 0.2]))
    np.testing.assert_allclose(xs, np.array([0.1, 0.2]) * (1 - np.cos(2.0)), rtol=1e-10)


def test_integrate_twist_closed_form():
    """A constant twist: x = x0 + v t, R = exp(t [w]x) R0; the twist is sampled back."""
    from visjax.geometry import so3_exp

    v = jnp.array([0.1, -0.2, 0.05, 0.3, 0.0, -0.1])
    ts = jnp.linspace(0.0, 1.5, 4)
    traj = integrate_twist(lambda t: v, jnp.ones(3), jnp.eye(3), ts)
    np.testing.assert_allclose(traj.x, 1.0 + ts[:, None] * v[None, :3], rtol=1e-10)
    R = np.stack([np.asarray(so3_exp(t * v[3:])) for t in ts])
    np.testing.assert_allclose(traj.R, R, atol=1e-10)
    np.testing.assert_allclose(traj.twist, np.broadcast_to(v, (4, 6)))
