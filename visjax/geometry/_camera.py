"""Pinhole camera: the intrinsic matrix, pixel <-> normalized coordinates, projection.

Source: Chitrakaran et al., eqs. (10), (14), (15) and (22).

Convention: pixel coordinates are $p = [u, v]$ with $[u, v, 1]^T = A\\,[x, y, 1]^T$ (eq. (15)),
where $m = [x, y, 1]^T = \\bar m / z$ are the normalized coordinates of a point $\\bar m$
expressed in the camera frame (eq. (10)); $z$ is the depth along the optical axis.
Arrays of points have the point index first: shape (n, 2) or (n, 3).
"""

from typing import final

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._results import RESULTS, intrinsics_ok, raise_or_keep
from .._util import as_float, check_shape


def intrinsic_matrix(
    fx: float | ArrayLike,
    fy: float | ArrayLike,
    cx: float | ArrayLike,
    cy: float | ArrayLike,
    skew: float | ArrayLike = 0.0,
) -> Float[Array, "3 3"]:
    """The intrinsic calibration matrix $A$ of eq. (15).

    **Arguments:**

    - `fx`, `fy`: focal lengths in pixels.
    - `cx`, `cy`: the principal point $(u_0, v_0)$ in pixels.
    - `skew`: the skew entry $A_{12}$ (0 for rectangular pixels).

    **Returns:** $A = [[f_x, s, c_x], [0, f_y, c_y], [0, 0, 1]]$.

    No error path: NaN in, NaN out (a NaN or inf entry reaches every output entry
    computed from it; none is turned finite).
    """
    fx, fy, cx, cy, skew = (as_float(v) for v in (fx, fy, cx, cy, skew))
    for name, value in (("fx", fx), ("fy", fy), ("cx", cx), ("cy", cy), ("skew", skew)):
        check_shape(value, (), name)
    dtype = jnp.result_type(fx, fy, cx, cy, skew)
    z = jnp.zeros((), dtype)
    o = jnp.ones((), dtype)
    return jnp.stack(
        [jnp.stack([fx, skew, cx]), jnp.stack([z, fy, cy]), jnp.stack([z, z, o])]
    ).astype(dtype)


def _check_A(A):
    A = as_float(A)
    check_shape(A, (3, 3), "A")
    return A


def _check_last(x, size: int, name: str):
    x = as_float(x)
    if x.ndim < 1 or x.shape[-1] != size:
        raise ValueError(f"`{name}` must have shape (..., {size}); got shape {tuple(x.shape)}.")
    return x


def to_homogeneous(x: Float[ArrayLike, "... 2"]) -> Float[Array, "... 3"]:
    """Append a 1 to the last axis: $[u, v] \\mapsto [u, v, 1]$ (eq. (14)).

    No error path: NaN in, NaN out (a NaN or inf entry reaches every output entry
    computed from it; none is turned finite).
    """
    return _to_homogeneous(_check_last(x, 2, "x"))


@jax.jit
def _to_homogeneous(x):
    return jnp.concatenate([x, jnp.ones(x.shape[:-1] + (1,), x.dtype)], axis=-1)


def pixel_to_normalized(
    p: Float[ArrayLike, "... 2"], A: Float[ArrayLike, "3 3"]
) -> Float[Array, "... 2"]:
    """Normalized coordinates $[x, y]$ from pixels, $m = A^{-1} p$ (inverse of eq. (15)).

    **Arguments:**

    - `p`: pixel coordinates, shape (..., 2).
    - `A`: the intrinsic matrix.

    No error path: a non-finite pixel gives NaN coordinates (NaN in, NaN out), and so does
    an unusable `A` (non-finite, or a zero focal length), never a finite value.

    **Returns:** $[x, y]$ of $m = [x, y, 1]^T$, shape (..., 2).
    """
    return _pixel_to_normalized(_check_last(p, 2, "p"), _check_A(A))


# The arithmetic of the functions above and below, compiled: one program per shape when
# called outside `jit` (not one compiled operation per line); inlined under `jit`.
@jax.jit
def _pixel_to_normalized(p, A):
    ok = intrinsics_ok(A)
    A = jnp.where(ok, A, jnp.eye(3, dtype=A.dtype))  # no inf, no NaN gradient
    fx, s, cx = A[0, 0], A[0, 1], A[0, 2]
    fy, cy = A[1, 1], A[1, 2]
    y = (p[..., 1] - cy) / fy
    x = (p[..., 0] - cx - s * y) / fx
    return jnp.where(ok, jnp.stack([x, y], axis=-1), jnp.nan)


