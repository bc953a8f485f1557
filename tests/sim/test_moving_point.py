"""`sim.moving_point_scene`: a moving point seen by a moving camera, against the
perspective dynamics (Jang's thesis, eq. (2.11)) integrated independently."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.helpers import central_difference
from visjax.geometry import so3_exp
from visjax.sim import Trajectory, moving_camera_point, moving_point_scene

K_C = np.array([[800.0, 2.0, 320.0], [0.0, 780.0, 240.0], [0.0, 0.0, 1.0]])
W = jnp.array([0.05, -0.08, 0.12])  # the camera's constant angular velocity (world frame)
R0 = so3_exp(jnp.array([0.1, -0.2, 0.05]))
X0 = jnp.array([0.2, -0.1, 0.0])


def camera_pose(t):
    """A camera turning at the constant rate W and translating on a sinusoid (closed form):
    R(t) = exp(t [W]x) R0, x(t) = X0 + [0.3 sin(1.1 t), 0.1 t, 0.05 cos(0.7 t) - 0.05]."""
    R = so3_exp(t * W) @ R0
    x = X0 + jnp.array([0.3 * jnp.sin(1.1 * t), 0.1 * t, 0.05 * jnp.cos(0.7 * t) - 0.05])
    v = jnp.array([0.33 * jnp.cos(1.1 * t), 0.1, -0.035 * jnp.sin(0.7 * t)])
    return R, x, v


def point(t):
    """The point's world position and velocity (closed form)."""
    p = jnp.array([0.1 + 0.05 * t, -0.2 + 0.1 * jnp.sin(0.9 * t), 2.5 + 0.02 * t])
    v = jnp.array([0.05, 0.09 * jnp.cos(0.9 * t), 0.02])
    return p, v


def build(ts, **kw):
    R, x, v = jax.vmap(camera_pose)(ts)
    twist = jnp.concatenate([v, jnp.broadcast_to(W, v.shape)], axis=1)
    p, vp = jax.vmap(point)(ts)
    return moving_point_scene(Trajectory(ts=ts, R=R, x=x, twist=twist), p, vp, K_C, **kw)


def test_state_agrees_with_integrating_eq_2_11():
    """The builder's state (geometry at each sample) equals the perspective dynamics (2.11)
    integrated from the same start with the camera-frame velocities the builder reports
    (computed here independently, as functions of time)."""
    ts = jnp.linspace(0.0, 4.0, 81)
    sc = build(ts)

    def camera_twist(t):  # [v_c, w_c] in the camera basis
        R, _, v = camera_pose(t)
        return jnp.concatenate([R.T @ v, R.T @ W])

    def point_velocity(t):
        R, _, _ = camera_pose(t)
        return R.T @ point(t)[1]

    x = moving_camera_point(camera_twist, point_velocity, sc.x[0], ts)
    np.testing.assert_allclose(sc.x, x, rtol=0, atol=1e-8)
    assert float(jnp.max(jnp.abs(sc.x[-1] - sc.x[0]))) > 0.05  # it did move
    # the reported velocities are the same camera-frame quantities
    np.testing.assert_allclose(sc.camera_velocity, jax.vmap(camera_twist)(ts), atol=1e-14)
    np.testing.assert_allclose(sc.point_velocity, jax.vmap(point_velocity)(ts), atol=1e-14)
    # pixels through K_c, the state from the camera-frame position
    pix = sc.x[:, :2] @ K_C[:2, :2].T + K_C[None, :2, 2]
    np.testing.assert_allclose(sc.pixels, pix, rtol=1e-14)
    np.testing.assert_allclose(sc.x[:, 2] * sc.position[:, 2], 1.0, rtol=1e-14)
    assert bool(jnp.all(sc.in_view))


