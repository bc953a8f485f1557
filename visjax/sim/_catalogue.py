"""Canonical scenes: the scenes, none of them a paper's, on which the tests, the benchmark
scripts and the example data files run the estimators.

Each scene's parameters are fixed here, once, from its description; nothing is tuned per
estimator. The builders return the truth and what a camera records (plain arrays, a
`MovingPointScene`, or a dict of them); the `*_record` functions return a scene as the
arrays of a data file (a dict whose keys are those of `visjax.io`'s data classes:
`visjax.io.VelocityData(**sinusoidal_plate_record())`). Enable 64-bit floats
(`jax.config.update("jax_enable_x64", True)`) before building: the numbers the tests and
benchmarks quote are float64 ones.

- Fixed camera, moving object (the velocity estimator): `sinusoidal_plate_scene`,
  `spline_board_scene`; data file `sinusoidal_plate_record`.
- Moving camera, moving target (the unknown input observer): `sideways_camera_scene`,
  `circling_camera_scene` (`moving_target_scene`, `MOVING_TARGET_SCENES`); data file
  `sideways_camera_record`.
- Camera on a moving platform, static features (the uncalibrated structure estimator):
  `tilted_platform_scene`, `side_looking_platform_scene`; data file
  `tilted_platform_record`.
"""

import jax
import jax.numpy as jnp
import numpy as np

from ..geometry import intrinsics_from_camera, so3_exp
from ._moving_point import MovingPointScene, moving_point_scene
from ._rigs import add_pixel_noise, platform_camera_pixels
from ._scene import (
    CameraRig,
    Sampler,
    intrinsics,
    object_points,
    planar_features,
    points_in_camera,
    sinusoidal_trajectory,
    spline_trajectory,
)
from ._trajectory import Trajectory, sample_times

_DEG = np.pi / 180.0


# --- fixed camera, moving object ----------------------------------------------------------


def _flip():
    """The object turned half a turn about x: its features face the camera."""
    return so3_exp(jnp.array([np.pi, 0.0, 0.0]))


def sinusoidal_plate_scene(
    duration: float = 10.0,
    rate_hz: float = 1000.0,
    noise_px: float = 0.0,
    dropout: float = 0.0,
    seed: int = 0,
    feature_seed: int = 0,
) -> dict:
    """A plate moving on all six degrees of freedom in front of a fixed camera.

    Six irregular coplanar features on a 0.3 m plate (`planar_features(6, size=0.3,
    normal=(0.1, 0.2, 1.0), offset=0.04, seed=feature_seed)`: the object origin 4 cm off
    the plate), starting 1.5 m in front of the camera at (0.05, -0.03, 1.5) m; sinusoidal
    twist on all six axes (amplitudes 0.1, 0.08, 0.05 m/s and 0.3, 0.2, 0.25 rad/s at
    0.3, 0.2, 0.25, 0.15, 0.35, 0.2 Hz). The camera: focal length 900 px, a 90.5 degree
    pixel grid, principal point (512, 384), image 1024 x 768. Frames at `rate_hz` with
    Gaussian pixel noise `noise_px` and a fraction `dropout` of the observations missing
    (NaN), drawn from `jax.random.key(seed)`. The known length for the depth: between
    features 1 and 3.

    **Returns:** a dict: `ts` (N,), `pixels` (N, 6, 2), `A` (3, 3), `body` (the plate's
    `Trajectory`, its twist the truth), `features` (6, 3) in the plate's frame,
    `known_pair` `(1, 3)`.
    """
    s = planar_features(6, size=0.3, normal=(0.1, 0.2, 1.0), offset=0.04, seed=feature_seed)
    sampler = Sampler(rate_hz=rate_hz, noise_px=noise_px, dropout=dropout)
    ts = sampler.times(duration)
    body = sinusoidal_trajectory(
        jnp.array([0.1, 0.08, 0.05, 0.3, 0.2, 0.25]),
        jnp.array([0.3, 0.2, 0.25, 0.15, 0.35, 0.2]),
        jnp.array([0.05, -0.03, 1.5]),
        _flip() @ so3_exp(jnp.array([0.2, -0.1, 0.3])),
        ts,
    )
    rig = CameraRig(
        A=intrinsics(900.0, cx=512.0, cy=384.0, skew_angle_deg=90.5), image_size=(1024, 768)
    )
    key = jax.random.key(seed)
    pixels, _ = sampler.record(rig, points_in_camera(rig, object_points(body, s)), key)
    return {
        "ts": ts,
        "pixels": pixels,
        "A": rig.A,
        "body": body,
        "features": s,
        "known_pair": (1, 3),
    }


