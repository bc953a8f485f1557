"""The scenes of the two landmark problems (scenes of their own, not the papers' motions):
`point_depth_scene` (static points seen by a camera moving with a constant twist; the
point-depth problem of Spica et al.'s observer) and `homography_scene` (a camera moving
before a planar target; the homography problem of Hamel et al.'s observer), with their
constants and `plane_group_velocity`."""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..geometry import skew, sl3_normalize, so3_exp
from ._scene import CameraRig, constant_twist_trajectory, points_in_camera, view
from ._trajectory import sample_times

POINT_DEPTH_POINTS = (
    (0.1, -0.05, 0.5),
    (-0.3, 0.2, 1.2),
    (0.4, 0.3, 2.0),
    (-0.6, -0.4, 2.5),
    (0.2, -0.7, 3.0),
)  # five static points at 0.5-3 m in front of the camera's start (its frame: the world's)
POINT_DEPTH_TWIST = (
    0.3,
    0.2,
    0.05,
    0.02,
    -0.03,
    0.05,
)  # constant (world frame): sideways and forwards, turning
POINT_DEPTH_CAMERA = (
    (600.0, 0.0, 320.0),
    (0.0, 600.0, 240.0),
    (0.0, 0.0, 1.0),
)  # intrinsics, pixels


class PointDepthScene(eqx.Module):
    """The scene of `point_depth_scene`: `ts` (N,), `points` (N, n, 3) in the camera frame
    (the truth), `pixels` (N, n, 2), `twists` (N, 6) the camera's twist in its own frame
    $(v, \\omega)$, `K` (3, 3)."""

    ts: Float[Array, " N"]
    points: Float[Array, "N n 3"]
    pixels: Float[Array, "N n 2"]
    twists: Float[Array, "N 6"]
    K: Float[Array, "3 3"]


def point_depth_scene(duration: float = 1.0, rate_hz: float = 1000.0) -> PointDepthScene:
    """Five static points (`POINT_DEPTH_POINTS`) seen by a camera moving with the constant twist
    `POINT_DEPTH_TWIST` (closed form, `visjax.sim.constant_twist_trajectory`), `duration` s at
    `rate_hz`."""

    ts = sample_times(duration, rate_hz)
    body = constant_twist_trajectory(jnp.asarray(POINT_DEPTH_TWIST), jnp.zeros(3), jnp.eye(3), ts)
    rig = CameraRig(A=jnp.asarray(POINT_DEPTH_CAMERA), image_size=None)
    P = points_in_camera(rig, jnp.asarray(POINT_DEPTH_POINTS), body)
    R_T = jnp.swapaxes(body.R, 1, 2)
    v = jnp.einsum("kij,kj->ki", R_T, body.twist[:, :3])
    w = jnp.einsum("kij,kj->ki", R_T, body.twist[:, 3:])
    return PointDepthScene(
        ts=ts, points=P, pixels=view(rig, P), twists=jnp.concatenate([v, w], axis=1), K=rig.A
    )


HOMOGRAPHY_PLANE_POINTS = (
    (-0.8, -0.6),
    (0.8, -0.6),
    (0.8, 0.6),
    (-0.8, 0.6),
    (0.2, 0.3),
    (-0.4, 0.1),
    (0.5, -0.2),
    (-0.1, -0.4),
)  # (X, Y) on the plane Z = HOMOGRAPHY_PLANE_DISTANCE of the reference camera (corners first)
HOMOGRAPHY_PLANE_DISTANCE = 2.0  # m, the plane's distance from the reference camera (normal e_3)
HOMOGRAPHY_START = (0.2, -0.1, -0.3)  # m, the camera's start in the reference camera's frame
HOMOGRAPHY_START_ROTATION = (0.05, 0.1, -0.02)  # rad, its orientation there (rotation vector)
HOMOGRAPHY_VELOCITY = (0.1, 0.05, 0.15)  # m/s, constant, reference frame
HOMOGRAPHY_ANGULAR_VELOCITY = (0.05, -0.1, 0.08)  # rad/s, constant, reference frame
HOMOGRAPHY_CAMERA = (
    (600.0, 0.0, 640.0),
    (0.0, 600.0, 480.0),
    (0.0, 0.0, 1.0),
)  # 1280 x 960 px, ~93 deg


