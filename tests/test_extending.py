"""`docs/extending.md`, run as it stands: its Python blocks, in order, are the module
`my_problem.py`; its bash block's commands run through `visjax.cli.main` with nothing in
visjax changed (the problem reaches the command line by `--import`, the public path). The
numbers asserted are what the page's example is for: the observer, swept and tuned, beats
central differences on noisy tracks, and the sweep's best bandwidth beats the default."""

import re
import shlex
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pandas as pd
import pytest

from visjax.cli import main
from visjax.io import read_summary

PAGE = Path(__file__).resolve().parents[1] / "docs" / "extending.md"


def _blocks(language):
    return re.findall(rf"```{language}\n(.*?)```", PAGE.read_text(), flags=re.S)


@pytest.fixture(scope="module")
def module_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("extending")
    (folder / "my_problem.py").write_text("\n\n".join(_blocks("python")))
    yield folder
    from visjax.studies import _registry

    # the page's module adds a method to the velocity problem: gone for the other modules
    _registry._ADDED.get("velocity", {}).pop("differenced", None)


def test_the_page_runs_from_the_command_line(module_dir, monkeypatch, capsys):
    monkeypatch.chdir(module_dir)
    monkeypatch.syspath_prepend(str(module_dir))
    commands = [shlex.split(line) for line in _blocks("bash")[0].strip().splitlines()]
    assert [c[3] for c in commands] == ["run", "sweep", "tune", "compare"]
    for argv in commands:
        assert argv[:3] == ["visjax", "--import", "my_problem"]
        assert main([*argv[1:], "--quiet"]) == 0, argv

    run = read_summary(module_dir / "run_out" / "summary.json")
    assert run["kind"] == "run" and run["result"] == "successful"
    import my_problem

    from visjax import studies

    problem = studies.problem("pixel_velocity", noise_px=0.5)
    assert isinstance(problem, my_problem.PixelVelocityProblem)
    ev = studies.evaluate(problem, keys=jax.random.key(0)[None])
    np.testing.assert_allclose(run["metrics"]["rms"], ev.metrics["rms"][0], rtol=1e-10)

    sweep = read_summary(module_dir / "sweep_out" / "summary.json")
    table = pd.read_parquet(module_dir / "sweep_out" / "runs.parquet")
    assert len(table) == 7 * 4 and (table["result"] == "successful").all()
    best = sweep["best"]["params"]["omega"]
    assert 1.0 < best < 100.0  # the error is U-shaped in the bandwidth: lag vs noise
    assert sweep["best"]["metric"] < sweep["paper"]["metric"]  # held-out seeds

    tune = read_summary(module_dir / "tune_out" / "summary.json")
    assert tune["training_loss"]["tuned"] <= tune["training_loss"]["sweep_best"]

    records = pd.read_parquet(module_dir / "compare_out" / "records.parquet")
    assert set(records["method"]) == {"estimator", "differences"}
    med = records.groupby("method")["rms_worst"].median()
    # 0.5 px (the builder's default noise: the command line's --noise defaults to the
    # problem's own) at 100 Hz: central differences carry the noise sigma / (sqrt(2) dt) =
    # 35.4 px/s per axis (truncation error ~1e-4 px/s), the worst of two axes above it
    assert 33.0 < med["differences"] < 45.0, med
    assert read_summary(module_dir / "compare_out" / "summary.json")["noise_px"] == 0.5
    assert np.isfinite(med["estimator"]) and med["estimator"] > 0
    assert "held-out" in capsys.readouterr().out

    # the page's reproduction, registered by the same module: its row, checked; central
    # differences at 0.5 px carry 0.5 / (sqrt(2) 0.01 s) = 35.4 px/s per axis
    (row,) = studies.registered_reproduction("pixel_velocity").rows(None, quick=True)
    assert row["reference_kind"] == "trivial" and row["unit"] == "px/s"
    assert 33.0 < row["reference"] < 42.0 and 0 < row["value"] < row["reference"], row


@pytest.mark.slow
def test_the_page_runs_as_a_script(module_dir):
    """`python my_problem.py`: the page's Python studies; at 0.5 px, the swept observer
    beats central differences by more than a factor 2, and tuning improves on the sweep."""
    proc = subprocess.run(
        [sys.executable, "my_problem.py"],
        cwd=module_dir,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = proc.stdout.splitlines()
    rms = {}
    for line in lines:
        parts = line.split()
        if parts and parts[0] in ("estimator", "differences"):
            rms.setdefault(parts[0], []).append(float(parts[3]))
    assert np.median(rms["estimator"]) < 0.5 * np.median(rms["differences"]), rms
    best = float(re.search(r"best bandwidth: .*?\} ([\d.e+-]+) px/s", proc.stdout).group(1))
    tuned = float(re.search(r"tuned: .*?\} ([\d.e+-]+)", proc.stdout).group(1))
    assert tuned <= best


@pytest.mark.slow  # the velocity problem's compiles (about 30 s)
def test_a_method_of_your_own_beside_the_velocity_estimator(module_dir, monkeypatch, capsys):
    """The page's second example from the command line: the differenced velocity added to
    the registered `velocity` problem by the `--import`ed module, run, swept over its own
    parameter, and both methods tuned with the same budget and compared on the same draws;
    at 0.1 px over 1 s it beats zero velocity (the trivial estimate), its swept cutoff
    beats its default on held-out seeds, and the tuning spends 4 evaluations on each
    method's own parameters over the two seeds after the compared ones."""
    monkeypatch.chdir(module_dir)
    commands = [shlex.split(line) for line in _blocks("bash")[1].strip().splitlines()]
    assert [c[3] for c in commands] == ["run", "sweep", "compare"]
    for argv in commands:
        assert main([*argv[1:], "--quiet"]) == 0, argv
    run = read_summary(module_dir / "diff_run" / "summary.json")
    assert run["method"] == "differenced" and run["result"] == "successful"
    assert run["quality"]["ratio_to_trivial"] < 1, run["quality"]
    sweep = read_summary(module_dir / "diff_sweep" / "summary.json")
    assert sweep["method"] == "differenced" and sweep["best"]["metric"] < sweep["paper"]["metric"]
    records = pd.read_parquet(module_dir / "diff_compare" / "records.parquet")
    assert list(records["method"]) == ["estimator", "differenced"] * 2
    assert (records["result"] == "successful").all()
    summary = read_summary(module_dir / "diff_compare" / "summary.json")
    assert summary["problem_settings"]["added_methods"]["differenced"]["like"] == "ekf"
    tuning = summary["tuning"]
    assert tuning["budget"] == 4 and tuning["train_seeds"] == [2, 3]
    assert set(records["seed"]) == {0, 1}  # disjoint from the training seeds
    own = tuning["methods"]["differenced"]
    assert own["evaluations"] == 4 and list(own["searched"]) == ["cutoff_hz"]
    assert own["searched"]["cutoff_hz"] == [0.5, 50.0]
    assert (own["train_failed"], own["train_median"]) <= (
        own["train_failed_at_defaults"],
        own["train_median_at_defaults"],
    )
    assert list(tuning["methods"]["estimator"]["searched"]) == ["K_scale", "rho_scale"]
    history = pd.read_parquet(module_dir / "diff_compare" / "tuning.parquet")
    assert len(history) == 8 and set(history["method"]) == {"estimator", "differenced"}