def spline_board_scene(duration: float = 10.0, noise_px: float = 0.0, seed: int = 0) -> dict:
    """A board passing through five key poses in front of a fixed camera.

    Eight features on a 0.5 m board (`planar_features(8, size=0.5, normal=(0.0, 0.3,
    1.0), offset=-0.05, seed=5)`), about 2.5 m away, through five key poses spread evenly
    over the run (a 0.4 m sweep in x with 25 degrees of turn) on a natural cubic spline
    (`spline_trajectory`). The camera: focal length 1100 px, principal point (640, 360),
    image 1280 x 720. Frames at 1 kHz with 0.2 ms of uniform time jitter (drawn from
    `jax.random.key(seed + 100)`) and Gaussian pixel noise `noise_px` (from
    `jax.random.key(seed)`). The known length for the depth: between features 0 and 5.

    **Returns:** a dict with the keys of `sinusoidal_plate_scene`: `ts` (N,), `pixels`
    (N, 8, 2), `A`, `body`, `features` (8, 3), `known_pair` `(0, 5)`.
    """
    s = planar_features(8, size=0.5, normal=(0.0, 0.3, 1.0), offset=-0.05, seed=5)
    sampler = Sampler(rate_hz=1000.0, jitter_s=2e-4, noise_px=noise_px)
    ts = sampler.times(duration, jax.random.key(seed + 100))
    knots = jnp.linspace(0.0, float(ts[-1]), 5)
    angles = jnp.deg2rad(jnp.array([0.0, 10.0, 25.0, 12.0, -5.0]))
    flip = _flip()
    R_k = jnp.stack([flip @ so3_exp(jnp.array([0.3 * a, a, 0.5 * a])) for a in angles])
    x_k = jnp.array(
        [[-0.2, 0.0, 2.5], [-0.1, 0.05, 2.4], [0.0, 0.1, 2.6], [0.1, 0.0, 2.5], [0.2, -0.05, 2.45]]
    )
    body = spline_trajectory(knots, R_k, x_k, ts)
    rig = CameraRig(A=intrinsics(1100.0, cx=640.0, cy=360.0), image_size=(1280, 720))
    key = jax.random.key(seed)
    pixels, _ = sampler.record(rig, points_in_camera(rig, object_points(body, s)), key)
    return {
        "ts": ts,
        "pixels": pixels,
        "A": rig.A,
        "body": body,
        "features": s,
        "known_pair": (0, 5),
    }


def sinusoidal_plate_record(
    duration: float = 10.0, seed: int = 0, noise_px: float = 0.1, dropout: float = 0.02
) -> dict:
    """`sinusoidal_plate_scene` at 1 kHz (its features and its noise both from `seed`) as
    the arrays of a velocity data file: the keys of `visjax.io.VelocityData`, the truth
    (`velocity`, the plate's twist) included. By default 0.1 px of pixel noise and 2% of
    the feature observations missing."""
    sc = sinusoidal_plate_scene(
        duration, noise_px=noise_px, dropout=dropout, seed=seed, feature_seed=seed
    )
    body, s = sc["body"], sc["features"]
    i, j = sc["known_pair"]
    return {
        "t": np.asarray(sc["ts"]),
        "pixels": np.asarray(sc["pixels"]),
        "A": np.asarray(sc["A"]),
        "R_star": np.asarray(body.R[0]),
        "s1": np.asarray(s[0]),
        "known_length": np.array([float(i), float(j), float(jnp.linalg.norm(s[i] - s[j]))]),
        "velocity": np.asarray(body.twist),
    }


# --- moving camera, moving target -----------------------------------------------------------

