"""A real lens' distortion through a problem: ignoring it biases the estimate, giving it
(`dist` in the data file) removes the bias."""

import dataclasses

import jax
import numpy as np
import pytest

from tests.example_data import structure_example
from visjax import papers, studies
from visjax.geometry import distort_pixels


@pytest.mark.slow  # three runs of the moving point's observer from files (12 s)
def test_ignoring_a_lens_biases_the_moving_point_and_dist_removes_the_bias(tmp_path):
    """The example structure file (6 s, noise-free) seen through a wide-angle lens, k1 =
    -0.3 (up to 2.9 px here, at the image's edge): the observer's worst-axis RMS over the
    second half, measured 2.5 mm from the pinhole's pixels, 45 mm from the lens' pixels
    taken for a pinhole's, and the pinhole's again from the lens' pixels with `dist`."""
    pinhole = structure_example(duration=6.0, noise_px=0.0)
    dist = np.array([-0.3, 0.0, 0.0, 0.0])
    raw = np.asarray(distort_pixels(pinhole.pixels, pinhole.A, dist))
    assert 2.0 < np.nanmax(np.abs(raw - pinhole.pixels)) < 4.0
    files = {
        "pinhole": pinhole,
        "ignored": dataclasses.replace(pinhole, pixels=raw),
        "corrected": dataclasses.replace(pinhole, pixels=raw, dist=dist),
    }
    rms = {}
    for name, data in files.items():
        problem = papers.moving_point_problem(data=data.save(tmp_path / f"{name}.npz"))
        ev = studies.evaluate(problem, keys=jax.random.key(0)[None])
        rms[name] = float(ev.metrics["rms_worst"][0])
    assert rms["pinhole"] < 0.005
    assert rms["ignored"] > 10 * rms["pinhole"]  # the bias: 45 mm against 2.5
    assert rms["corrected"] == pytest.approx(rms["pinhole"], rel=1e-6)
