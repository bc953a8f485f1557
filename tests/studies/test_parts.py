"""Sweeps that lose nothing: per-run seeding (any subset of runs reproduces the rows of the
whole sweep), parts written as chunks finish, resume, job slices (`shard`) and merging;
the command line's `--resume`, `--force`, `--shard i/N`, `visjax merge` and a sweep killed
by SIGTERM in a subprocess, resumed to an identical table."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest

from tests.studies.test_problem import toy
from visjax import studies
from visjax.cli import main
from visjax.studies._parts import part_name

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def problem():
    return toy()


@pytest.fixture(scope="module")
def points():
    return {"gain": np.geomspace(0.1, 10.0, 50)}


@pytest.fixture(scope="module")
def whole(problem, points):
    """50 points x 6 seeds = 300 runs in chunks of 32 (10 chunks, the last partial)."""
    return studies.sweep(problem, points, jnp.arange(6), study=studies.Study(chunk=32)).to_pandas()


def test_any_subset_of_runs_reproduces_its_rows(problem, points, whole):
    """Run i's noise comes from its seed's key alone: runs 100-199 computed alone (other
    chunks, other batch sizes), or in reverse order, equal those rows of the whole sweep."""
    alone = studies.sweep(
        problem, points, jnp.arange(6), study=studies.Study(chunk=16, runs=range(199, 99, -1))
    ).to_pandas()
    assert list(alone["run"]) == list(range(100, 200))
    rows = whole.iloc[100:200].reset_index(drop=True)
    pd.testing.assert_frame_equal(alone, rows, check_exact=False, rtol=1e-12, atol=0.0)
    # the rule itself: a run's metric from its own key by hand
    run = 137
    gain, seed = points["gain"][run // 6], run % 6
    value = studies.evaluate(problem, {"gain": gain}, jnp.array([seed])).metrics["error"][0]
    np.testing.assert_allclose(alone.loc[alone["run"] == run, "error"].item(), value, rtol=1e-12)


def test_parts_resume_and_refusals(tmp_path, problem, points, whole):
    """Each chunk a part; two parts lost (an interruption) and resumed: the table equals
    the uninterrupted one exactly; a folder with parts is refused without `resume`, and one
    holding another sweep's parts always."""
    folder = tmp_path / "parts"
    table = studies.sweep(
        problem, points, jnp.arange(6), study=studies.Study(chunk=32, parts=folder)
    ).to_pandas()
    pd.testing.assert_frame_equal(table, whole)
    manifest = json.loads((folder / "manifest.json").read_text())
    assert manifest["done"] == list(range(10)) and manifest["n_runs"] == 300
    assert manifest["info"]["metric"] == "error"
    for c in (3, 9):  # as if the sweep had been killed before writing these
        (folder / part_name(c)).unlink()
    with pytest.raises(studies.PartsError, match="resume"):
        studies.sweep(problem, points, jnp.arange(6), study=studies.Study(chunk=32, parts=folder))
    resumed = studies.sweep(
        problem, points, jnp.arange(6), study=studies.Study(chunk=32, parts=folder, resume=True)
    ).to_pandas()
    pd.testing.assert_frame_equal(resumed, whole)
    with pytest.raises(studies.PartsError, match="different sweep"):
        studies.sweep(
            problem, points, jnp.arange(5), study=studies.Study(chunk=32, parts=folder, resume=True)
        )
    with pytest.raises(ValueError, match="runs"):
        studies.sweep(problem, points, jnp.arange(6), study=studies.Study(runs=[1], parts=folder))


