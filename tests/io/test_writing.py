"""`visjax.io.write_outputs` and `command_summary`: what a command writes, checked."""

import json
import time

import numpy as np
import pandas as pd
import pytest

from visjax.io import Outputs, command_summary, write_outputs


def test_write_outputs_writes_every_kind_and_names_it(tmp_path):
    drawn = []

    def draw(*, path, formats):
        drawn.append((path.name, tuple(formats)))
        for f in formats:
            path.with_suffix("." + f).write_text(f)

    table = pd.DataFrame({"a": [1.0, np.nan], "b": ["x", "y"]})
    outputs = Outputs(
        arrays={"estimate.npz": {"t": [0.0, 0.5], "x": np.eye(2)}},
        tables={"rows": table, "other": table},
        csv=("rows",),
        figures={"fig": draw},
        json={"calibration.json": {"v": float("nan"), "w": [1.0, float("inf")]}},
        videos={"clip.mp4": lambda path: path.write_bytes(b"mp4")},
    )
    written = write_outputs(outputs, tmp_path / "new", ("png", "svg"))
    assert written == [
        "estimate.npz", "rows.parquet", "rows.csv", "other.parquet", "calibration.json",
        "fig.png", "fig.svg", "clip.mp4",
    ]  # fmt: skip
    out = tmp_path / "new"
    assert sorted(p.name for p in out.iterdir()) == sorted(written)
    with np.load(out / "estimate.npz") as z:
        np.testing.assert_array_equal(z["x"], np.eye(2))
        np.testing.assert_array_equal(z["t"], [0.0, 0.5])
    pd.testing.assert_frame_equal(pd.read_parquet(out / "rows.parquet"), table)
    assert pd.read_csv(out / "rows.csv")["b"].tolist() == ["x", "y"]
    assert json.loads((out / "calibration.json").read_text()) == {"v": None, "w": [1.0, None]}
    assert drawn == [("fig.png", ("png", "svg"))]


def test_command_summary_checks_its_schema_and_writes_it(tmp_path):
    body = {
        "final_position_error_m": [0.001, float("nan")],
        "duration_s": 1.0,
        "noise_px": 0.0,
        "final_camera_prediction_error_px": 0.2,
        "covariance_resets": 3,
    }
    started = time.perf_counter()
    s = command_summary(
        "static_points", body, settings={"out": tmp_path}, seed=None, started=started, out=tmp_path
    )
    assert s["final_position_error_m"] == [0.001, None] and s["settings"]["out"] == str(tmp_path)
    assert 0.0 <= s["wall_time_s"] < 60.0
    assert json.loads((tmp_path / "summary.json").read_text()) == s
    with pytest.raises(ValueError, match="covariance_resets"):
        command_summary("static_points", {**body, "covariance_resets": "3"}, settings={}, seed=None,
                        started=started)  # fmt: skip
