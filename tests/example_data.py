"""The example data of `examples/make_example_data.py`, built for the tests from the same
catalogue scenes of `visjax.sim` (the script is not imported: it is a script), wrapped in
the same `visjax.io` data classes; the same arrays for the same arguments."""

from visjax import io, sim


def velocity_example(
    duration: float = 10.0, seed: int = 0, noise_px: float = 0.1, dropout: float = 0.02
) -> io.VelocityData:
    """`velocity.npz`: `sim.sinusoidal_plate_record`."""
    return io.VelocityData(**sim.sinusoidal_plate_record(duration, seed, noise_px, dropout))


def structure_example(
    duration: float = 20.0, seed: int = 0, noise_px: float = 0.1
) -> io.MovingPointData:
    """`structure.npz`: `sim.sideways_camera_record`."""
    return io.MovingPointData(**sim.sideways_camera_record(duration, seed, noise_px))


def euclidean_example(
    duration: float = 40.0, seed: int = 0, noise_px: float = 0.2, dropout: float = 0.02
) -> io.StaticPointsData:
    """`euclidean.npz`: `sim.tilted_platform_record`."""
    return io.StaticPointsData(**sim.tilted_platform_record(duration, seed, noise_px, dropout))
