"""Write one complete example data file per estimator, in the formats of `visjax.io`
(README, "Your own data"), from scenes that are none of the papers' own:

- `velocity.npz`: a plate with six irregular coplanar features, 1.5 m in front of a fixed
  camera with a slightly skewed pixel grid, moving on all six degrees of freedom; 1 kHz,
  0.1 px pixel noise, 2% of the feature observations missing (NaN).
- `structure.npz`: a camera translating sideways (sinusoid, 0.5 m amplitude) 2.5 m from a
  target moving along a line; frames at 50 Hz, camera velocities at 200 Hz.
- `euclidean.npz`: a camera looking 27 degrees down from a slowly moving platform at ten
  static features 2-3.2 m away, five of them known; the nominal camera is off the true
  one (focal length, skew, principal point, a 2 degree tilt, the offset).

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


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="examples/data", help="folder (default examples/data)")
    parser.add_argument("--duration", type=float, default=10.0, help="seconds (default 10)")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    written = [velocity_example(args.duration).save(out / "velocity.npz")]
    for path in written:
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
