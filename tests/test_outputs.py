"""Every output of `visjax reproduce --quick` loads with pandas or NumPy and follows its
documented schema (`visjax.io.SUMMARIES`, `TABLES`, `ARRAYS`); the schema checks refuse
what does not."""

import json
import math
import pathlib

import numpy as np
import pandas as pd
import pytest

from tests.helpers import check_outputs
from visjax import __version__, studies
from visjax.cli import main
from visjax.io import (
    COMMON,
    SUMMARIES,
    TABLES,
    command_summary,
    read_summary,
    schema_markdown,
    validate_summary,
    write_summary as write,
)
from visjax.recording import MAX_TIMES


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce") / "results"
    rrd = out.parent / "results.rrd"  # the Rerun recording, read back below
    argv = ["reproduce", "--quick", "--quiet", "--format", "png,pdf", "--rerun", str(rrd)]
    assert main([*argv, "--out", str(out)]) == 0
    return out


@pytest.mark.slow
def test_reproduce_writes_a_rerun_recording_of_every_reproduction(results):
    """`reproduce --rerun`: read back with Rerun's own reader, each reproduction's arrays
    with a time axis are entities of one row per time (decimated to `MAX_TIMES`), and the
    testbed's video is there as at most 100 frames."""
    pytest.importorskip("rerun")
    from rerun.chunk import RrdReader

    rows = {}
    for chunk in RrdReader(results.parent / "results.rrd").stream():
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    with np.load(results / "velocity" / "estimate.npz") as estimate:
        n = len(estimate["t"][:: max(1, -(-len(estimate["t"]) // MAX_TIMES))])
    assert rows["/velocity/estimate/v_hat_0"] == n
    frames = [e for e in rows if e.startswith("/testbed/") and e.endswith("/frames")]
    assert frames and all(0 < rows[e] <= 100 for e in frames), frames
    assert {e.split("/")[1] for e in rows if e != "/__properties"} >= {"velocity", "testbed"}


@pytest.mark.slow
def test_every_output_of_reproduce_quick_loads_with_its_schema(results):
    kinds = check_outputs(results)
    # one summary per command, each of its documented kind
    assert kinds == {
        "summary.json": "reproduce",
        "velocity/summary.json": "velocity",
        "geometry/summary.json": "geometry",
        "moving_point/summary.json": "moving_point",
        "static_points/summary.json": "static_points",
        "testbed/summary.json": "testbed",
        "point_depth/summary.json": "point_depth",
        "homography/summary.json": "homography",
    }
    # every figure in both formats asked for
    pngs = {p.with_suffix("") for p in results.rglob("*.png")}
    pdfs = {p.with_suffix("") for p in results.rglob("*.pdf")}
    assert pngs == pdfs and len(pngs) >= 5
    # every set's trajectory saved, with the camera-velocity figure of the thesis
    for name in ("I.1", "I.2", "I.3", "I.4", "II.1", "II.2", "II.3"):
        assert (results / "moving_point" / f"estimate_{name}.npz").is_file()
        assert (results / "moving_point" / f"camera_velocity_{name}.png").is_file()


@pytest.mark.slow
def test_the_reproduce_table_holds_numbers(results):
    top = json.loads((results / "summary.json").read_text())
    assert top["quick"] is True and top["settings"]["quick"] is True
    for row in top["rows"]:
        assert list(row) == ["name", "value", "reference", "reference_kind", "unit"]
        assert row["value"] is None or isinstance(row["value"], float), row
        assert isinstance(row["reference"], float), row
        assert row["reference_kind"] in studies.REFERENCE_KINDS, row
        assert "seed 0" not in row["name"]
    table = pd.read_parquet(results / "summary.parquet")
    assert table["value"].dtype == np.float64
    np.testing.assert_allclose(
        table["value"].to_numpy(),
        [np.nan if r["value"] is None else r["value"] for r in top["rows"]],
    )
    velocity = read_summary(results / "velocity" / "summary.json")
    # the scoring window is the paper's 5-10 s for its 10 s run, named by value, not by key
    assert velocity["window_s"] == [5.0, 10.0] and len(velocity["rms_window"]) == 6
    assert max(velocity["rms_window"]) == pytest.approx(top["rows"][0]["value"])
    estimate = np.load(results / "velocity" / "estimate.npz")
    err = estimate["v_hat"] - estimate["velocity"]
    inside = (estimate["t"] >= 5.0) & (estimate["t"] < 10.0)
    np.testing.assert_allclose(
        np.sqrt(np.mean(err[inside] ** 2, axis=0)), velocity["rms_window"], rtol=1e-12
    )
    # the structure table equals its summary
    structure = read_summary(results / "moving_point" / "summary.json")
    sets = pd.read_parquet(results / "moving_point" / "sets.parquet")
    for name, record in structure["sets"].items():
        rows = sets[sets["set"] == name].sort_values("axis")
        np.testing.assert_allclose(rows["rms_m"], record["rms"], rtol=1e-12)


def _valid(kind="static_points"):
    body = {
        "final_position_error_m": [0.001, float("nan")],
        "duration_s": 1.0,
        "noise_px": 0.0,
        "final_camera_prediction_error_px": 0.2,
        "covariance_resets": 3,
    }
    meta = {
        "kind": kind,
        "visjax_version": __version__,
        "jax_version": "0",
        "created_utc": "2026-01-01T00:00:00+00:00",
        "wall_time_s": 1.5,
        "seed": None,
        "settings": {"duration": 1.0},
    }
    return {**meta, **body}


def test_schema_checks_refuse_what_is_not_documented(tmp_path):
    written = write(tmp_path / "summary.json", _valid())
    assert written["final_position_error_m"][1] is None  # NaN is written as null
    loaded = pd.read_json(tmp_path / "summary.json", typ="series")
    assert loaded["covariance_resets"] == 3 and math.isclose(loaded["wall_time_s"], 1.5)
    # every digit json wrote is read back (pandas' default parser rounds the last ones)
    x = 0.00040141514610180667
    write(tmp_path / "summary.json", {**_valid(), "final_position_error_m": [x, 0.1]})
    assert read_summary(tmp_path / "summary.json")["final_position_error_m"][0] == x
    bad = _valid()
    del bad["covariance_resets"]
    with pytest.raises(ValueError, match="'covariance_resets' is missing"):
        validate_summary(bad)
    bad = {**_valid(), "covariance_resets": "3"}
    with pytest.raises(ValueError, match="'covariance_resets' must be int"):
        validate_summary(bad)
    with pytest.raises(ValueError, match="keys not in its schema: \\['rms_5_10s'\\]"):
        validate_summary({**_valid(), "rms_5_10s": [0.1]})
    with pytest.raises(ValueError, match="`kind` must be one of"):
        validate_summary({**_valid(), "kind": "nonsense"})
    with pytest.raises(ValueError, match="'seed' must be int\\|null"):
        validate_summary({**_valid(), "seed": 1.5})
    # a kind of visjax 0.3: read as the new one, with a warning; never written
    (tmp_path / "old.json").write_text(json.dumps(_valid("euclidean")))
    with pytest.warns(FutureWarning, match="'euclidean' of visjax 0.3 is now 'static_points'"):
        assert read_summary(tmp_path / "old.json")["covariance_resets"] == 3
    with pytest.raises(ValueError, match="`kind` must be one of"):
        command_summary("structure", {}, settings={}, seed=None, started=0.0)


def test_the_schemas_are_documented():
    page = (pathlib.Path(__file__).parents[1] / "docs" / "outputs.md").read_text()
    assert schema_markdown() in page  # the page's tables are generated from the schemas
    for key in COMMON:
        assert f"`{key}`" in page
    for kind, keys in SUMMARIES.items():
        assert f"`{kind}`" in page
        for key in keys:
            assert f"`{key}`" in page, (kind, key)
    for name, columns in TABLES.items():
        assert f"`{name}`" in page
