"""Camera rigs: what a camera sees of points, for a fixed camera, a camera moving with a
measured velocity, and a camera mounted on a moving platform."""

from collections.abc import Callable

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from .._util import as_float, check_shape
from ..geometry import feature_in_camera, project
from ..kinematics import perspective_dynamics
from ._trajectory import Trajectory


def fixed_camera_pixels(
    body: Trajectory, points: Float[ArrayLike, "n 3"], A: Float[ArrayLike, "3 3"]
) -> Float[Array, "N n 2"]:
    """Pixels of points fixed on a moving body, seen by a fixed camera whose frame is the
    fixed frame: $\\bar m_i = x + R s_i$ (Chitrakaran et al., eq. (5)), then $p_i = A m_i$
    (eq. (15)).

    **Arguments:** `body` the body's `Trajectory`; `points` (n, 3) the points in the body
    frame; `A` the intrinsics.
    """
    points = as_float(points)
    check_shape(points, (None, 3), "points")
    world = body.x[:, None, :] + jnp.einsum("nij,kj->nki", body.R, points)
    return jax.vmap(lambda P: project(P, A).pixels)(world)


def platform_camera_pixels(
    R_b: Float[ArrayLike, "N 3 3"],
    x_b: Float[ArrayLike, "N 3"],
    R_c: Float[ArrayLike, "3 3"],
    x_c: Float[ArrayLike, "3"],
    A: Float[ArrayLike, "3 3"],
    points: Float[ArrayLike, "n 3"],
) -> Float[Array, "N n 2"]:
    """Pixels of static world points seen by a camera mounted at `(R_c, x_c)` on a platform
    whose pose `(R_b, x_b)` moves (Nath et al., eqs. (1)-(4); `geometry.feature_in_camera`)."""
    R_b, x_b, points = as_float(R_b), as_float(x_b), as_float(points)
    check_shape(points, (None, 3), "points")

    def one(R, x):
        m_bar = jax.vmap(lambda w: feature_in_camera(w, R, x, R_c, x_c))(points)
        return project(m_bar, A).pixels

    return jax.vmap(one)(R_b, x_b)


class _PerspectiveField(eqx.Module):
    """Jang's thesis, eq. (2.11), with the camera's and the point's velocities of time (a
    Module: diffrax's compiled solve is reused by every call with equal velocities)."""

    camera_twist: Callable
    point_velocity: Callable

    def __call__(self, t, x, args):
        return perspective_dynamics(x, self.camera_twist(t), self.point_velocity(t))


def moving_camera_point(
    camera_twist: Callable[[Array], Array],
    point_velocity: Callable[[Array], Array],
    x0: Float[ArrayLike, "3"],
    ts: Float[ArrayLike, " N"],
) -> Float[Array, "N 3"]:
    """The state $x = [X/Z, Y/Z, 1/Z]$ of a point seen by a moving camera, integrated from
    the perspective dynamics (Jang's thesis, eq. (2.11)) with an 8th-order solver at
    tolerance 1e-11.

    **Arguments:** `camera_twist(t)` $= [v_c, \\omega]$ in the camera basis; `point_velocity(t)`
    the point's own velocity $v_p$ (camera basis); `x0` the state at `ts[0]`; `ts`.
    """
    ts, x0 = as_float(ts), as_float(x0)
    check_shape(x0, (3,), "x0")

    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(_PerspectiveField(camera_twist, point_velocity)),
        diffrax.Dopri8(),
        ts[0],
        ts[-1],
        None,
        x0,
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=diffrax.PIDController(rtol=1e-11, atol=1e-13),
        max_steps=200_000,
    )
    return sol.ys


def add_pixel_noise(
    key: PRNGKeyArray | None, pixels: Float[ArrayLike, "..."], sigma: Float[ArrayLike, ""]
) -> Float[Array, "..."]:
    """Pixels plus i.i.d. Gaussian noise of standard deviation `sigma` (px) on every
    coordinate; `sigma = 0` returns them unchanged (then `key` may be `None`)."""
    pixels = as_float(pixels)
    try:
        level = float(sigma)
    except (TypeError, jax.errors.ConcretizationTypeError):
        level = None  # traced (a sweep over noise levels)
    if level is None or isinstance(sigma, jax.Array):  # no Python branch on an array's value
        if key is None:
            raise ValueError("a PRNG `key` is required for a traced pixel noise level.")
        sigma = eqx.error_if(sigma, sigma < 0, "the pixel noise must be non-negative")
        return pixels + sigma * jax.random.normal(key, pixels.shape, pixels.dtype)
    if not sigma >= 0:
        raise ValueError(f"the pixel noise must be non-negative; got {sigma!r}.")
    if sigma == 0:
        return pixels
    if key is None:
        raise ValueError("a PRNG `key` is required for pixel noise > 0.")
    return pixels + sigma * jax.random.normal(key, pixels.shape, pixels.dtype)


def hold_indices(n: int, rate_hz: int, camera_hz: int):
    """For each of `n` samples at `rate_hz`, the index of the latest camera frame at
    `camera_hz` (zero-order hold), and the fast-rate index of each frame; integer
    arithmetic, exact. NumPy, static."""
    held = (np.arange(n) * camera_hz) // rate_hz
    first = np.searchsorted(held, np.arange(held[-1] + 1))
    return held, first
