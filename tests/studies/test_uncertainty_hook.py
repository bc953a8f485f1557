"""`AbstractProblem.uncertainty` reported by `compare` (the batch baselines' predicted
spread beside their errors), and the homography problem's robust `dlt`."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax import papers, studies
from visjax._results import RESULTS
from visjax.papers import hamel


@pytest.mark.slow  # four methods compiled; point-depth's compare test is in the unit tier
def test_compare_reports_the_static_points_predicted_spread():
    problem = papers.static_points_problem(noise_px=0.5, duration=2.0, rate_hz=20.0)
    records = studies.compare(problem, range(2), study=studies.Study(repeats=1))
    by = {(r["method"], r["seed"]): r for r in records}
    n = len(by[("batch", 0)]["error"])
    for method in ("batch", "batch_window", "ekf"):
        for seed in (0, 1):
            r = by[(method, seed)]
            assert r["result"] == "successful"
            std = np.asarray(r["error_std"], float)
            assert std.shape == (n,) and np.all(std > 0) and np.all(std < 0.1)
    # the batch fit's prediction is the spread of its error: the two seeds' errors are
    # within a few predicted standard deviations (a 3-d error's norm over its predicted
    # RMS is about 1; over 8 it is a chi-square(3) tail below 1e-12)
    for seed in (0, 1):
        r = by[("batch", seed)]
        ratio = np.asarray(r["error"]) / np.asarray(r["error_std"])
        assert np.all(ratio < 8.0), ratio
    assert by[("estimator", 0)]["error_std"] == [None] * n


def test_nullable_json_keeps_the_numbers():
    out = studies._problem.as_json(
        {"a": jnp.array([1.0, jnp.nan]), "b": jnp.array(jnp.nan), "c": jnp.array(2.0)},
        True,
        nullable=True,
    )
    assert out == {"a": [1.0, None], "b": None, "c": 2.0}
    assert studies._problem.as_json({"a": jnp.array([1.0])}, False, nullable=True) == {"a": None}


@pytest.mark.slow  # a RANSAC compile over frames: the unit tier's time
def test_robust_dlt_takes_outlier_points_the_corner_dlt_does_not():
    clean = hamel.homography_problem(duration=0.05, rate_hz=200.0)
    robust = hamel.homography_problem(duration=0.05, rate_hz=200.0, robust=True)
    assert "find_homography_robust" in robust.settings()["dlt_points"]
    params = clean.resolve()
    inputs = clean.inputs(jax.random.key(0))
    # one corner 40 px off in every frame: an outlier of the corner DLT's own four points
    bad = dict(inputs, pixels=inputs["pixels"].at[:, 0].add(40.0))

    def err(problem, data):
        sol = problem.solve("dlt", params, data)
        assert sol.result == RESULTS.successful
        return float(problem.metrics("dlt", sol)["error"])

    e_clean, e_plain, e_robust = err(clean, inputs), err(clean, bad), err(robust, bad)
    assert e_clean < 1e-9 and e_robust < 1e-9, (e_clean, e_robust)
    assert e_plain > 0.05, e_plain
