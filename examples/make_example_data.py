"""Write one complete example data file per estimator, in the formats of `visjax.io`
(docs/your-own-data.md), from scenes that are none of the papers' own:

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

The scenes are those of `visjax.sim`'s catalogue (`sinusoidal_plate_record`,
`sideways_camera_record`, `tilted_platform_record`: their docstrings give every
parameter); this script wraps them in `visjax.io`'s data classes and saves them. Each file
holds the truth keys too, so that `visjax ... --data` reports its errors. Run:

    python examples/make_example_data.py --out examples/data
"""

import argparse
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

from visjax import io, sim  # noqa: E402


def velocity_example(
    duration: float = 10.0, seed: int = 0, noise_px: float = 0.1, dropout: float = 0.02
) -> io.VelocityData:
    """The fixed-camera scene of the module docstring (`sim.sinusoidal_plate_record`)."""
    return io.VelocityData(**sim.sinusoidal_plate_record(duration, seed, noise_px, dropout))


def structure_example(
    duration: float = 20.0, seed: int = 0, noise_px: float = 0.1
) -> io.MovingPointData:
    """The moving-camera scene of the module docstring (`sim.sideways_camera_record`): the
    camera's velocity at 200 Hz, its frames at 50 Hz (pixel noise `noise_px`), the truth at
    the frames."""
    return io.MovingPointData(**sim.sideways_camera_record(duration, seed, noise_px))


def euclidean_example(
    duration: float = 40.0, seed: int = 0, noise_px: float = 0.2, dropout: float = 0.02
) -> io.StaticPointsData:
    """The uncalibrated-camera scene of the module docstring (`sim.tilted_platform_record`),
    logged at 200 Hz: fx 900 px, a 91.5 degree pixel grid, principal point (524, 371); the
    camera 27 degrees down with a 2 degree tilt that the nominal mounting does not know; 6
    known and 5 unknown features 2-3.2 m away; a slow platform."""
    return io.StaticPointsData(**sim.tilted_platform_record(duration, seed, noise_px, dropout))


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
