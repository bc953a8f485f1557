"""Lens distortion: OpenCV's camera model, forwards (`distort_pixels`) and backwards
(`undistort_pixels`), in JAX.

The model is OpenCV's (the `calib3d` module's camera model: Brown-Conrady radial and
tangential terms, the rational model's denominator, the thin prism terms and the tilted
sensor), with its coefficients in its order,

$$(k_1, k_2, p_1, p_2[, k_3[, k_4, k_5, k_6[, s_1, s_2, s_3, s_4[, \\tau_x, \\tau_y]]]])$$

(4, 5, 8, 12 or 14 values; the ones not given are 0). A point of the camera frame with
normalized coordinates $(x, y)$, $r^2 = x^2 + y^2$, is seen at

$$x'' = x \\frac{1 + k_1 r^2 + k_2 r^4 + k_3 r^6}{1 + k_4 r^2 + k_5 r^4 + k_6 r^6}
 + 2 p_1 x y + p_2 (r^2 + 2 x^2) + s_1 r^2 + s_2 r^4,$$
$$y'' = y \\frac{1 + k_1 r^2 + k_2 r^4 + k_3 r^6}{1 + k_4 r^2 + k_5 r^4 + k_6 r^6}
 + p_1 (r^2 + 2 y^2) + 2 p_2 x y + s_3 r^2 + s_4 r^4,$$

then through the tilt $R(\\tau_x, \\tau_y)$ of the sensor (a projective map of $(x'', y'', 1)$),
then at the pixel $A\\,[x''', y''', 1]^T$ (eq. (15) of Chitrakaran et al.; the skew of `A` is
applied, where OpenCV ignores it: with zero skew the two agree).

The estimators of visjax assume a pinhole camera: a distorted track is undistorted before
any of them sees it (`undistort_pixels`: the pinhole pixel $A\\,[x, y, 1]^T$ of the point
seen at a pixel, what `cv2.undistortPoints(p, A, dist, P=A)` computes), and a renderer
distorts an ideal image with `distort_pixels`.
"""

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._util import as_float
from ._camera import _check_A, _check_last, _normalized_to_pixel, _pixel_to_normalized

DISTORTION_LENGTHS = (4, 5, 8, 12, 14)
"""The numbers of distortion coefficients OpenCV's camera model takes (`dist`)."""

NEWTON_STEPS = 10
"""Newton steps of `undistort_pixels` (quadratic convergence from the distorted point: a
lens of $k_1 = -0.3$ reaches float64's precision in 5 to 6 steps at the image corners)."""


def check_distortion(dist) -> Array:
    """`dist` (one of OpenCV's lengths, `DISTORTION_LENGTHS`) as a float array of all 14
    coefficients, those not given 0: one compiled program serves every length.

    **Raises:** `ValueError` naming the lengths allowed, for any other shape."""
    dist = as_float(dist)
    if dist.ndim != 1 or dist.shape[0] not in DISTORTION_LENGTHS:
        raise ValueError(
            f"`dist` must hold 4, 5, 8, 12 or 14 coefficients (OpenCV's order: k1, k2, p1, "
            f"p2[, k3[, k4, k5, k6[, s1, s2, s3, s4[, tau_x, tau_y]]]]); got shape "
            f"{tuple(dist.shape)}."
        )
    return jnp.concatenate([dist, jnp.zeros(14 - dist.shape[0], dist.dtype)])


def _tilt(tau_x, tau_y):
    """OpenCV's tilted-sensor projection matrix for the angles $\\tau_x$, $\\tau_y$."""
    cx, sx, cy, sy = jnp.cos(tau_x), jnp.sin(tau_x), jnp.cos(tau_y), jnp.sin(tau_y)
    one, zero = jnp.ones_like(cx), jnp.zeros_like(cx)
    rot_x = jnp.array([[one, zero, zero], [zero, cx, sx], [zero, -sx, cx]])
    rot_y = jnp.array([[cy, zero, -sy], [zero, one, zero], [sy, zero, cy]])
    rot = rot_y @ rot_x
    proj = jnp.array(
        [[rot[2, 2], zero, -rot[0, 2]], [zero, rot[2, 2], -rot[1, 2]], [zero, zero, one]]
    )
    return proj @ rot


def _radial(r2, k):
    """The radial factor of OpenCV's model at $r^2$."""
    r4, r6 = r2 * r2, r2 * r2 * r2
    return (1 + k[0] * r2 + k[1] * r4 + k[4] * r6) / (1 + k[5] * r2 + k[6] * r4 + k[7] * r6)