def test_behind_the_camera_is_refused_and_nan_under_jit():
    ts = jnp.linspace(0.0, 1.0, 11)
    R = jnp.broadcast_to(jnp.eye(3), (11, 3, 3))
    x = jnp.zeros((11, 3))
    twist = jnp.zeros((11, 6))
    cam = Trajectory(ts=ts, R=R, x=x, twist=twist)
    p = jnp.stack([0.1 * ts, 0.0 * ts, 1.0 - 2.0 * ts], axis=1)  # crosses Z = 0 at t = 0.5
    vp = jnp.broadcast_to(jnp.array([0.1, 0.0, -2.0]), (11, 3))
    with pytest.raises(ValueError, match="behind the camera .* at sample 5"):
        moving_point_scene(cam, p, vp, K_C)
    sc = jax.jit(lambda p: moving_point_scene(cam, p, vp, K_C))(p)
    behind = np.asarray(p[:, 2] <= 0)
    assert behind.sum() == 6
    assert np.all(np.isnan(sc.x[behind])) and np.all(np.isnan(sc.pixels[behind]))
    assert np.all(np.isfinite(sc.x[~behind])) and np.all(np.isfinite(sc.pixels[~behind]))
    np.testing.assert_array_equal(np.asarray(sc.in_view), ~behind)


def test_outside_the_image_is_masked():
    ts = jnp.linspace(0.0, 4.0, 41)
    sc = build(ts)
    full = sc.pixels
    # an image that the point leaves: everything with u > 640 px is outside
    masked = build(ts, image_size=(640.0, 480.0))
    out = np.asarray((full[:, 0] > 640.0) | (full[:, 0] < 0) | (full[:, 1] > 480.0))
    assert 0 < out.sum() < out.size
    np.testing.assert_array_equal(np.asarray(masked.in_view), ~out)
    assert np.all(np.isnan(masked.pixels[out]))
    np.testing.assert_array_equal(masked.pixels[~out], full[~out])
    np.testing.assert_array_equal(masked.x, sc.x)  # the truth stays


def test_shapes_are_refused_before_tracing(no_jaxtyping):
    ts = jnp.linspace(0.0, 1.0, 5)
    R = jnp.broadcast_to(jnp.eye(3), (5, 3, 3))
    cam = Trajectory(ts=ts, R=R, x=jnp.zeros((5, 3)), twist=jnp.zeros((5, 6)))
    p = jnp.ones((5, 3))
    with pytest.raises(ValueError, match=r"`point_position` must have shape \(5, 3\)"):
        moving_point_scene(cam, jnp.ones((4, 3)), p, K_C)
    with pytest.raises(ValueError, match=r"`point_velocity` must have shape \(5, 3\)"):
        moving_point_scene(cam, p, jnp.ones((5, 2)), K_C)
    with pytest.raises(ValueError, match=r"`K_c` must have shape \(3, 3\)"):
        moving_point_scene(cam, p, p, jnp.eye(2))
    with pytest.raises(ValueError, match="`image_size`"):
        moving_point_scene(cam, p, p, K_C, image_size=(640.0, -1.0))


def test_jit_vmap_grad():
    ts = jnp.linspace(0.0, 2.0, 21)
    R, x, v = jax.vmap(camera_pose)(ts)
    twist = jnp.concatenate([v, jnp.broadcast_to(W, v.shape)], axis=1)
    cam = Trajectory(ts=ts, R=R, x=x, twist=twist)
    p, vp = jax.vmap(point)(ts)

    def depth_sum(offset):  # the point shifted by a world offset
        return jnp.sum(moving_point_scene(cam, p + offset[None, :], vp, K_C).x[:, 2])

    off = jnp.array([0.01, -0.02, 0.03])
    batch = jnp.stack([off, 2 * off, -off])
    np.testing.assert_allclose(
        jax.jit(jax.vmap(depth_sum))(batch), [depth_sum(o) for o in batch], rtol=1e-13
    )
    g = jax.grad(depth_sum)(off)
    fd = central_difference(depth_sum, np.asarray(off), 1e-6)
    np.testing.assert_allclose(g, fd, rtol=1e-7)
