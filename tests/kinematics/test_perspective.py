"""The perspective dynamics of a point seen by a moving camera (Jang's thesis, eq. (2.11))."""

import jax
import jax.numpy as jnp
import numpy as np

from visjax.kinematics import camera_term, known_input_term, perspective_dynamics


def test_perspective_dynamics_is_the_derivative_of_the_projection():
    """(2.11) equals d/dt [X/Z, Y/Z, 1/Z] along (2.5): r_dot = v_p - v_c + r x w."""
    rng = np.random.default_rng(0)
    for _ in range(5):
        r = np.array([0.3, -0.2, 1.5]) + 0.1 * rng.normal(size=3)
        u = rng.normal(size=6)
        v_p = rng.normal(size=3)
        r_dot = v_p - u[:3] + np.cross(r, u[3:])
        state = lambda r: jnp.stack([r[0] / r[2], r[1] / r[2], 1.0 / r[2]])  # noqa: E731
        _, x_dot = jax.jvp(state, (jnp.asarray(r),), (jnp.asarray(r_dot),))
        x = state(r)
        np.testing.assert_allclose(perspective_dynamics(x, u, v_p), x_dot, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(
            camera_term(x, u) + known_input_term(x[:2], u), perspective_dynamics(x, u, np.zeros(3))
        )
