"""Methods added to a registered problem (`studies.add_method`): studied like the problem's
own (evaluate, compare, sweep, tune, `jit`/`vmap`/`grad`), selected (`methods=`,
`--methods`), their parameters owned (a grid axis no selected method uses refused), and
every clash an error naming both sides. A toy problem (a weighted mean of noisy samples of
2) keeps the compiles small; the velocity problem's worked example is
`tests/test_extending.py`'s."""

import sys
import textwrap

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

NAME = "mean-toy"


class Estimate(eqx.Module):
    value: jax.Array
    result: RESULTS


class Mean(studies.AbstractProblem):
    """Samples of 2 with Gaussian noise; `estimator`: a weighted mean (`gain`, the weights'
    decay); `first`: the first sample (no parameter)."""

    methods = ("estimator", "first")
    metric = "error"
    own_parameters = {"first": ()}
    data_parameters = ("noise_px",)

    samples: jax.Array
    noise_px: jax.Array

    def parameters(self):
        return {
            "gain": studies.Parameter(1.0, "-", True, "the weights' decay"),
            "noise_px": studies.noise_parameter(self.noise_px),
        }

    def inputs(self, key):
        return self.samples + self.noise_px * jax.random.normal(key, self.samples.shape)

    def solve(self, method, params, inputs, *, outputs=False):
        if method == "first":
            return Estimate(inputs[0], RESULTS.successful)
        i = jnp.arange(inputs.shape[0], dtype=inputs.dtype)
        w = jnp.exp(-params["gain"] * i / inputs.shape[0])
        return Estimate(jnp.sum(w * inputs) / jnp.sum(w), RESULTS.successful)

    def metrics(self, method, solution):
        return {"error": jnp.abs(solution.value - 2.0)}


def mean_toy(*, noise_px: float = 0.3):
    return Mean(samples=jnp.full(16, 2.0), noise_px=jnp.asarray(noise_px, float))


def trimmed(problem, params, inputs):
    """The mean of the samples within `width` of their median, smoothly weighted."""
    w = jax.nn.sigmoid((params["width"] - jnp.abs(inputs - jnp.median(inputs))) / 0.05)
    return Estimate(jnp.sum(w * inputs) / jnp.sum(w), RESULTS.successful)


WIDTH = studies.Parameter(0.5, "-", True, "the half-width kept around the median")


@pytest.fixture
def toy():
    studies.register_problem(NAME, mean_toy, replace=True)
    studies.add_method(NAME, "trimmed", trimmed, {"width": WIDTH}, like="estimator")
    yield
    _registry._ADDED.pop(NAME, None)
    _registry._REGISTRY.pop(NAME, None)