MOVING_TARGET_K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
"""The camera of the moving-target scenes: focal length 800 px, principal point (320, 240)."""
MOVING_TARGET_IMAGE = (640.0, 480.0)
"""The image of the moving-target scenes (width, height), pixels."""
MOVING_TARGET_RATE_HZ = 1000
"""The rate of the moving-target scenes' truth (samples per second)."""
MOVING_TARGET_FRAME_HZ = 50
"""The rate at which the camera records frames in the moving-target scenes."""

MOVING_TARGET_SCENES = {
    "sideways": dict(
        amplitude=0.5,
        frequency_hz=0.2,
        target_start=(0.0, -0.4, 2.5),
        target_velocity=(0.0, 0.04, 0.0),
        duration=20.0,
    ),
    "circle_diagonal": dict(
        radius=0.3,
        frequency_hz=0.25,
        target_start=(-0.2, -0.4, 2.5),
        target_velocity=(0.02, 0.04, 0.0),
        duration=20.0,
    ),
}
"""The parameters of the moving-target scenes, by name: the camera's motion (`amplitude`
of the sideways sinusoid or `radius` of the circle, m; `frequency_hz`), the target's start
(m, world frame) and constant velocity (m/s), the default duration (s). See
`sideways_camera_scene` and `circling_camera_scene`."""


def moving_target_camera(name: str, ts) -> Trajectory:
    """The camera's trajectory in the moving-target scene `name` (`MOVING_TARGET_SCENES`)
    at the times `ts`, in closed form (world frame); the camera's axes are the world's, so
    it looks along the world's $+z$."""
    s = MOVING_TARGET_SCENES[name]
    ts = jnp.asarray(ts)
    w = 2.0 * jnp.pi * s["frequency_hz"]
    z = jnp.zeros_like(ts)
    if name == "sideways":
        a = s["amplitude"]
        x = jnp.stack([a * jnp.sin(w * ts), z, z], axis=1)
        v = jnp.stack([a * w * jnp.cos(w * ts), z, z], axis=1)
    else:
        r = s["radius"]
        x = jnp.stack([r * jnp.sin(w * ts), r * jnp.cos(w * ts), z], axis=1)
        v = jnp.stack([r * w * jnp.cos(w * ts), -r * w * jnp.sin(w * ts), z], axis=1)
    R = jnp.broadcast_to(jnp.eye(3), (ts.shape[0], 3, 3))
    return Trajectory(ts=ts, R=R, x=x, twist=jnp.concatenate([v, jnp.zeros_like(v)], axis=1))


def moving_target_scene(name: str, duration: float | None = None) -> MovingPointScene:
    """The truth of the moving-target scene `name` (`MOVING_TARGET_SCENES`) at
    `MOVING_TARGET_RATE_HZ` (1 kHz) from t = 0 over `duration` seconds (default: the
    scene's own), seen by the camera `MOVING_TARGET_K` with a `MOVING_TARGET_IMAGE` image
    (pixels outside it NaN). See `sideways_camera_scene`, `circling_camera_scene`."""
    s = MOVING_TARGET_SCENES[name]
    duration = s["duration"] if duration is None else duration
    rate = MOVING_TARGET_RATE_HZ
    ts = jnp.arange(int(round(duration * rate)), dtype=float) / rate
    p0, vp = jnp.asarray(s["target_start"]), jnp.asarray(s["target_velocity"])
    point = p0[None, :] + ts[:, None] * vp[None, :]
    velocity = jnp.broadcast_to(vp, point.shape)
    return moving_point_scene(
        moving_target_camera(name, ts),
        point,
        velocity,
        MOVING_TARGET_K,
        image_size=MOVING_TARGET_IMAGE,
    )


def sideways_camera_scene(duration: float = 20.0) -> MovingPointScene:
    """A camera translating sinusoidally sideways past a target moving on a vertical line.

    The camera: $x_c(t) = [0.5\\sin(2\\pi\\,0.2\\,t), 0, 0]$ m (peak 0.63 m/s, its velocity
    changes sign every 2.5 s), looking along the world $+z$. The target starts 2.5 m in
    front at (0, -0.4, 2.5) m and moves along a vertical line at 0.04 m/s, so its image
    motion is vertical. Camera `MOVING_TARGET_K` (focal length 800 px, principal point
    (320, 240)), image 640 x 480; the truth at 1 kHz; a camera records its frames at
    `MOVING_TARGET_FRAME_HZ` (50 Hz). `moving_target_scene("sideways", duration)`."""
    return moving_target_scene("sideways", duration)


