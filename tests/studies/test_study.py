"""Version 4's study API: one signature per study (`study=Study(...)`, `keys` always), a
plain function as a `FunctionProblem`, one result protocol (`.to_pandas()`), `plan`,
`sweep_then_hold_out` / `sweep_then_tune`, the version-3 forms still working with a
`FutureWarning` and giving the same numbers, and the one signal handler."""

import os
import signal

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest

from tests.studies.test_problem import Estimate, by_hand, toy
from visjax import studies
from visjax._results import RESULTS


def weighted(params, key):
    """The toy problem's estimator as a plain function of (params, key)."""
    x = 2.0 + 0.1 * jax.random.normal(key, (32,))
    w = jnp.exp(-params["gain"] * jnp.arange(32.0) / 32)
    return Estimate(jnp.sum(w * x) / jnp.sum(w), RESULTS.successful, jnp.asarray(-1))


def error(sol):
    return {"error": jnp.abs(sol.value - 2.0)}


FN = studies.FunctionProblem(weighted, error, metric="error")


def test_study_checks_its_fields():
    assert studies.Study().chunk == 64
    for bad, match in [
        ({"chunk": 0}, "chunk"),
        ({"chunk": True}, "chunk"),
        ({"shard": (3, 2)}, "shard"),
        ({"resume": True}, "resume"),
        ({"runs": [1], "shard": (0, 2)}, "runs"),
        ({"repeats": 0}, "repeats"),
        ({"max_seconds": -1.0}, "max_seconds"),
    ]:
        with pytest.raises(ValueError, match=match):
            studies.Study(**bad)


def test_a_function_problem_agrees_with_the_problem_in_every_study():
    p, keys = toy(), np.arange(3)
    expected = [by_hand(p, 2.0, (0.0, 0.0), s) for s in range(3)]
    ev = studies.evaluate(FN, {"gain": 2.0}, keys)
    np.testing.assert_allclose(ev.metrics["error"], expected, rtol=1e-12)
    frame = ev.to_pandas()
    assert list(frame.columns) == ["key", "result", "failed_sample", "error"]
    assert list(frame["result"]) == ["successful"] * 3

    points = {"gain": np.array([0.5, 2.0])}
    table = studies.sweep(FN, points, keys, study=studies.Study(chunk=4))
    mine = studies.sweep(p, points, keys, study=studies.Study(chunk=4))
    assert isinstance(table, studies.SweepResult) and isinstance(table.to_pandas(), pd.DataFrame)
    np.testing.assert_allclose(table["error"], mine["error"], rtol=1e-12)
    assert len(table) == 6 and table.n_points == 2 and table.n_seeds == 3

    records = studies.compare(FN, keys[:2], params={"gain": 2.0}, study=studies.Study(repeats=1))
    assert isinstance(records, studies.Comparison) and len(records) == 2
    np.testing.assert_allclose(records.to_pandas()["error"], expected[:2], rtol=1e-12)
    (row,) = records.medians("error")  # one method: its median over the keys
    assert row["method"] == "function" and row["failed"] == 0 and "std_key" not in row
    assert row["metric"] == pytest.approx(float(np.median(expected[:2])), rel=1e-12)

    tuned = studies.tune(FN, {"gain": 1.0}, keys, steps=5)
    assert tuned.loss <= tuned.loss0 and list(tuned.to_pandas()["step"]) == list(range(6))
    again = studies.tune(p, {"gain": 1.0}, keys, steps=5)
    np.testing.assert_allclose(tuned.loss, again.loss, rtol=1e-10)


def test_version3_forms_warn_and_give_the_same_numbers():
    p, keys = toy(), jnp.arange(2)
    points = {"gain": np.array([0.5, 2.0])}
    new = studies.sweep(p, points, keys, study=studies.Study(chunk=4)).to_pandas()
    with pytest.warns(FutureWarning, match="Study"):
        old = studies.sweep(p, points, keys, chunk=4)
    pd.testing.assert_frame_equal(old.to_pandas(), new)
    assert old.equals(new) and not old.equals(new.iloc[:-1])  # a SweepResult or a frame
    with pytest.warns(FutureWarning, match="FunctionProblem"):
        fn = studies.sweep(weighted, points, keys, metrics=error)
    np.testing.assert_allclose(fn["error"], new["error"], rtol=1e-12)
    with pytest.warns(FutureWarning, match="compare"):
        records = studies.compare(p, seeds=2, first_seed=1, repeats=1)
    now = studies.compare(p, np.arange(1, 3), study=studies.Study(repeats=1))
    assert [r["seed"] for r in records] == [r["seed"] for r in now] == [1, 1, 2, 2]
    assert [r["error"] for r in records] == [r["error"] for r in now]
    with pytest.warns(FutureWarning, match="compare"):  # version 3's defaults: seeds 0-3
        default = studies.compare(p, first_seed=1, study=studies.Study(repeats=1))
    assert sorted({r["seed"] for r in default}) == [1, 2, 3, 4]
    with pytest.warns(FutureWarning, match="FunctionProblem"):
        old_tune = studies.tune(weighted, {"gain": 1.0}, lambda s: error(s)["error"], keys, steps=3)
    new_tune = studies.tune(FN, {"gain": 1.0}, keys, steps=3)
    assert old_tune.loss == pytest.approx(new_tune.loss, rel=1e-12)
    with pytest.raises(ValueError, match="only"):
        studies.sweep(p, points, keys, study=studies.Study(), chunk=4)
    with pytest.raises(TypeError, match="unexpected"):
        studies.sweep(p, points, keys, chunks=4)


