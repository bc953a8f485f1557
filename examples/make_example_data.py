"""Write one complete example data file per estimator, in the formats of `visjax.io`
(README, "Your own data"), from scenes that are none of the papers' own:

- `velocity.npz`: a plate with six irregular coplanar features, 1.5 m in front of a fixed
  camera with a slightly skewed pixel grid, moving on all six degrees of freedom; 1 kHz,
  0.1 px pixel noise, 2% of the feature observations missing (NaN).
- `structure.npz`: a camera translating sideways (sinusoid, 0.5 m amplitude, 0.2 Hz) 2.5 m
  from a target moving along a vertical line at 4 cm/s; frames at 50 Hz with 0.1 px
  noise, camera velocities at 200 Hz.
- `euclidean.npz`: a camera looking 27 degrees down from a slowly moving platform at eleven
  static features 2-3.2 m away, six of them known; logged at 200 Hz with 0.2 px noise and
  2% of the observations missing; the nominal camera is off the true one (focal length,
  skew, principal point, a 2 degree tilt, the offset).

Each file holds the truth keys too, so that `visjax ... --data` reports its errors. Run:

    python examples/make_example_data.py --out examples/data
"""

import argparse
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

from visjax import io, sim  # noqa: E402
from visjax.geometry import so3_exp  # noqa: E402


def velocity_example(
    duration: float = 10.0, seed: int = 0, noise_px: float = 0.1, dropout: float = 0.02
) -> io.VelocityData:
    """The fixed-camera scene of the module docstring."""
    s = sim.planar_features(6, size=0.3, normal=(0.1, 0.2, 1.0), offset=0.04, seed=seed)
    R0 = so3_exp(jnp.array([np.pi, 0.0, 0.0])) @ so3_exp(jnp.array([0.2, -0.1, 0.3]))
    x0 = jnp.array([0.05, -0.03, 1.5])
    sampler = sim.Sampler(rate_hz=1000.0, noise_px=noise_px, dropout=dropout)
    ts = sampler.times(duration)
    body = sim.sinusoidal_trajectory(
        jnp.array([0.1, 0.08, 0.05, 0.3, 0.2, 0.25]),
        jnp.array([0.3, 0.2, 0.25, 0.15, 0.35, 0.2]),
        x0,
        R0,
        ts,
    )
    rig = sim.CameraRig(
        A=sim.intrinsics(900.0, cx=512.0, cy=384.0, skew_angle_deg=90.5), image_size=(1024, 768)
    )
    pixels, _ = sampler.record(
        rig, sim.points_in_camera(rig, sim.object_points(body, s)), jax.random.key(seed)
    )
    return io.VelocityData(
        t=np.asarray(ts),
        pixels=np.asarray(pixels),
        A=np.asarray(rig.A),
        R_star=np.asarray(body.R[0]),
        s1=np.asarray(s[0]),
        known_length=np.array([1.0, 3.0, float(jnp.linalg.norm(s[1] - s[3]))]),
        velocity=np.asarray(body.twist),
    )


