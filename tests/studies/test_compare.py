"""`studies.compare`: every method sees the same inputs per seed; records carry the result
code's name, timings and the scores."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest

from tests.helpers import euclidean_scene_file
from visjax._results import RESULTS
from visjax.studies import compare

# the version-3 functional form (`compare(methods, inputs, score, seeds=...)`), kept with a
# FutureWarning: these tests hold it to its old behaviour
pytestmark = pytest.mark.filterwarnings("ignore::FutureWarning")


class Out(eqx.Module):
    value: jax.Array
    result: RESULTS


def mean(x):
    return Out(jnp.mean(x), RESULTS.successful)


def flagged_max(x):
    bad = jnp.max(x) > 1.5
    return Out(jnp.max(x), RESULTS.where(bad, RESULTS.diverged, RESULTS.successful))


def inputs(key):
    x = jax.random.normal(key, (50,))
    return x, jnp.mean(x)


def score(name, sol, truth):
    return {"error": float(sol.value - truth)}


def test_records_same_inputs_and_result_names():
    records = compare(
        {"mean": mean, "max": flagged_max}, inputs, score, seeds=3, updates={"mean": 50}
    )
    table = pd.DataFrame(records)
    assert len(table) == 6 and set(table["seed"]) == {0, 1, 2}
    assert set(table.columns) >= {
        "method",
        "seed",
        "result",
        "latency_s_per_sample",
        "total_s",
        "compile_s",
        "error",
    }
    # the mean of the same inputs as the truth: zero error on every seed
    np.testing.assert_allclose(table[table.method == "mean"]["error"], 0.0, atol=1e-15)
    maxima = [float(jnp.max(inputs(jax.random.key(s))[0])) for s in range(3)]
    expected = ["diverged" if m > 1.5 else "successful" for m in maxima]
    assert list(table[table.method == "max"]["result"]) == expected
    assert "diverged" in expected  # the seeds include a flagged run
    mean_rows = table[table.method == "mean"]
    np.testing.assert_allclose(mean_rows.latency_s_per_sample * 50, mean_rows.total_s)
    assert table.compile_s.notna().sum() == 2  # first seed only
    # seeds from `first_seed`: the same records as those seeds in the full run
    later = pd.DataFrame(
        compare({"max": flagged_max}, inputs, score, seeds=2, first_seed=1, repeats=1)
    )
    assert list(later["seed"]) == [1, 2]
    assert list(later["result"]) == expected[1:]
    assert later.compile_s.notna().sum() == 1


def test_bad_arguments():
    with pytest.raises(ValueError, match="seeds"):
        compare({"mean": mean}, inputs, score, seeds=0)
    with pytest.raises(ValueError, match="updates"):
        compare({"mean": mean}, inputs, score, updates={"other": 3})
    with pytest.raises(ValueError, match="first_seed"):
        compare({"mean": mean}, inputs, score, first_seed=-1)


@pytest.mark.slow
def test_velocity_and_euclidean_problems_on_data_files(tmp_path):
    """The two other problems of `visjax compare`, from data files (noise on top of the
    file's pixels): every method succeeds and scores with the estimator's own keys."""

    from visjax.io import VelocityData
    from visjax.papers import chitrakaran, static_points_problem, velocity_problem

    path = euclidean_scene_file(tmp_path / "euclidean.npz", 2.0, 20.0)
    v = chitrakaran.section6_scenario(0.3, 1000.0)
    vpath = tmp_path / "velocity.npz"
    VelocityData(
        t=np.asarray(v.ts),
        pixels=np.asarray(v.pixels),
        A=np.asarray(v.A),
        R_star=np.asarray(v.R_star),
        s1=np.asarray(v.s[0]),
        known_length=np.array([0.0, 1.0, float(np.linalg.norm(v.s[1] - v.s[0]))]),
        velocity=np.asarray(v.velocity),
    ).save(vpath)
    for factory, file, key in (
        (static_points_problem, path, "error"),
        (velocity_problem, vpath, "rms"),
    ):
        p = factory(data=file, noise_px=0.1)
        records = compare(p, seeds=1, repeats=1)
        assert [r["method"] for r in records] == ["estimator", "batch", "batch_window", "ekf"]
        assert all(r["result"] == "successful" for r in records), records
        assert all(np.all(np.isfinite(r[key])) for r in records)
        assert p.settings()["source"] == str(file)
