"""A moving point seen by a moving camera: camera-frame geometry, pixels, the camera's
velocity in its own frame and the true perspective state, from world-frame trajectories.

Convention: the camera's `Trajectory` gives its orientation `R` (columns: the camera's axes
in the world frame, so a camera-frame vector $r$ is $R r$ in the world) and the position
`x` of its optical centre in the world; its twist $[v, \\omega]$ is in the world frame. The
camera looks along its $+z$ axis. A world point $p$ is at $r = R^T (p - x)$ in the camera
frame; differentiating, $\\dot r = -(R^T\\omega) \\times r + R^T\\dot p - R^T v$, which is
Jang's thesis, eq. (2.5), with $v_c = R^T v$, $\\omega_c = R^T \\omega$ and the point's own
velocity $v_p = R^T \\dot p$ (all in the camera basis), and the state $x = [X/Z, Y/Z, 1/Z]$
then obeys eq. (2.11) (`visjax.kinematics.perspective_dynamics`).
"""

import functools
from typing import final

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .._util import as_float, check_shape
from ._trajectory import Trajectory


@final
class MovingPointScene(eqx.Module):
    """What a moving camera sees of a moving point, sample by sample.

    **Fields** (N samples, at the trajectory's times):

    - `ts` (N,).
    - `position` (N, 3): the point in the camera frame, $r = [X, Y, Z]$.
    - `pixels` (N, 2): its pixels $K_c [X/Z, Y/Z, 1]$; NaN where it is outside the image
        (a dropped frame) when an `image_size` was given.
    - `camera_velocity` (N, 6): $u = [v_c, \\omega_c]$, the camera's linear and angular
        velocity in the camera basis (what the thesis' observer consumes, eq. (2.11)).
    - `point_velocity` (N, 3): the point's own velocity $v_p$ in the camera basis (the
        unknown input, eq. (3.21)).
    - `x` (N, 3): the true state $[X/Z, Y/Z, 1/Z]$ (eq. (2.7)).
    - `in_view` (N,): whether the point projects inside the image (all `True` without an
        `image_size`).
    """

    ts: Float[Array, " N"]
    position: Float[Array, "N 3"]
    pixels: Float[Array, "N 2"]
    camera_velocity: Float[Array, "N 6"]
    point_velocity: Float[Array, "N 3"]
    x: Float[Array, "N 3"]
    in_view: Bool[Array, " N"]


def moving_point_scene(
    camera: Trajectory,
    point_position: Float[ArrayLike, "N 3"],
    point_velocity: Float[ArrayLike, "N 3"],
    K_c: Float[ArrayLike, "3 3"],
    *,
    image_size: tuple[float, float] | None = None,
) -> MovingPointScene:
    """A point moving in the world seen by a moving camera (conventions in the module's
    docstring; Jang's thesis, eqs. (2.5), (2.7), (2.11)).

    **Arguments:**

    - `camera`: the camera's `Trajectory` (world frame; twist in the world frame).
    - `point_position` (N, 3), `point_velocity` (N, 3): the point's world position and
        velocity at `camera.ts`.
    - `K_c` (3, 3): the intrinsic matrix, $p = K_c [X/Z, Y/Z, 1]$.
    - `image_size`: optional `(width, height)` in pixels; a point whose pixels fall outside
        $[0, w] \\times [0, h]$ is reported by `in_view` and its pixels are NaN (dropped,
        not reported: `visjax.estimators.moving_point_stream(..., dropped="hold")`
        holds the last frame).

    **Returns:** a `MovingPointScene`.

    A point behind the camera or on its focal plane ($Z \\le 0$) has no image and no state:
    with concrete inputs it raises `ValueError` (naming the first such sample) before any
    tracing; under `jit` the samples concerned get NaN pixels and a NaN state (and
    `in_view` False), never a finite placeholder.
    """
    point_position, point_velocity, K_c = (
        as_float(a) for a in (point_position, point_velocity, K_c)
    )
    if not isinstance(camera, Trajectory):
        raise ValueError(f"`camera` must be a visjax Trajectory; got {type(camera).__name__}.")
    n = camera.ts.shape[0]
    check_shape(point_position, (n, 3), "point_position")
    check_shape(point_velocity, (n, 3), "point_velocity")
    check_shape(K_c, (3, 3), "K_c")
    if image_size is not None:
        if len(image_size) != 2 or not all(float(s) > 0 for s in image_size):
            raise ValueError(
                f"`image_size` must be (width, height), both positive; got {image_size!r}."
            )

    size = None if image_size is None else tuple(float(s) for s in image_size)
    position, pixels, velocity, v_p, x, in_view = _moving_point_arrays(
        camera.R, camera.x, camera.twist, point_position, point_velocity, K_c, size
    )
    Z = position[:, 2]
    concrete = _concrete(Z)
    if concrete is not None and np.any(~(concrete > 0)):
        k = int(np.flatnonzero(~(concrete > 0))[0])
        raise ValueError(
            f"the point is behind the camera (or on its focal plane, or not finite) at sample "
            f"{k}: depth Z = {concrete[k]:.4g} <= 0 in the camera frame; it has no image "
            "(Jang's thesis, Assumption 2.1: the point stays in front of the camera)."
        )
    return MovingPointScene(
        ts=camera.ts,
        position=position,
        pixels=pixels,
        camera_velocity=velocity,
        point_velocity=v_p,
        x=x,
        in_view=in_view,
    )


@functools.partial(jax.jit, static_argnums=6)
def _moving_point_arrays(R, x_c, twist, point_position, point_velocity, K_c, image_size):
    # one compiled program per shape (called outside `jit`: not one per operation)
    R_T = jnp.swapaxes(R, -1, -2)
    position = jnp.einsum("nij,nj->ni", R_T, point_position - x_c)  # r = R^T (p - x)
    v_c = jnp.einsum("nij,nj->ni", R_T, twist[:, :3])
    w_c = jnp.einsum("nij,nj->ni", R_T, twist[:, 3:])
    v_p = jnp.einsum("nij,nj->ni", R_T, point_velocity)
    Z = position[:, 2]
    front = Z > 0
    Z_safe = jnp.where(front, Z, 1.0)
    x = jnp.stack([position[:, 0] / Z_safe, position[:, 1] / Z_safe, 1.0 / Z_safe], axis=1)
    x = jnp.where(front[:, None], x, jnp.nan)  # eq. (2.7); no state behind the camera
    pixels = x[:, :2] @ K_c[:2, :2].T + K_c[None, :2, 2]
    in_view = front
    if image_size is not None:
        w, h = image_size
        inside = (
            (pixels[:, 0] >= 0.0)
            & (pixels[:, 0] <= w)
            & (pixels[:, 1] >= 0.0)
            & (pixels[:, 1] <= h)
        )
        in_view = in_view & inside
    pixels = jnp.where(in_view[:, None], pixels, jnp.nan)
    return position, pixels, jnp.concatenate([v_c, w_c], axis=1), v_p, x, in_view



def _concrete(x):
    """`x` as a NumPy array if it is concrete (not traced), else `None`."""
    try:
        return np.asarray(x)
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
        return None