def plane_group_velocity(
    omega: Float[ArrayLike, "3"],
    v: Float[ArrayLike, "3"],
    n: Float[ArrayLike, "3"],
    d: Float[ArrayLike, ""],
) -> Float[Array, "3 3"]:
    """The group velocity $A = [\\Omega]_\\times + V n^T / d - (n^T V / (3d)) I$ of the
    homography of a plane (unit normal `n`, distance `d`, in the current camera frame)
    seen by a camera with angular velocity `omega` and linear velocity `v` (its own frame):
    $\\dot H = H A$ (`visjax.estimators.HomographyEstimator`'s module; tested against
    $H^{-1}\\dot H$)."""
    omega, v, n, d = (jnp.asarray(a) for a in (omega, v, n, d))
    nv = jnp.dot(n, v) / (3.0 * d)
    return skew(omega) + jnp.outer(v, n) / d - nv * jnp.eye(3, dtype=v.dtype)


class HomographyScene(eqx.Module):
    """The scene of `homography_scene`: `ts` (N,), `pixels` (N, n, 2) the current image,
    `reference` (n, 2) the reference image, `H` (N, 3, 3) the true homography in SL(3)
    (current to reference, $\\mathring p_i \\propto H p_i$), `A` (N, 3, 3) the true group
    velocity, `omega` (N, 3) the camera's angular velocity in its own frame, `K` (3, 3)."""

    ts: Float[Array, " N"]
    pixels: Float[Array, "N n 2"]
    reference: Float[Array, "n 2"]
    H: Float[Array, "N 3 3"]
    A: Float[Array, "N 3 3"]
    omega: Float[Array, "N 3"]
    K: Float[Array, "3 3"]


def homography_scene(duration: float = 2.0, rate_hz: float = 1000.0) -> HomographyScene:
    """A camera moving with a constant twist (`HOMOGRAPHY_VELOCITY`,
    `HOMOGRAPHY_ANGULAR_VELOCITY`) from `HOMOGRAPHY_START` before the planar target
    `HOMOGRAPHY_PLANE_POINTS` (eight points on the plane at `HOMOGRAPHY_PLANE_DISTANCE` of
    the reference camera), `duration` s at `rate_hz`, in closed form: the pose
    $R(t) = \\exp(t[\\omega]_\\times) R_0$, $\\xi(t) = \\xi_0 + t v$ in the reference
    frame; a point $X$ of the reference frame is $R^T(X - \\xi)$ in the current one; the
    homography $H \\propto (I + \\xi n^T / (d - n^T\\xi))\\, R$ brought to SL(3)."""

    ts = sample_times(duration, rate_hz)
    K = jnp.asarray(HOMOGRAPHY_CAMERA)
    n0 = jnp.array([0.0, 0.0, 1.0])
    XY = jnp.asarray(HOMOGRAPHY_PLANE_POINTS)
    X_ref = jnp.concatenate([XY, jnp.full((XY.shape[0], 1), HOMOGRAPHY_PLANE_DISTANCE)], axis=1)
    R0 = so3_exp(jnp.asarray(HOMOGRAPHY_START_ROTATION))
    v, w = jnp.asarray(HOMOGRAPHY_VELOCITY), jnp.asarray(HOMOGRAPHY_ANGULAR_VELOCITY)

    def frame(t):
        R = so3_exp(t * w) @ R0
        xi = jnp.asarray(HOMOGRAPHY_START) + t * v
        d = HOMOGRAPHY_PLANE_DISTANCE - n0 @ xi  # the current camera's distance to the plane
        X = (X_ref - xi[None, :]) @ R  # R^T (X - xi), row by row
        H = sl3_normalize((jnp.eye(3) + jnp.outer(xi, n0) / d) @ R)
        A = plane_group_velocity(R.T @ w, R.T @ v, R.T @ n0, d)
        return X, H, A, R.T @ w

    X, H, A, omega = jax.vmap(frame)(ts)
    m = X / X[..., 2:]
    pixels = (m @ K.T)[..., :2]
    reference = ((X_ref / X_ref[:, 2:]) @ K.T)[:, :2]
    return HomographyScene(ts, pixels, reference, H, A, omega, K)