def structure_example(
    duration: float = 20.0, seed: int = 0, noise_px: float = 0.1
) -> io.StructureData:
    """The moving-camera scene of the module docstring: the camera's velocity at 200 Hz,
    its frames at 50 Hz (pixel noise `noise_px`), the truth at the frames."""
    fine_hz, frame_hz, velocity_hz = 1000, 50, 200
    ts = jnp.arange(int(round(duration * fine_hz)), dtype=float) / fine_hz
    w = 2.0 * np.pi * 0.2
    z = jnp.zeros_like(ts)
    x = jnp.stack([0.5 * jnp.sin(w * ts), z, z], axis=1)
    v = jnp.stack([0.5 * w * jnp.cos(w * ts), z, z], axis=1)
    camera = sim.Trajectory(
        ts=ts,
        R=jnp.broadcast_to(jnp.eye(3), (ts.shape[0], 3, 3)),
        x=x,
        twist=jnp.concatenate([v, jnp.zeros_like(v)], axis=1),
    )
    start, speed = jnp.array([0.0, -0.4, 2.5]), jnp.array([0.0, 0.04, 0.0])
    point = start[None, :] + ts[:, None] * speed[None, :]
    K_c = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
    scene = sim.moving_point_scene(
        camera, point, jnp.broadcast_to(speed, point.shape), K_c, image_size=(640.0, 480.0)
    )
    frames = slice(0, None, fine_hz // frame_hz)
    key = jax.random.key(seed) if noise_px > 0 else None
    pixels = sim.add_pixel_noise(key, scene.pixels[frames], noise_px)
    velocity = slice(0, None, fine_hz // velocity_hz)
    return io.StructureData(
        t=np.asarray(ts[frames]),
        pixels=np.asarray(pixels),
        A=K_c,
        camera_t=np.asarray(ts[velocity]),
        camera_velocity=np.asarray(scene.camera_velocity[velocity]),
        D=np.array([0.0, 1.0, 0.0]),  # the target moves vertically in the image
        depth_guess=np.array(4.0),
        position=np.asarray(scene.position[frames]),
    )


def euclidean_example(
    duration: float = 40.0, seed: int = 0, noise_px: float = 0.2, dropout: float = 0.02
) -> io.EuclideanData:
    """The uncalibrated-camera scene of the module docstring, logged at 200 Hz: fx 900 px,
    a 91.5 degree pixel grid, principal point (524, 371); the camera 27 degrees down with
    a 2 degree tilt that the nominal mounting does not know; 6 known and 5 unknown
    features 2-3.2 m away; a slow platform."""
    deg = np.pi / 180.0
    A = sim.intrinsics(900.0, cx=524.0, cy=371.0, skew_angle_deg=91.5)
    R_nominal = so3_exp(jnp.array([-27.0 * deg, 0.0, 0.0]))
    R_c = R_nominal @ so3_exp(2.0 * deg * jnp.array([1.0, 1.0, 1.0]) / np.sqrt(3.0))
    x_c = jnp.array([0.03, -0.06, 0.15])
    rig = sim.CameraRig(A=A, R_c=R_c, x_c=x_c, image_size=(1024, 768))
    # features placed by their direction and depth from the camera at the start
    rays = np.array(
        [
            (-0.3, -0.2, 2.1),
            (0.32, -0.18, 2.6),
            (0.28, 0.22, 3.1),
            (-0.25, 0.2, 2.4),
            (0.0, -0.05, 3.2),
            (0.1, 0.1, 2.0),
            (-0.15, 0.05, 2.3),
            (0.2, -0.1, 2.9),
            (0.05, 0.18, 2.2),
            (-0.22, -0.12, 3.0),
            (0.12, 0.02, 2.6),
        ]
    )
    m = np.stack([rays[:, 0] * rays[:, 2], rays[:, 1] * rays[:, 2], rays[:, 2]], 1)
    world = jnp.asarray(np.asarray(x_c) + m @ np.asarray(R_c).T)

    def pose(t):
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

    sampler = sim.Sampler(rate_hz=200.0, noise_px=noise_px, dropout=dropout)
    ts = sampler.times(duration)
    R_b, x_b = jax.vmap(pose)(ts)
    body = sim.Trajectory(ts=ts, R=R_b, x=x_b, twist=jnp.zeros((ts.shape[0], 6)))  # poses only
    pixels, _ = sampler.record(rig, sim.points_in_camera(rig, world, body), jax.random.key(seed))
    return io.EuclideanData(
        t=np.asarray(ts),
        pixels=np.asarray(pixels),
        platform_R=np.asarray(R_b),
        platform_x=np.asarray(x_b),
        known_features=np.asarray(world[:6]),
        # the nominal camera: fx 880 px, no skew, the image centre, 27 degrees down, the
        # offset 1 cm off on each axis
        A_nominal=np.asarray(sim.intrinsics(880.0, cx=512.0, cy=384.0)),
        R_c_nominal=np.asarray(R_nominal),
        x_c_nominal=np.array([0.04, -0.05, 0.14]),
        features=np.asarray(world[6:]),
    )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="examples/data", help="folder (default examples/data)")
    parser.add_argument(
        "--duration",
        type=float,
        default=10.0,
        help="seconds of the velocity file; the structure file is twice as long, the euclidean "
        "one four times (default 10)",
    )
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    written = [
        velocity_example(args.duration).save(out / "velocity.npz"),
        structure_example(2 * args.duration).save(out / "structure.npz"),
        euclidean_example(4 * args.duration).save(out / "euclidean.npz"),
    ]
    for path in written:
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
