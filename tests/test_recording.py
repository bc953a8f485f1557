"""Recordings for the Rerun viewer (`visjax.recording`) of the problems whose recordings
hold more than time series: the camera's path and the world's points (a camera on a moving
platform, Nath et al.'s), the homography's error (Hamel et al.'s), read back with Rerun's
own reader."""

import numpy as np
import pytest

from visjax import recording, studies

pytestmark = pytest.mark.slow  # two problems built and run
rerun = pytest.importorskip("rerun")


def test_the_camera_path_the_world_points_and_the_homographys_error(tmp_path):
    from rerun.chunk import RrdReader

    path = tmp_path / "two.rrd"
    rec = recording.open_recording(path)
    platform = studies.problem("static_points", duration=1.0)
    homography = studies.problem("homography", duration=0.2)
    recording.log_problem(rec, "static_points", platform, ["estimator"])
    recording.log_problem(rec, "homography", homography, ["estimator"])
    rec.disconnect()
    rows = {}
    for chunk in RrdReader(path).stream():
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    n = len(np.asarray(platform.ts))
    assert rows["/static_points/camera"] == min(n, recording.MAX_TIMES)
    assert rows["/static_points/camera_path"] == 1  # static: the whole path
    assert rows["/static_points/world/known"] == rows["/static_points/world/unknown_true"] == 1
    sol = studies.solution(homography, None, 0)
    assert rows["/homography/estimator/error/H"] == len(np.asarray(sol.ts))
    with pytest.raises(ValueError, match=r"ends in \.rrd"):
        recording.open_recording(tmp_path / "x.txt")