def test_job_slices_merge_and_their_errors(tmp_path, problem, points, whole):
    """Three disjoint slices merge into the whole table; a missing slice names its chunks,
    a slice given twice is a run found twice, parts of another sweep do not merge."""
    folders = []
    for i in range(3):
        f = tmp_path / f"shard{i}"
        part = studies.sweep(
            problem, points, jnp.arange(6), study=studies.Study(chunk=32, parts=f, shard=(i, 3))
        ).to_pandas()
        assert set(part["run"] // 32 % 3) == {i}
        folders.append(f)
    table, manifest = studies.merge_parts(folders)
    pd.testing.assert_frame_equal(table, whole)
    with pytest.raises(studies.PartsError, match=r"3 of 10 chunks are missing \(chunks 1, 4, 7\)"):
        studies.merge_parts(folders[::2])
    twice = tmp_path / "again"
    studies.sweep(
        problem, points, jnp.arange(6), study=studies.Study(chunk=32, parts=twice, shard=(1, 3))
    )
    with pytest.raises(studies.PartsError, match="found twice"):
        studies.merge_parts([*folders, twice])
    other = tmp_path / "other"
    studies.sweep(
        problem, points, jnp.arange(5), study=studies.Study(chunk=32, parts=other, shard=(0, 3))
    )
    with pytest.raises(studies.PartsError, match="different sweep"):
        studies.merge_parts([folders[0], other])


def test_altered_foreign_or_truncated_parts_are_recomputed_or_refused(
    tmp_path, problem, points, whole
):
    """Issue 44: a part copied over another, a part of another sweep with the same chunk
    index, a part whose values were edited, a truncated part: `resume` recomputes each
    (the table equals the uninterrupted one, no run counted twice) and `merge_parts`
    refuses each, naming it; a manifest that is damaged or lacks a key is one error
    naming the file."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    folder = tmp_path / "parts"
    studies.sweep(problem, points, jnp.arange(6), study=studies.Study(chunk=32, parts=folder))
    other = tmp_path / "other"
    studies.sweep(problem, points, jnp.arange(1, 7), study=studies.Study(chunk=32, parts=other))
    saved = {c: (folder / part_name(c)).read_bytes() for c in range(10)}

    def copied_over():
        (folder / part_name(2)).write_bytes(saved[1])

    def foreign():
        (folder / part_name(4)).write_bytes((other / part_name(4)).read_bytes())

    def edited():
        table = pq.read_table(folder / part_name(6))
        error = pa.array(np.zeros(table.num_rows))
        table = table.set_column(table.column_names.index("error"), "error", error)
        pq.write_table(table, folder / part_name(6))

    def truncated():
        (folder / part_name(8)).write_bytes(saved[8][: len(saved[8]) // 2])

    for alter, chunk in ((copied_over, 2), (foreign, 4), (edited, 6), (truncated, 8)):
        alter()
        with pytest.raises(studies.PartsError, match=part_name(chunk)):
            studies.merge_parts([folder])
        lines = []
        resumed = studies.sweep(
            problem,
            points,
            jnp.arange(6),
            study=studies.Study(chunk=32, parts=folder, resume=True, log=lines.append),
        ).to_pandas()
        pd.testing.assert_frame_equal(resumed, whole)
        assert any(part_name(chunk) in ln and "recomputed" in ln for ln in lines), lines
        table, _ = studies.merge_parts([folder])
        pd.testing.assert_frame_equal(table, whole)
    manifest = folder / "manifest.json"
    good = manifest.read_text()
    for text, says in (
        (good[: len(good) // 2], "not valid JSON"),
        (json.dumps({k: v for k, v in json.loads(good).items() if k != "identity"}), "'identity'"),
        (json.dumps({**json.loads(good), "done": ["x"]}), "'done'"),
    ):
        manifest.write_text(text)
        for call in (
            lambda: studies.merge_parts([folder]),
            lambda: studies.sweep(
                problem,
                points,
                jnp.arange(6),
                study=studies.Study(chunk=32, parts=folder, resume=True),
            ),
        ):
            with pytest.raises(studies.PartsError, match=f"manifest.json: .*{says}"):
                call()


def test_memory_estimate_refuses_a_chunk_too_large(problem, points):
    """The memory of one chunk from XLA's analysis; a limit below it is refused before any
    run, naming a chunk that fits."""
    lines = []
    with pytest.raises(ValueError, match=r"use a chunk of at most \d+ runs"):
        studies.sweep(
            problem,
            points,
            jnp.arange(6),
            study=studies.Study(chunk=32, max_memory=100, log=lines.append),
        )
    assert lines and lines[0].startswith("memory per chunk of 32 runs:")


def test_command_shards_merge_and_force(tmp_path, capsys):
    """`visjax sweep --shard i/N` into one --out, `visjax merge`, against the whole sweep;
    a finished sweep is not replaced without --force."""
    base = ["sweep", "point_depth", "--set", "planar", "--duration", "0.05", "--seeds", "2"]
    base += ["--grid", "alpha=300:3000:6", "--chunk", "4", "--noise", "0.5", "--quiet"]
    whole = tmp_path / "whole"
    assert main([*base, "--out", str(whole)]) == 0
    expected = pd.read_parquet(whole / "planar" / "runs.parquet")
    assert len(expected) == 12 and (whole / "planar" / "parts" / "manifest.json").exists()
    shards = tmp_path / "shards"
    for i in range(2):
        assert main([*base, "--shard", f"{i}/2", "--out", str(shards)]) == 0
    assert (shards / "planar" / "parts-1-of-2" / "manifest.json").exists()
    merged = tmp_path / "merged"
    assert main(["merge", str(shards), "--out", str(merged)]) == 0
    pd.testing.assert_frame_equal(pd.read_parquet(merged / "runs.parquet"), expected)
    summary = json.loads((merged / "summary.json").read_text())
    assert summary["kind"] == "merge" and summary["runs"] == 12
    capsys.readouterr()
    assert main([*base, "--out", str(whole)]) == 1
    assert "--force" in capsys.readouterr().err
    assert main([*base, "--out", str(whole), "--force"]) == 0


@pytest.mark.slow  # three subprocesses (about 30 s)
def test_sigterm_then_resume_gives_the_same_table(tmp_path):
    """A sweep killed by SIGTERM after some chunks (a subprocess) says how many runs are
    saved and how to resume; resumed, its table equals an uninterrupted sweep's."""
    out = tmp_path / "out"
    argv = [sys.executable, "-m", "visjax.cli", "--import", "tests.studies.slow_toy", "sweep"]
    argv += ["slow-toy", "--grid", "gain=0.1:10:24", "--seeds", "2", "--chunk", "4"]
    argv += ["--noise", "0.1", "--quiet", "--out", str(out)]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(argv, cwd=ROOT, env=env, stderr=subprocess.PIPE, text=True)
    manifest = out / "parts" / "manifest.json"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if manifest.exists() and len(json.loads(manifest.read_text())["done"]) >= 2:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    done = len(json.loads(manifest.read_text())["done"])
    assert 2 <= done < 12, done
    assert f"{done * 4} of 48 runs are saved" in err and "--resume" in err
    assert not (out / "runs.parquet").exists()
    resumed = subprocess.run([*argv, "--resume"], cwd=ROOT, env=env, capture_output=True)
    assert resumed.returncode == 0, resumed.stderr
    fresh = tmp_path / "fresh"
    argv[argv.index(str(out))] = str(fresh)
    assert subprocess.run(argv, cwd=ROOT, env=env, capture_output=True).returncode == 0
    pd.testing.assert_frame_equal(
        pd.read_parquet(out / "runs.parquet"), pd.read_parquet(fresh / "runs.parquet")
    )


@pytest.mark.slow  # a local Ray instance of 2 CPUs (about 20 s)
def test_ray_executor_equals_one_process_and_survives_a_killed_worker(tmp_path):
    """The chunks as Ray tasks on a local instance of 2 CPUs: the table equals the
    single-process sweep; a worker killed (SIGKILL) while it computes a chunk is retried,
    and the table is still equal."""
    import threading

    pytest.importorskip("ray")
    from tests.studies.slow_toy import slow_toy

    problem = slow_toy()
    points = {"gain": np.geomspace(0.1, 10.0, 24)}
    expected = studies.sweep(
        problem, points, jnp.arange(2), study=studies.Study(chunk=4)
    ).to_pandas()
    executor = studies.RayExecutor(num_cpus=2, max_retries=3)
    try:
        parts = tmp_path / "parts"
        killed = []

        def kill_a_worker():  # once a chunk is written, SIGKILL a worker that computes one
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline and not killed:
                manifest = parts / "manifest.json"
                if manifest.exists() and json.loads(manifest.read_text())["done"]:
                    found = _processes("ray::_run_task")
                    if found:
                        os.kill(found[0], signal.SIGKILL)
                        killed.append(found[0])
                time.sleep(0.02)

        killer = threading.Thread(target=kill_a_worker, daemon=True)
        killer.start()
        table = studies.sweep(
            problem,
            points,
            jnp.arange(2),
            study=studies.Study(chunk=4, executor=executor, parts=parts),
        ).to_pandas()
        killer.join(timeout=5)
        assert killed, "no worker was killed: the test did not test the retry"
        pd.testing.assert_frame_equal(table, expected)
        again = studies.sweep(
            problem, points, jnp.arange(2), study=studies.Study(chunk=4, executor=executor)
        ).to_pandas()
        pd.testing.assert_frame_equal(again, expected)
    finally:
        executor.shutdown()


def _processes(text: str) -> list[int]:
    """The processes whose command line holds `text` (Ray names a busy worker by its task)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
            except OSError:
                continue
            if text in cmdline and entry.name != str(os.getpid()):
                found.append(int(entry.name))
    return found