def test_plan_counts_runs_and_memory_before_any_compile():
    p = toy()
    points = {"gain": np.array([0.5, 1.0, 2.0])}
    found = studies.plan(p, points, 4, studies.Study(chunk=8), kind="sweep")
    assert found.runs == 3 * 4 + 2 * 4  # the grid, then the best and the defaults held out
    per_run = 32 * np.dtype(p.samples.dtype).itemsize
    assert found.memory == 8 * per_run + 12 * (6 + 1) * 8  # a chunk's inputs, the table
    assert studies.plan(p, points, 4, kind="tune", steps=10).runs == 12 + 40 + 12
    assert studies.plan(p, None, 4, kind="compare").runs == 8
    found.check("toy")  # fits
    with pytest.raises(studies.Refused, match="MiB"):
        studies.Plan("sweep", 10, 2**40, "inputs", 2**30).check("toy")
    with pytest.raises(studies.Refused, match="runs"):
        studies.Plan("sweep", studies.MAX_RUNS + 1, 0, "", None).check("toy")
    with pytest.raises(studies.Refused, match="did you mean 'gain'"):
        studies.check_grid(p, "gian=1/2", "toy")
    assert studies.grid_size("gain=0.1:10:3,offset=1/2") == 6


def test_sweep_then_hold_out_and_tune_measure_on_other_keys():
    p = toy()
    points = {"gain": np.array([0.5, 4.0])}
    keys, held = np.arange(2), np.arange(2, 4)
    found = studies.sweep_then_hold_out(p, points, keys, held, study=studies.Study(chunk=4))
    assert set(found.held) == {"best", "paper"}
    by_point = found.sweep.to_pandas().groupby("point")["error"].mean()
    assert found.best["params"]["gain"] == [0.5, 4.0][int(by_point.idxmin())]
    gain = found.best["params"]["gain"]
    expected = np.mean([by_hand(p, gain, (0.0, 0.0), s) for s in (2, 3)])
    assert found.held["best"]["metric"] == pytest.approx(expected, rel=1e-12)
    assert list(found.to_pandas()["point"]) == ["best", "paper"]
    tuned = studies.sweep_then_tune(p, points, keys, held, steps=3)
    assert set(tuned.held) == {"tuned", "sweep best", "paper"}
    assert tuned.tuned.loss <= tuned.tuned.loss0
    with pytest.raises(ValueError, match="shard"):
        studies.sweep_then_tune(p, points, keys, held, study=studies.Study(shard=(0, 2)))


def test_one_handler_asks_a_listening_study_to_stop_then_interrupts():
    with studies.handling_signals():
        with studies.interruptible() as stop:
            assert not stop()
            os.kill(os.getpid(), signal.SIGTERM)
            assert stop()  # the first signal: a clean stop after the chunk in flight
            with pytest.raises(studies.Interrupted):
                os.kill(os.getpid(), signal.SIGTERM)  # the second: at once
        with pytest.raises(studies.Interrupted) as e:
            os.kill(os.getpid(), signal.SIGINT)  # no study listening: at once
        assert e.value.name == "SIGINT"
    p = toy()
    asked = iter([False, True])
    study = studies.Study(chunk=1, stop=lambda: next(asked))
    with pytest.raises(KeyboardInterrupt):
        studies.sweep(p, {"gain": np.array([0.5, 1.0, 2.0])}, np.arange(1), study=study)


def test_a_runs_outcome_names_why_it_is_not_a_success():
    """`Verdict.outcome`, what `visjax run` reports and exits 1 on: a failed run's code and
    sample, a data file with too many frames missing, an estimate no better than the
    trivial one; otherwise `successful` (no reason)."""
    from visjax.studies import Verdict

    judged = {
        "metric": "rms", "ratio_to_trivial": 12.0, "trivial_estimate": "zero velocity",
        "trivial": 0.1, "threshold": 1.0, "flag": "worse_than_trivial",
    }  # fmt: skip
    ok = Verdict("estimator", "successful", -1, {}, True, dict(judged, flag="ok"))
    assert ok.outcome() == ("successful", None)
    failed = Verdict("estimator", "diverged", 41, {}, False, None)
    assert failed.outcome() == ("diverged", "the run failed: diverged at sample 41")
    dropped = {"over": True, "result": "too_many_dropped_frames", "line": "75 of 100 missing"}
    code, why = ok.outcome(dropped)
    assert code == "too_many_dropped_frames" and why.endswith("75 of 100 missing")
    assert failed.outcome(dropped)[0] == "diverged"  # the run's own failure first
    code, why = Verdict("estimator", "successful", -1, {}, True, judged).outcome()
    assert code == "worse_than_trivial" and "12 times that of zero velocity" in why


def test_available_memory_is_the_accelerators_own_on_a_gpu():
    """Issue 47: a chunk on a GPU lives in the GPU's memory: `max_memory="available"` reads
    the device's `memory_stats()` there, the host's memory on a CPU."""
    from visjax.studies._sweep import available_memory

    class FakeGPU:
        platform = "gpu"

        def memory_stats(self):
            return {"bytes_limit": 80 * 2**30, "bytes_in_use": 30 * 2**30}

    class Silent(FakeGPU):
        def memory_stats(self):
            return None

    assert available_memory(FakeGPU()) == pytest.approx(0.8 * 50 * 2**30)
    host = available_memory(Silent())  # no statistics: the host's, as on a CPU
    assert host == pytest.approx(available_memory(jax.devices("cpu")[0]), rel=0.2)
