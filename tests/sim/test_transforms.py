"""The general builders and the UIO's stream builder under jit, vmap and grad."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax.estimators import moving_point_stream
from visjax.sim import add_pixel_noise, fixed_camera_pixels, integrate_twist, platform_camera_pixels

A = jnp.array([[800.0, 0.0, 320.0], [0.0, 790.0, 240.0], [0.0, 0.0, 1.0]])
TS = jnp.linspace(0.0, 1.0, 5)


def _pixels(a, points):
    body = integrate_twist(
        lambda t: a * jnp.sin(t) * jnp.ones(6), jnp.array([0, 0, 2.0]), jnp.eye(3), TS
    )
    return fixed_camera_pixels(body, points, A)


@pytest.mark.slow  # the unit tier's time: 9 s of compiles
def test_fixed_camera_pixels_jit_vmap_grad():
    points = jnp.array([[0.1, 0.0, 0.0], [0.0, 0.1, 0.0]])
    f = jax.jit(lambda a: jnp.sum(_pixels(a, points)))
    batched = jax.vmap(f)(jnp.array([0.1, 0.2]))
    np.testing.assert_allclose(batched[1], f(0.2), rtol=1e-12)
    g = jax.grad(f)(0.1)
    fd = (f(0.1 + 1e-6) - f(0.1 - 1e-6)) / 2e-6
    np.testing.assert_allclose(g, fd, rtol=1e-6)


def test_platform_camera_pixels_and_noise_jit_vmap_grad():
    R_b = jnp.broadcast_to(jnp.eye(3), (5, 3, 3))
    points = jnp.array([[0.0, 0.1, 1.5], [0.1, -0.1, 1.6]])

    def f(x, key):
        x_b = jnp.stack([x * TS, jnp.zeros(5), jnp.zeros(5)], axis=1)
        p = platform_camera_pixels(R_b, x_b, jnp.eye(3), jnp.zeros(3), A, points)
        return jnp.sum(add_pixel_noise(key, p, 0.1))

    keys = jax.random.split(jax.random.key(0), 2)
    batched = jax.jit(jax.vmap(f, in_axes=(None, 0)))(0.2, keys)
    np.testing.assert_allclose(batched[0], f(0.2, keys[0]), rtol=1e-12)
    # u = 800 (X - x_b) / Z + 320: d/dx sum_u = -800 sum_t t sum_i 1 / Z_i
    expected = -800.0 * float(jnp.sum(TS)) * (1 / 1.5 + 1 / 1.6)
    np.testing.assert_allclose(jax.grad(f)(0.2, keys[0]), expected, rtol=1e-12)


def test_moving_camera_stream_jit_vmap_grad():
    pixels = jnp.stack([320.0 + 10.0 * TS, 240.0 - 5.0 * TS], axis=1)
    u = jnp.zeros((5, 6))
    f = jax.jit(lambda p: jnp.sum(moving_point_stream(TS, p, u, A).ys.y))
    np.testing.assert_allclose(jax.grad(f)(pixels), np.tile([1 / 800.0, 1 / 790.0], (5, 1)))
    batched = jax.vmap(f)(jnp.stack([pixels, pixels + 1.0]))
    np.testing.assert_allclose(batched[1] - batched[0], 5 * (1 / 800.0 + 1 / 790.0), rtol=1e-10)
