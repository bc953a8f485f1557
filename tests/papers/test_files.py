"""`papers.*_from_file`, what `visjax velocity|structure|euclidean --data` runs (moved out
of the report): the second-half RMS by hand, and a file run equal to the same estimator run
through its problem (two independent paths: the saved trajectory's last sample against the
final state's output)."""

import jax
import numpy as np
import pytest

from tests.helpers import euclidean_scene_file
from visjax import papers, studies
from visjax.papers._files import last_half_rms


def test_last_half_rms_by_hand_skips_nan():
    t = np.arange(6.0)  # second half: t >= 2.5, samples 3, 4, 5
    est = np.array([[9.0, 0], [9, 0], [9, 0], [1, 2], [np.nan, 2], [3, 2]])
    truth = np.zeros((6, 2))
    rms, window = last_half_rms(t, est, truth)
    np.testing.assert_allclose(rms, [np.sqrt((1 + 9) / 2), 2.0], rtol=1e-15)
    assert window == [3.0, 5.0]


def test_static_points_file_run_equals_its_problem(tmp_path):
    path = euclidean_scene_file(tmp_path / "scene.npz", 2.0, 20.0)
    run = papers.static_points_from_file(path)
    assert run.failure is None and run.body["result"] == "successful"
    assert run.arrays["features"].shape[1:] == (run.body["unknown_features"], 3)
    problem = papers.static_points_problem(data=path, noise_px=0.0)
    ev = studies.evaluate(problem, keys=jax.random.key(0)[None])
    np.testing.assert_allclose(
        run.body["final_position_error_m"], ev.metrics["error"][0], rtol=1e-10
    )
    assert max(run.body["final_position_error_m"]) < 0.5  # 2 s in: converging, not diverged
    with pytest.raises(ValueError, match="`exciting` chooses the project's scene"):
        papers.static_points_problem(data=path, exciting=False)