def normalized_to_pixel(
    m: Float[ArrayLike, "... 2"], A: Float[ArrayLike, "3 3"]
) -> Float[Array, "... 2"]:
    """Pixels from normalized coordinates, $p = A m$ (eq. (15)).

    **Arguments:**

    - `m`: normalized coordinates $[x, y]$, shape (..., 2).
    - `A`: the intrinsic matrix.

    **Returns:** pixel coordinates $[u, v]$, shape (..., 2).

    No error path: NaN in, NaN out (a NaN or inf entry reaches every output entry
    computed from it; none is turned finite).
    """
    return _normalized_to_pixel(_check_last(m, 2, "m"), _check_A(A))


@jax.jit
def _normalized_to_pixel(m, A):
    u = A[0, 0] * m[..., 0] + A[0, 1] * m[..., 1] + A[0, 2]
    v = A[1, 1] * m[..., 1] + A[1, 2]
    return jnp.stack([u, v], axis=-1)


@final
class Projection(eqx.Module):
    """What `project` returns.

    **Fields:** `pixels` (..., 2): the pixel coordinates, NaN for a point that could not be
    projected (never a finite placeholder); `result`: a `RESULTS` item, `successful`, or
    (with `throw=False`) `nonfinite_pixels` (a non-finite point), `behind_camera` (a depth
    $z \\le 0$) or `invalid_intrinsics`.
    """

    pixels: Float[Array, "... 2"]
    result: RESULTS


def project(
    points: Float[ArrayLike, "... 3"], A: Float[ArrayLike, "3 3"], *, throw: bool = True
) -> Projection:
    """Project 3D points given in the camera frame to pixels (Chitrakaran et al., eqs. (10)
    and (15)).

    **Arguments:**

    - `points`: $\\bar m = [x, y, z]$ in the camera frame, shape (..., 3).
    - `A`: the intrinsic matrix.
    - `throw`: if `True` (default), a point with depth $z \\le 0$ ("behind the camera"), a
        non-finite point or an unusable `A` (non-finite, a zero focal length) raises at run
        time; with `False` the failure is the `result` (those pixels NaN), so that one bad
        frame of a `jax.vmap` batch leaves the others intact.

    **Returns:** a `Projection`: `pixels` (..., 2) and `result`.
    """
    if not isinstance(throw, bool):
        raise ValueError(f"`throw` must be a bool; got {throw!r}.")
    pixels, result = _project_checked(points, A)
    return raise_or_keep(result, Projection(pixels, result), throw)


def _project_checked(
    points: Float[ArrayLike, "... 3"], A: Float[ArrayLike, "3 3"]
) -> tuple[Float[Array, "... 2"], RESULTS]:
    """`(pixels, result)` of `project` without raising; the pixels of a point behind the
    camera are NaN (never a finite placeholder)."""
    return _project_arrays(_check_last(points, 3, "points"), _check_A(A))


@jax.jit
def _project_arrays(points, A):
    z = points[..., 2]
    bad_depth = jnp.any(z <= 0.0)
    nonfinite = ~jnp.all(jnp.isfinite(points))
    result = RESULTS.where(
        nonfinite,
        RESULTS.nonfinite_pixels,
        RESULTS.where(bad_depth, RESULTS.behind_camera, RESULTS.successful),
    )
    result = RESULTS.where(intrinsics_ok(A), result, RESULTS.invalid_intrinsics)
    # Keep the division finite for the points in front (and their gradients NaN-free).
    z_safe = jnp.where(z > 0.0, z, 1.0)
    m = points[..., :2] / z_safe[..., None]
    pixels = _normalized_to_pixel(m, A)
    ok = (z > 0.0) & jnp.all(jnp.isfinite(points), axis=-1)  # a point's pixel whole or NaN
    pixels = jnp.where(ok[..., None], pixels, jnp.nan)
    pixels = jnp.where(intrinsics_ok(A), pixels, jnp.nan)
    return pixels, result


def extended_intrinsics(A: Float[ArrayLike, "3 3"]) -> Float[Array, "3 3"]:
    """The matrix $A_e$ of Chitrakaran et al., eq. (22): $A$ with the principal point removed.

    $A_e = A - [[0, 0, u_0], [0, 0, v_0], [0, 0, 0]]$, which maps the rate of the
    normalized coordinates to the rate of the extended image coordinates
    $p_e = [u, v, \\ln z]$ in eq. (21).

    No error path: NaN in, NaN out (a NaN or inf entry reaches every output entry
    computed from it; none is turned finite).
    """
    A = _check_A(A)
    mask = jnp.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]], A.dtype)
    return A - mask * A
