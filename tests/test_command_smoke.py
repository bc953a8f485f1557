"""One small smoke test for each study command (`run`, `compare`, `sweep`, `tune`) on the
cheapest problem (the unknown input observer of Jang's thesis, set I.1, two seconds): the
command succeeds, every output loads with pandas against its documented schema, and the
numbers are those of the library call it makes. Product-scale runs of these commands are
the slow tests of `tests/test_cli.py`."""

import json

import numpy as np
import pandas as pd
import pytest

from visjax.cli import main
from visjax.io import read_summary

SMALL = ["moving_point", "--set", "I.1", "--duration", "2", "--seeds", "1", "--noise", "0.5"]


def _strict_json(path):
    return json.loads(path.read_text(), parse_constant=pytest.fail)


def test_compare_smoke(tmp_path, capsys):
    out = tmp_path / "compare"
    argv = ["compare", "structure", "--duration", "2", "--seeds", "1", "--noise", "0.5"]
    assert main([*argv, "--quiet", "--out", str(out)]) == 0
    summary = read_summary(out / "summary.json")
    assert summary["kind"] == "compare"
    records = pd.read_parquet(out / "records.parquet")
    assert set(records["method"]) == {"estimator", "batch", "batch_window", "ekf"}
    assert (records["result"] == "successful").all()
    assert (records["latency_s_per_sample"] > 0).all()
    rms = records[["rms_X", "rms_Y", "rms_Z"]].to_numpy()  # tidy: a column per axis
    assert rms.shape == (4, 3) and np.all(np.isfinite(rms)) and np.all(rms > 0)
    named = set(records.columns) - {"method", "result"}  # no list-valued column
    assert all(pd.api.types.is_numeric_dtype(records[c]) for c in named)
    csv = pd.read_csv(out / "records.csv")
    assert len(csv) == 4 and np.allclose(csv[["rms_X", "rms_Y", "rms_Z"]], rms, rtol=1e-15)
    assert (out / "comparison.png").stat().st_size > 0
    assert "batch_window" in capsys.readouterr().out


def test_sweep_and_tune_smoke(tmp_path, capsys):
    """`sweep` then `tune` of the same small problem in one process: the table's rows, the
    best point, strict JSON; the tuned point no worse on its training seed than the
    sweep's best it started from. The structure problem writes one folder per thesis set
    and a top-level summary of kind `sets`."""
    sweep_out, tune_out = tmp_path / "sweep", tmp_path / "tune"
    grid = ["--grid", "K_scale=0.5/1,Y_scale=1"]
    assert main(["sweep", *SMALL, *grid, "--quiet", "--out", str(sweep_out)]) == 0
    assert read_summary(sweep_out / "summary.json")["kind"] == "sets"
    one = sweep_out / "I_1"
    table = pd.read_parquet(one / "runs.parquet")
    assert len(table) == 2 and (table["result"] == "successful").all()
    assert sorted(table["K_scale"]) == [0.5, 1.0] and np.all(table["rms_worst"] > 0)
    pd.testing.assert_frame_equal(pd.read_csv(one / "runs.csv"), table, check_dtype=False)
    summary = _strict_json(one / "summary.json")
    assert read_summary(one / "summary.json")["kind"] == "sweep"
    assert summary["metric"] == "rms_worst"
    best = table.loc[table["rms_worst"].idxmin()]
    assert summary["best"]["params"]["K_scale"] == best["K_scale"]
    # the absolute gains the best point stands for: the published ones times its multiplier
    K_pub = np.array(summary["paper_gains"]["K"])
    np.testing.assert_allclose(summary["best_gains"]["K"], best["K_scale"] * K_pub, rtol=1e-12)
    assert (one / "sweep.png").stat().st_size > 0

    assert main(["tune", *SMALL, *grid, "--steps", "2", "--quiet", "--out", str(tune_out)]) == 0
    assert read_summary(tune_out / "summary.json")["kind"] == "sets"
    one = tune_out / "I_1"
    summary = _strict_json(one / "summary.json")
    assert read_summary(one / "summary.json")["kind"] == "tune"
    assert summary["training_loss"]["tuned"] <= summary["training_loss"]["sweep_best"]
    history = pd.read_csv(one / "history.csv")
    assert len(history) >= 2 and np.all(np.isfinite(history["loss"]))
    assert "held-out" in capsys.readouterr().out


def test_run_smoke(tmp_path, capsys):
    """`visjax run`: one method once; the summary's metrics are those of
    `studies.evaluate` at the same seed, and the estimates table loads with pandas."""
    import jax

    from visjax import studies

    out = tmp_path / "run"
    argv = ["run", "moving_point", "--duration", "2", "--noise", "0.5", "--seed", "3"]
    assert main([*argv, "--quiet", "--out", str(out)]) == 0
    summary = read_summary(out / "summary.json")
    assert summary["kind"] == "run" and summary["result"] == "successful"
    problem = studies.problem("moving_point", duration=2.0, noise_px=0.5)
    ev = studies.evaluate(problem, keys=jax.random.key(3)[None])
    np.testing.assert_allclose(summary["metrics"]["rms"], ev.metrics["rms"][0], rtol=1e-12)
    table = pd.read_parquet(out / "estimates.parquet")
    assert table.columns[0] == "t" and {"X", "Z", "X_true", "Z_true", "x3_hat"} <= set(table)
    # the truth beside the estimate: the run's own rms over the second half, from the table
    half = table[table["t"] >= table["t"].iloc[-1] / 2]
    to_m = problem.to_m
    rms_z = np.sqrt(np.mean((half["Z"] - half["Z_true"]) ** 2)) * to_m
    assert rms_z == pytest.approx(summary["metrics"]["rms"][2], rel=0.05)
    assert np.all(np.diff(table["t"]) > 0) and (out / "run.png").stat().st_size > 0
    assert "rms_worst" in capsys.readouterr().out


def test_run_writes_a_rerun_recording_that_rerun_reads_back(tmp_path):
    """`visjax run --rerun FILE.rrd` (the run of `test_run_smoke`, compiled once): read back
    with Rerun's own reader, every estimate and truth column of `estimates.parquet` is an
    entity with one row per saved time, and the point's 3-D estimate and truth are there."""
    pytest.importorskip("rerun")
    from rerun.chunk import RrdReader

    out, rrd = tmp_path / "run", tmp_path / "run.rrd"
    argv = ["run", "moving_point", "--duration", "2", "--noise", "0.5", "--seed", "3"]
    assert main([*argv, "--quiet", "--rerun", str(rrd), "--out", str(out)]) == 0
    rows = {}
    for chunk in RrdReader(rrd).stream():
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    table = pd.read_parquet(out / "estimates.parquet")
    n = len(table)
    for column in table.columns[1:]:
        kind, name = ("truth", column[:-5]) if column.endswith("_true") else ("estimate", column)
        assert rows[f"/moving_point/estimator/{kind}/{name}"] == n, column
    assert rows["/moving_point/estimator/points"] == n
    assert rows["/moving_point/truth_points"] == n
    with pytest.raises(SystemExit) as refused:  # not a Rerun file: refused before any work
        main(["run", "moving_point", "--rerun", str(tmp_path / "run.txt")])
    assert refused.value.code == 2
