"""Tuning every method with the same budget (`studies.tune_methods`, `compare_tuned`, the
command line's `compare --tune`) and structural parameters (`structural_parameters`: a
window's length, set per compiled program). A toy problem with a known optimum keeps
the compiles small: the methods' metric is the distance of a gain from 3 (in decades)
and of a structural size from 8."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest

from visjax import RESULTS, studies
from visjax.cli import main
from visjax.io import read_summary
from visjax.studies import _registry

NAME = "search-toy"


class Value(eqx.Module):
    value: jax.Array
    result: RESULTS


class Toy(studies.AbstractProblem):
    """`gain`: the metric is |log10(gain / 3)| plus the draw's noise; `window`: the metric
    is |size - 8| / 8, `size` a structural parameter (an array's length); `fixed`: no
    parameter; `scaled`: `gain` with `offset`, a parameter not searched (`tunable=False`)."""

    methods = ("gain", "window", "fixed", "scaled")
    metric = "error"
    data_parameters = ("noise_px",)
    structural_parameters = ("size",)
    own_parameters = {
        "gain": ("gain",), "window": ("size",), "fixed": (), "scaled": ("gain", "offset")
    }  # fmt: skip

    noise_px: jax.Array
    size: int = eqx.field(static=True, default=4)

    def parameters(self):
        return {
            "gain": studies.Parameter(1.0, "", True, "a gain", span=(0.01, 100.0)),
            "offset": studies.Parameter(1.0, "", True, "not searched", tunable=False),
            "size": studies.Parameter(float(self.size), "", True, "an array's length"),
            "noise_px": studies.noise_parameter(self.noise_px),
        }

    def inputs(self, key):
        return self.noise_px * jax.random.normal(key, ())

    def solve(self, method, params, inputs, *, outputs=False):
        if method in ("gain", "scaled"):
            g = params["gain"] * (params["offset"] if method == "scaled" else 1.0)
            x = jnp.abs(jnp.log10(g / 3.0))
        elif method == "window":
            x = jnp.abs(jnp.ones(self.size).sum() - 8.0) / 8.0  # the size is the array's
        else:
            x = jnp.asarray(0.5)
        value = x + inputs
        return Value(value, RESULTS.where(value < 1.5, RESULTS.successful, RESULTS.diverged))

    def metrics(self, method, solution):
        return {"error": solution.value}


@pytest.fixture(scope="module")
def toy():
    return Toy(noise_px=jnp.asarray(0.01))


def test_structural_parameters_set_the_field_and_are_never_traced_or_swept(toy):
    """`structured` replaces the static field (a whole number for an int field); a traced
    value, a fraction and a grid axis over it are refused, each saying why."""
    assert toy.structured({"size": 8.0}).size == 8 and toy.size == 4
    assert toy.structured({"gain": 2.0}) is toy  # not structural: the problem itself
    with pytest.raises(ValueError, match="whole number"):
        toy.structured({"size": 2.5})
    with pytest.raises(ValueError, match="concrete number"):
        jax.jit(lambda s: toy.structured({"size": s}).size)(8.0)
    with pytest.raises(ValueError, match="cannot be a grid axis"):
        toy.check_axes(["size"], ["window"])
    # evaluated at a size: compiled for it (the metric is exact: |8 - 8| / 8 = 0)
    ev = studies.evaluate(toy.at({"noise_px": 0.0}), {"size": 8}, np.arange(2), method="window")
    np.testing.assert_allclose(ev.metrics["error"], 0.0)
    assert toy.method_parameters("window") == ("size",)
    assert studies.searched_parameters(toy, "scaled") == {"gain": (0.01, 100.0)}
    assert studies.searched_parameters(toy, "window") == {"size": (0.4, 40.0)}


def test_every_method_gets_the_same_budget_and_finds_the_optimum(toy):
    """Each method with something to search spends exactly `budget` evaluations, the first
    at the defaults; the best point's training score is never worse than the defaults';
    the log-uniform search finds the gain's optimum (3) to a tenth of a decade and the
    structural size's (8) exactly on its grid of ratios sqrt 2."""
    tuning = studies.tune_methods(toy, np.arange(10, 14), budget=32, study=studies.Study())
    assert [tuning[m].evaluations for m in toy.methods] == [32, 32, 1, 32]
    for t in tuning.values():
        assert t.history[0] == {"evaluation": 0, **t.defaults, "failed": 0, "median": t.median0}
        assert (t.failed, t.median) <= (t.failed0, t.median0)
    assert abs(math.log10(tuning["gain"].params["gain"] / 3.0)) < 0.1
    assert tuning["window"].params == {"size": 8.0}
    assert tuning["fixed"].params == {} and tuning["fixed"].searched == {}
    assert set(tuning["scaled"].params) == {"gain"}  # `offset` is not tunable
    table = tuning.to_pandas()
    assert len(table) == 32 * 3 + 1 and set(table["method"]) == set(toy.methods)
    summary = tuning.as_json()
    assert summary["budget"] == 32 and summary["train_seeds"] == [10, 11, 12, 13]
    assert summary["methods"]["window"]["evaluations"] == 32


def test_a_failed_point_loses_to_one_that_succeeds(toy):
    """The score is lexicographic: failures first. At a noise that fails half the draws of
    a far gain, the tuned point is one that fails none."""
    noisy = toy.at({"noise_px": 0.5})
    tuning = studies.tune_methods(noisy, np.arange(8), methods=["gain"], budget=16)
    t = tuning["gain"]
    worst = max(h["failed"] for h in t.history)
    assert worst > 0 and t.failed == min(h["failed"] for h in t.history)


def test_compare_tuned_compares_the_tuned_points_on_other_seeds(toy):
    """`compare_tuned`: the training and the test seeds must be disjoint; each method runs
    at its own tuned point (`method_params`), so the tuned gain's test error is below its
    default's; budget 0 is the untuned comparison."""
    with pytest.raises(ValueError, match="disjoint"):
        studies.compare_tuned(toy, np.arange(4), np.arange(3, 6), budget=4)
    records, tuning = studies.compare_tuned(toy, np.arange(4), np.arange(4, 8), 16)
    untuned, none = studies.compare_tuned(toy, np.arange(4), np.arange(4, 8), 0)
    assert none is None and tuning["gain"].evaluations == 16
    tuned = pd.DataFrame(records).groupby("method")["error"].median()
    plain = pd.DataFrame(untuned).groupby("method")["error"].median()
    assert tuned["gain"] < plain["gain"] and tuned["window"] < plain["window"]
    assert tuned["fixed"] == plain["fixed"]
    with pytest.raises(ValueError, match="data parameter"):
        studies.compare(toy, np.arange(2), method_params={"gain": {"noise_px": 0.0}})


class Counted(Toy):
    """The toy whose solve counts its executions (a host callback per call)."""

    def solve(self, method, params, inputs, *, outputs=False):
        jax.debug.callback(lambda: CALLS.append(method))
        return super().solve(method, params, inputs, outputs=outputs)


CALLS: list = []


def test_compare_times_repeats_calls_per_key_and_compiles_once(toy):
    """`Study.repeats` timed calls per method and key: on the first key after the call
    that compiles, on the others the first call is one of them (3 keys, repeats 2: 3 + 2
    + 2 executions per method); `compile_s` only on the first key."""
    CALLS.clear()
    counted = Counted(noise_px=jnp.asarray(0.01))
    study = studies.Study(repeats=2)
    records = studies.compare(counted, np.arange(3), methods=["gain", "fixed"], study=study)
    assert CALLS.count("gain") == 7 and CALLS.count("fixed") == 7
    table = records.to_pandas()
    assert table["compile_s"].notna().tolist() == [True, True, False, False, False, False]
    assert (table["total_s"] > 0).all()


def test_comparison_table_is_tidy(tmp_path):
    """`Comparison.to_pandas`: a vector metric one column per component, named by the
    problem (`columns`) or `name_i`; a failed run's `None` (whole or per entry) NaN in a
    float column; the CSV holds numbers and empty cells, never a list or `None`."""
    records = studies.Comparison(
        [
            {"method": "a", "seed": 0, "result": "successful", "rms": [1.0, None],
             "err": [[1.0, 2.0]], "compile_s": 0.5, "total": 2.0},
            {"method": "a", "seed": 1, "result": "diverged", "rms": None, "err": None,
             "compile_s": None, "total": None},
        ]
    )  # fmt: skip
    records.columns = {"rms": ("rms_v_x", "rms_v_y")}
    table = records.to_pandas()
    assert list(table.columns) == [
        "method", "seed", "result", "rms_v_x", "rms_v_y", "err_0_0", "err_0_1", "compile_s",
        "total",
    ]  # fmt: skip
    assert table["rms_v_x"].tolist()[0] == 1.0 and table[["rms_v_y"]].isna().all().all()
    assert table.loc[1, ["rms_v_x", "err_0_1", "compile_s", "total"]].isna().all()
    assert all(table[c].dtype == float for c in ("rms_v_x", "err_0_0", "compile_s", "total"))
    studies.save_table(table, tmp_path, "records")
    text = (tmp_path / "records.csv").read_text()
    assert "None" not in text and "[" not in text


def test_compare_tune_on_the_command_line(toy, tmp_path):
    """`visjax compare PROBLEM --tune --budget N`: the summary's `tuning` (the tuned
    parameters, the training seeds after the test seeds) and `tuning.parquet`."""
    studies.register_problem(NAME, lambda: toy, replace=True)
    try:
        argv = ["compare", NAME, "--seeds", "3", "--tune", "--budget", "8", "--methods"]
        assert main([*argv, "gain,fixed", "--out", str(tmp_path), "--quiet"]) == 0
    finally:
        _registry._REGISTRY.pop(NAME, None)
    summary = read_summary(tmp_path / "summary.json")
    tuning = summary["tuning"]
    assert tuning["train_seeds"] == [3, 4, 5] and summary["seeds"] == 3
    assert tuning["methods"]["gain"]["evaluations"] == 8
    assert set(tuning["methods"]) == {"gain", "fixed"}
    history = pd.read_parquet(tmp_path / "tuning.parquet")
    assert len(history) == 8 + 1


def test_a_problem_with_an_added_method_searches_its_structure_as_its_own(toy):
    """With a method added (`WithMethods`), the problem's structural parameters are still
    searched as whole numbers on their grid, and the added method's parameter with the
    same budget."""

    def half(problem, params, inputs):
        return Value(jnp.abs(params["scale"] - 2.0) + inputs, RESULTS.successful)

    scale = studies.Parameter(1.0, "", True, "a scale", span=(0.5, 8.0))
    added = studies.WithMethods(toy, (studies.Method("half", half, (("scale", scale),)),))
    tuning = studies.tune_methods(added, np.arange(3), methods=["window", "half"], budget=32)
    assert tuning["window"].params == {"size": 8.0} and tuning["half"].evaluations == 32
    assert abs(tuning["half"].params["scale"] - 2.0) < 0.3