def _distort_one(m, k, tilt):
    """The distorted normalized coordinates of one point `m` (2,), coefficients `k` (14,)
    (OpenCV's camera model: the module's docstring)."""
    x, y = m[0], m[1]
    r2 = x * x + y * y
    r4 = r2 * r2
    radial = _radial(r2, k)
    xd = x * radial + 2 * k[2] * x * y + k[3] * (r2 + 2 * x * x) + k[8] * r2 + k[9] * r4
    yd = y * radial + k[2] * (r2 + 2 * y * y) + 2 * k[3] * x * y + k[10] * r2 + k[11] * r4
    v = tilt @ jnp.stack([xd, yd, jnp.ones_like(xd)])
    return v[:2] / v[2]


@jax.jit
def _distort(m, k):
    tilt = _tilt(k[12], k[13])
    flat = m.reshape(-1, 2)
    out = jax.vmap(_distort_one, in_axes=(0, None, None))(flat, k, tilt)
    return out.reshape(m.shape)


@jax.jit
def _undistort(d, k):
    tilt = _tilt(k[12], k[13])
    untilt = jnp.linalg.inv(tilt)
    flat = d.reshape(-1, 2)
    eps = jnp.finfo(flat.dtype).eps
    jacobian = jax.jacfwd(_distort_one)

    def one(target):
        # the start: the tilt undone (OpenCV's start of its fixed-point iteration)
        v = untilt @ jnp.stack([target[0], target[1], jnp.ones_like(target[0])])
        start = v[:2] / v[2]

        def newton(_, m):
            f = _distort_one(m, k, tilt) - target
            J = jacobian(m, k, tilt)
            det = J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]  # the 2x2 solve in closed form
            step = jnp.stack([J[1, 1] * f[0] - J[0, 1] * f[1], J[0, 0] * f[1] - J[1, 0] * f[0]])
            return m - step / det

        m = jax.lax.fori_loop(0, NEWTON_STEPS, newton, start)
        residual = jnp.max(jnp.abs(_distort_one(m, k, tilt) - target))
        converged = residual <= 100 * eps * (1 + jnp.max(jnp.abs(target)))
        # a root where the radial factor is negative is a point mirrored through the
        # axis, which no lens shows (OpenCV's undistortion stops there too)
        upright = _radial(m[0] * m[0] + m[1] * m[1], k) > 0
        return jnp.where(converged & upright & jnp.all(jnp.isfinite(m)), m, jnp.nan)

    return jax.vmap(one)(flat).reshape(d.shape)


def distort_pixels(
    p: Float[ArrayLike, "... 2"], A: Float[ArrayLike, "3 3"], dist: Float[ArrayLike, " k"]
) -> Float[Array, "... 2"]:
    """Where a lens with the distortion `dist` shows the points that a pinhole camera
    with the intrinsics `A` shows at the pixels `p` (OpenCV's model, in the module's
    docstring; `cv2.projectPoints` with `dist`).

    **Arguments:** `p` (..., 2) pinhole pixels; `A` (3, 3); `dist` 4, 5, 8, 12 or 14
    coefficients in OpenCV's order.

    **Returns:** the distorted pixels (..., 2). No error path: NaN in, NaN out.

    **Raises:** `ValueError` for `dist` of another length."""
    p, A, dist = _check_last(p, 2, "p"), _check_A(A), check_distortion(dist)
    return _normalized_to_pixel(_distort(_pixel_to_normalized(p, A), dist), A)


def undistort_pixels(
    p: Float[ArrayLike, "... 2"], A: Float[ArrayLike, "3 3"], dist: Float[ArrayLike, " k"]
) -> Float[Array, "... 2"]:
    """The pinhole pixels of the points a lens with the distortion `dist` shows at the
    pixels `p`: the inverse of `distort_pixels` (`cv2.undistortPoints(p, A, dist, P=A)`,
    solved by Newton's method to the dtype's precision, where OpenCV stops after five
    fixed-point steps).

    **Arguments:** as `distort_pixels`.

    **Returns:** the undistorted pixels (..., 2): NaN for a non-finite pixel, and for a
    pixel the model cannot have produced (beyond the largest radius a lens of strong
    barrel distortion maps to, where Newton's method does not converge); never a
    finite guess.

    **Raises:** `ValueError` for `dist` of another length."""
    p, A, dist = _check_last(p, 2, "p"), _check_A(A), check_distortion(dist)
    return _normalized_to_pixel(_undistort(_pixel_to_normalized(p, A), dist), A)