def test_an_added_method_is_studied_like_the_problems_own(toy):
    p = studies.problem(NAME)
    assert isinstance(p, studies.WithMethods) and p.methods == ("estimator", "first", "trimmed")
    assert p.method_parameters("trimmed") == ("width",) and p.method_parameters("first") == ()
    assert set(p.parameters()) == {"gain", "noise_px", "width"}
    keys = np.arange(3)
    ev = studies.evaluate(p, {"width": 0.4}, keys, method="trimmed")
    for i, key in enumerate(keys):  # an independent computation of the same draws
        x = np.asarray(mean_toy().inputs(jax.random.key(int(key))))
        w = 1 / (1 + np.exp(-(0.4 - np.abs(x - np.median(x))) / 0.05))
        np.testing.assert_allclose(ev.metrics["error"][i], abs(w @ x / w.sum() - 2), rtol=1e-12)
    # the problem's own methods are unchanged by the added one
    own = studies.evaluate(mean_toy(), None, keys, method="estimator").metrics["error"]
    np.testing.assert_array_equal(studies.evaluate(p, None, keys).metrics["error"], own)
    # jit, vmap and grad through the added method's parameter and the data parameter
    loss = jax.jit(
        lambda w, s: studies.evaluate(p, {"width": w, "noise_px": s}, keys, method="trimmed")
        .metrics["error"].mean()
    )  # fmt: skip
    d, grad = 1e-5, jax.grad(loss, argnums=(0, 1))(0.4, 0.3)
    for i, step in enumerate(((d, 0.0), (0.0, d))):  # central differences, each argument
        fd = (loss(0.4 + step[0], 0.3 + step[1]) - loss(0.4 - step[0], 0.3 - step[1])) / (2 * d)
        np.testing.assert_allclose(grad[i], fd, rtol=1e-5)
    batch = jax.vmap(loss, in_axes=(0, None))(jnp.array([0.3, 0.4]), 0.3)
    np.testing.assert_allclose(batch[1], loss(0.4, 0.3), rtol=1e-12)
    # compare: the selected methods only, in their order, on the same draws
    records = studies.compare(p, keys, methods=["trimmed", "estimator"])
    assert [r["method"] for r in records][:2] == ["trimmed", "estimator"] and len(records) == 6
    est = [r["error"] for r in records if r["method"] == "estimator"]
    np.testing.assert_allclose(est, own, rtol=1e-12)
    assert records.medians_table("error").shape[0] == 2
    # a sweep of the added method over its own parameter; the estimator's axis refused
    found = studies.sweep_then_hold_out(p, "width=0.1/1", keys, keys + 3, method="trimmed")
    assert len(found.sweep) == 6 and set(found.best["params"]) == {"width"}
    with pytest.raises(studies.Refused, match=r"'gain' is used by \['estimator'\], not by"):
        studies.sweep_then_hold_out(p, "gain=0.1/1", keys, keys + 3, method="trimmed")
    fn = studies.FunctionProblem(lambda params, key: Estimate(0.0, RESULTS.successful), dict)
    with pytest.raises(ValueError, match="noise levels need `noise_px` among its data"):
        studies.compare(fn, keys, noise_levels=[0.1])
    with pytest.raises(ValueError, match=r"unknown method 'trimed' \(did you mean 'trimmed'\?\)"):
        p.check_method("trimed")


def test_every_clash_is_an_error_naming_both(toy, monkeypatch):
    with pytest.raises(ValueError, match="added by .*trimmed already"):
        studies.add_method(NAME, "trimmed", trimmed, like="estimator")
    with pytest.raises(ValueError, match="exactly one of `like`"):
        studies.add_method(NAME, "x", trimmed)
    with pytest.raises(ValueError, match="unknown problem 'nope'"):
        studies.add_method("nope", "x", trimmed, like="estimator")
    studies.add_method(NAME, "first", trimmed, like="estimator")  # the problem's own name
    with pytest.raises(ValueError, match="has a method 'first' of its own.*needs another name"):
        studies.problem(NAME)
    studies.remove_method(NAME, "first")
    studies.add_method(NAME, "wide", trimmed, {"gain": WIDTH}, like="estimator")
    with pytest.raises(ValueError, match=r"parameter\(s\) \['gain'\] are the problem's own"):
        studies.problem(NAME)
    studies.remove_method(NAME, "wide")
    studies.add_method(NAME, "odd", trimmed, like="nope")
    with pytest.raises(ValueError, match="like='nope' is not one of the problem's methods"):
        studies.problem(NAME)
    studies.remove_method(NAME, "odd")
    assert studies.problem(NAME).methods[-1] == "trimmed"

    # an installed plugin reusing a registered problem's name: an error naming both
    class EntryPoint:
        name, value = NAME, "their_package.problems:build"

    import importlib.metadata

    monkeypatch.setattr(importlib.metadata, "entry_points", lambda group: [EntryPoint()])
    for state, fresh in (("_LOADED", False), ("_PENDING", {}), ("_BROKEN", {})):
        monkeypatch.setattr(_registry, state, fresh)
    with pytest.raises(ValueError, match=r"both .*mean_toy \(registered\) and the installed "):
        studies.registered(NAME)