def circling_camera_scene(duration: float = 20.0) -> MovingPointScene:
    """A camera moving on a circle parallel to the image plane, a target moving diagonally.

    The camera: $x_c(t) = [0.3\\sin(2\\pi\\,0.25\\,t), 0.3\\cos(2\\pi\\,0.25\\,t), 0]$ m,
    looking along the world $+z$ (the circle centred on the optical axis: centred 0.3 m
    below it, the target would leave the image after about 15 s). The target starts at
    (-0.2, -0.4, 2.5) m and moves diagonally at (0.02, 0.04, 0) m/s. Camera, image and
    rates those of `sideways_camera_scene`. `moving_target_scene("circle_diagonal",
    duration)`."""
    return moving_target_scene("circle_diagonal", duration)


def sideways_camera_record(duration: float = 20.0, seed: int = 0, noise_px: float = 0.1) -> dict:
    """`sideways_camera_scene` as the arrays of a structure data file: the keys of
    `visjax.io.MovingPointData`. Frames at 50 Hz with Gaussian pixel noise `noise_px` (from
    `jax.random.key(seed)`), the camera's velocity at 200 Hz, the target's direction of
    motion in the image `D = [0, 1, 0]`, a depth guess of 4 m, and the truth (the target's
    position in the camera frame) at the frames."""
    truth = sideways_camera_scene(duration)
    frames = slice(0, None, MOVING_TARGET_RATE_HZ // MOVING_TARGET_FRAME_HZ)
    velocity = slice(0, None, MOVING_TARGET_RATE_HZ // 200)
    key = jax.random.key(seed) if noise_px > 0 else None
    pixels = add_pixel_noise(key, truth.pixels[frames], noise_px)
    return {
        "t": np.asarray(truth.ts[frames]),
        "pixels": np.asarray(pixels),
        "A": MOVING_TARGET_K.copy(),
        "camera_t": np.asarray(truth.ts[velocity]),
        "camera_velocity": np.asarray(truth.camera_velocity[velocity]),
        "D": np.array([0.0, 1.0, 0.0]),  # the target moves vertically in the image
        "depth_guess": np.array(4.0),
        "position": np.asarray(truth.position[frames]),
    }


# --- camera on a moving platform, static features ---------------------------------------------


def _world_points(R_c, x_c, rays_depths):
    """World points (the platform at the origin, unrotated) from camera-frame directions
    (x/z, y/z) and depths z."""
    rd = np.asarray(rays_depths, float)
    m = np.stack([rd[:, 0] * rd[:, 2], rd[:, 1] * rd[:, 2], rd[:, 2]], 1)
    return jnp.asarray(np.asarray(x_c) + m @ np.asarray(R_c).T)


def _platform_scene(name, ts, pose, A, R_c, x_c, known, unknown, nominal, dt):
    R_b, x_b = jax.jit(jax.vmap(pose))(ts)  # compiled once, not dispatched op by op
    omega_c = _world_points(R_c, x_c, known)
    omega_s = _world_points(R_c, x_c, unknown)
    pixels = jax.jit(platform_camera_pixels)
    return {
        "name": name,
        "ts": ts,
        "R_b": R_b,
        "x_b": x_b,
        "p_s": pixels(R_b, x_b, R_c, x_c, A, omega_s),
        "p_c": pixels(R_b, x_b, R_c, x_c, A, omega_c),
        "omega_c": omega_c,
        "omega_s": omega_s,
        "A": A,
        "R_c": R_c,
        "x_c": x_c,
        "nominal": nominal,
        "dt": dt,
    }


# the tilted platform's features: camera-frame directions (x/z, y/z) and depths z at the start
_TILTED_KNOWN = [
    (-0.3, -0.2, 2.1),
    (0.32, -0.18, 2.6),
    (0.28, 0.22, 3.1),
    (-0.25, 0.2, 2.4),
    (0.0, -0.05, 3.2),
    (0.1, 0.1, 2.0),
]
_TILTED_UNKNOWN = [
    (-0.15, 0.05, 2.3),
    (0.2, -0.1, 2.9),
    (0.05, 0.18, 2.2),
    (-0.22, -0.12, 3.0),
    (0.12, 0.02, 2.6),
]


def _tilted_platform_pose(t):
    """The slow platform of the tilted scene at time t: (R_b, x_b)."""
    tp = 2.0 * jnp.pi * t
    x = jnp.stack(
        [
            0.1 * jnp.sin(0.1 * tp),
            0.08 * jnp.sin(0.15 * tp),
            0.12 * jnp.sin(0.1 * tp + 1.0),
        ]
    )
    w = jnp.stack(
        [
            0.05 * jnp.sin(0.12 * tp),
            0.05 * jnp.cos(0.17 * tp) - 0.05,
            0.08 * jnp.sin(0.25 * tp),
        ]
    )
    return so3_exp(w), x


def _tilted_mounting():
    """The tilted camera's nominal and true orientation and its offset on the platform."""
    R_nominal = so3_exp(jnp.array([-27.0 * _DEG, 0.0, 0.0]))  # optical axis 27 deg down (+y)
    R_c = R_nominal @ so3_exp(2.0 * _DEG * jnp.array([1.0, 1.0, 1.0]) / np.sqrt(3.0))
    return R_nominal, R_c, jnp.array([0.03, -0.06, 0.15])


def tilted_platform_scene(duration: float = 40.0, rate_hz: float = 1000.0) -> dict:
    """A camera looking down from a slowly moving platform at static features, its
    mounting tilted in a way the nominal mounting does not know.

    Intrinsics fx 900 px, skew angle 91.5 deg, principal point (524, 371); the camera 27
    deg down with a 2 deg tilt about (1, 1, 1) that the nominal mounting does not know,
    mounted at (0.03, -0.06, 0.15) m; 6 known and 5 unknown features 2-3.2 m away (placed
    by their direction and depth from the camera at the start); a slow platform (0.08-0.12
    m at 0.1-0.15 Hz, 0.05-0.08 rad at 0.12-0.25 Hz); sampled at `rate_hz` (1 kHz), no
    noise. Nominal camera: fx 880 px, no skew, principal point at the centre of a 1024 x
    768 image, 27 deg down, the offset 1 cm off on each axis.

    **Returns:** a dict: `name` ("tilted"), `ts` (N,), the platform's pose `R_b` (N, 3, 3)
    and `x_b` (N, 3), the pixels of the unknown features `p_s` (N, 5, 2) and of the known
    ones `p_c` (N, 6, 2), their world positions `omega_s` (5, 3) and `omega_c` (6, 3), the
    true camera `A`, `R_c`, `x_c`, the `nominal` camera `(A, R_c, x_c)`, and `dt` (None:
    integrate at the samples).
    """
    A = intrinsics_from_camera(0.009, 1e5, 1e5, 91.5 * _DEG, 524.0, 371.0)
    R_nominal, R_c, x_c = _tilted_mounting()
    nominal = (
        intrinsics_from_camera(0.0088, 1e5, 1e5, 90.0 * _DEG, 512.0, 384.0),
        R_nominal,
        jnp.array([0.04, -0.05, 0.14]),
    )
    ts = sample_times(duration, rate_hz)
    return _platform_scene(
        "tilted",
        ts,
        _tilted_platform_pose,
        A,
        R_c,
        x_c,
        _TILTED_KNOWN,
        _TILTED_UNKNOWN,
        nominal,
        None,
    )


def side_looking_platform_scene(duration: float = 40.0, rate_hz: float = 100.0) -> dict:
    """A camera looking sideways from a slow ground vehicle at static features 4-6 m away,
    logged at 100 Hz and integrated at 1 ms (the hold).

    Intrinsics fx 500 px, no skew, principal point (320, 240); the camera turned 90 deg
    about the platform's y axis with an unknown 3 deg about its own x axis, at (0.2, 0,
    0.05) m; 8 known and 4 unknown features; the platform moves 0.3 m at 0.1 Hz along x
    and turns 0.1 rad at 0.1 Hz; no noise. Nominal camera: fx 480 px, principal point
    (330, 235), 90 deg sideways, the offset 5 cm off along z.

    **Returns:** a dict with the keys of `tilted_platform_scene`: `name` ("side"), `p_s`
    (N, 4, 2), `p_c` (N, 8, 2), ..., and `dt` 1e-3.
    """
    A = intrinsics_from_camera(0.005, 1e5, 1e5, 90.0 * _DEG, 320.0, 240.0)
    R_nominal = so3_exp(jnp.array([0.0, 90.0 * _DEG, 0.0]))  # optical axis along platform +x
    R_c = R_nominal @ so3_exp(jnp.array([3.0 * _DEG, 0.0, 0.0]))
    x_c = jnp.array([0.2, 0.0, 0.05])
    nominal = (
        intrinsics_from_camera(0.0048, 1e5, 1e5, 90.0 * _DEG, 330.0, 235.0),
        R_nominal,
        jnp.array([0.2, 0.0, 0.0]),
    )
    known = [
        (-0.4, -0.3, 4.2),
        (0.4, -0.28, 5.0),
        (0.38, 0.3, 5.8),
        (-0.35, 0.32, 4.6),
        (0.0, -0.1, 6.0),
        (0.15, 0.15, 4.0),
        (-0.2, 0.0, 5.4),
        (0.25, 0.05, 4.4),
    ]
    unknown = [(-0.2, 0.1, 4.5), (0.25, -0.15, 5.5), (0.05, 0.22, 4.1), (-0.3, -0.18, 5.9)]

    def pose(t):
        tp = 2.0 * jnp.pi * t
        x = jnp.array(
            [0.3 * jnp.sin(0.1 * tp), 0.05 * jnp.sin(0.2 * tp), 0.2 * jnp.sin(0.07 * tp + 0.5)]
        )
        w = jnp.array(
            [0.03 * jnp.sin(0.3 * tp), 0.1 * jnp.sin(0.1 * tp), 0.03 * jnp.sin(0.2 * tp + 1.0)]
        )
        return so3_exp(w), x

    ts = sample_times(duration, rate_hz)
    return _platform_scene("side", ts, pose, A, R_c, x_c, known, unknown, nominal, 1e-3)


def tilted_platform_record(
    duration: float = 40.0, seed: int = 0, noise_px: float = 0.2, dropout: float = 0.02
) -> dict:
    """The scene of `tilted_platform_scene` logged at 200 Hz, as the arrays of a euclidean
    data file: the keys of `visjax.io.StaticPointsData`. The true camera is built with
    `intrinsics(900.0, cx=524.0, cy=371.0, skew_angle_deg=91.5)` and a 1024 x 768 image;
    Gaussian pixel noise `noise_px` and a fraction `dropout` of the observations missing,
    drawn from `jax.random.key(seed)`; the nominal camera as in `tilted_platform_scene`
    (`intrinsics(880.0, cx=512.0, cy=384.0)`), and the unknown features' positions
    (`features`) as the truth."""
    A = intrinsics(900.0, cx=524.0, cy=371.0, skew_angle_deg=91.5)
    R_nominal, R_c, x_c = _tilted_mounting()
    rig = CameraRig(A=A, R_c=R_c, x_c=x_c, image_size=(1024, 768))
    world = _world_points(R_c, x_c, _TILTED_KNOWN + _TILTED_UNKNOWN)
    n_known = len(_TILTED_KNOWN)
    sampler = Sampler(rate_hz=200.0, noise_px=noise_px, dropout=dropout)
    ts = sampler.times(duration)
    R_b, x_b = jax.vmap(_tilted_platform_pose)(ts)
    body = Trajectory(ts=ts, R=R_b, x=x_b, twist=jnp.zeros((ts.shape[0], 6)))  # poses only
    pixels, _ = sampler.record(rig, points_in_camera(rig, world, body), jax.random.key(seed))
    return {
        "t": np.asarray(ts),
        "pixels": np.asarray(pixels),
        "platform_R": np.asarray(R_b),
        "platform_x": np.asarray(x_b),
        "known_features": np.asarray(world[:n_known]),
        # the nominal camera: fx 880 px, no skew, the image centre, 27 degrees down, the
        # offset 1 cm off on each axis
        "A_nominal": np.asarray(intrinsics(880.0, cx=512.0, cy=384.0)),
        "R_c_nominal": np.asarray(R_nominal),
        "x_c_nominal": np.array([0.04, -0.05, 0.14]),
        "features": np.asarray(world[n_known:]),
    }