def test_a_method_from_an_imported_module_in_the_current_folder(toy, tmp_path, monkeypatch, capsys):
    """`visjax --import my_method` finds `my_method.py` in the current folder (not on
    `sys.path`); the method is run, compared and swept with `--methods`; a grid axis of an
    unselected method and an unknown `--method` are refused (exit 2, one line)."""
    _registry._ADDED.pop(NAME, None)  # added by the user's module this time
    (tmp_path / "my_method.py").write_text(
        textwrap.dedent(
            f"""
            from visjax import studies
            from tests.studies.test_methods import WIDTH, trimmed

            studies.add_method({NAME!r}, "trimmed", trimmed, {{"width": WIDTH}}, like="estimator")
            """
        )
    )
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])
    monkeypatch.delitem(sys.modules, "my_method", raising=False)
    cmd = ["--import", "my_method"]
    out = tmp_path / "compare"
    argv = [*cmd, "compare", NAME, "--methods", "trimmed,first", "--seeds", "2", "--noise", "0.3"]
    tables = ["--table", "md", "--table", "tex"]
    assert main([*argv, *tables, "--quiet", "--out", str(out)]) == 0
    records = pd.read_parquet(out / "records.parquet")
    assert list(records["method"]) == ["trimmed", "first"] * 2
    summary = read_summary(out / "summary.json")
    assert summary["settings"]["methods"] == ["trimmed", "first"]
    # the statistics: each method's median with its interval, the pair's paired test
    stats = summary["statistics"]
    err = records.groupby("method")["error"].median()
    for m in ("trimmed", "first"):
        x = stats["methods"][m]
        assert x["median"] == pytest.approx(err[m]) and x["low"] <= x["median"] <= x["high"]
    (pair,) = stats["pairs"]
    assert (pair["a"], pair["b"], pair["n"]) == ("trimmed", "first", 2)
    assert "| trimmed - first |" in (out / "comparison.md").read_text()
    assert (out / "comparison.tex").read_text().count(r"\begin{tabular}") == 2
    out = tmp_path / "sweep"
    argv = [*cmd, "sweep", NAME, "--methods", "trimmed", "--grid", "width=0.2/0.8", "--seeds", "2"]
    assert main([*argv, "--quiet", "--out", str(out)]) == 0
    summary = read_summary(out / "summary.json")
    assert summary["method"] == "trimmed" and set(summary["best"]["params"]) == {"width"}
    # accuracy against noise: the comparison at each level, one figure
    out = tmp_path / "noise"
    argv = [*cmd, "compare", NAME, "--noise", "0,0.3,1", "--seeds", "3", "--table", "md"]
    assert main([*argv, "--quiet", "--out", str(out)]) == 0
    stats = read_summary(out / "summary.json")["statistics"]
    assert stats["noise_levels"] == [0.0, 0.3, 1.0] and len(stats["by_noise"]) == 3
    medians = [s["methods"]["estimator"]["median"] for s in stats["by_noise"]]
    assert medians[0] < 1e-12 < medians[1] < medians[2]  # exact without noise, then growing
    records = pd.read_parquet(out / "records.parquet")
    assert sorted(set(records["noise_px"])) == [0.0, 0.3, 1.0] and len(records) == 3 * 3 * 3
    assert (out / "noise.png").stat().st_size > 10_000
    assert "| noise_px | method |" in (out / "comparison.md").read_text()
    capsys.readouterr()
    for argv, said in (
        ([*cmd, "sweep", NAME, "--methods", "trimmed", "--grid", "gain=0.2/0.8"], "'gain' is used"),
        ([*cmd, "run", NAME, "--method", "trimed"], "did you mean 'trimmed'"),
        ([*cmd, "compare", NAME, "--methods", "first,nope"], "unknown method 'nope'"),
    ):
        with pytest.raises(SystemExit) as e:
            main([*argv, "--quiet"])
        err = capsys.readouterr().err
        assert e.value.code == 2 and said in err and err.count("\n") == 1, err
