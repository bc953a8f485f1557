"""`studies.AbstractProblem` and what takes any problem (`evaluate`, `sweep`, `compare`,
`tune`, `objective`, the registry), on a toy problem whose answers are known in closed
form: a weighted mean of noisy samples of a constant."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax import studies
from visjax._results import RESULTS, result_names

TRACES = {"n": 0}


class Estimate(eqx.Module):
    value: jax.Array
    result: RESULTS
    failed_sample: jax.Array


class Mean(studies.AbstractProblem):
    """The constant `truth` from noisy samples: `estimator` weighs sample i by
    exp(-gain i / n) and adds the sum of `offset`; `baseline` is the plain mean. A value
    above `limit` is a failure (`diverged`)."""

    methods = ("estimator", "baseline")
    metric = "error"
    label = "absolute error (-)"
    grid = "gain=0.1:10:3"

    samples: jax.Array
    truth: float = eqx.field(static=True)
    noise: float = eqx.field(static=True, default=0.1)
    limit: float = eqx.field(static=True, default=1e9)

    def parameters(self):
        return {
            "gain": studies.Parameter(1.0, "-", True, "the weights' decay"),
            "offset": studies.Parameter((0.0, 0.0), "-", False, "added to the estimate"),
        }

    def inputs(self, key):
        return self.samples + self.noise * jax.random.normal(key, self.samples.shape)

    def solve(self, method, params, inputs, *, outputs=False):
        TRACES["n"] += 1
        if method == "estimator":
            i = jnp.arange(inputs.shape[0], dtype=inputs.dtype)
            w = jnp.exp(-params["gain"] * i / inputs.shape[0])
            value = jnp.sum(w * inputs) / jnp.sum(w) + jnp.sum(params["offset"])
        else:
            value = jnp.mean(inputs)
        bad = value > self.limit
        result = RESULTS.where(bad, RESULTS.diverged, RESULTS.successful)
        return Estimate(value, result, jnp.where(bad, 0, -1))

    def metrics(self, method, solution):
        error = jnp.abs(solution.value - self.truth)
        return {"error": error, "both": jnp.stack([error, error**2])}


def toy(**kwargs):
    return Mean(**{"samples": jnp.full(32, 2.0), "truth": 2.0, **kwargs})


def by_hand(problem, gain, offset, seed):
    x = np.asarray(problem.inputs(jax.random.key(seed)))
    w = np.exp(-gain * np.arange(x.size) / x.size)
    return abs(np.sum(w * x) / np.sum(w) + np.sum(offset) - problem.truth)


def test_resolve_defaults_broadcast_and_errors():
    p = toy()
    r = p.resolve({"offset": 0.5})
    assert r["gain"].shape == () and float(r["gain"]) == 1.0
    np.testing.assert_array_equal(r["offset"], [0.5, 0.5])  # one value for every component
    with pytest.raises(ValueError, match="unknown parameter"):
        p.resolve({"gian": 1.0})
    with pytest.raises(ValueError, match="unknown method"):
        p.check_method("ekf")
    assert p.check_method(None) == "estimator"


def test_evaluate_matches_hand_computation_jit_vmap_grad():
    p = toy()
    keys = jnp.arange(3)
    ev = studies.evaluate(p, {"gain": 2.0, "offset": (0.01, 0.02)}, keys)
    expected = [by_hand(p, 2.0, (0.01, 0.02), s) for s in range(3)]
    np.testing.assert_allclose(ev.metrics["error"], expected, rtol=1e-12)
    assert ev.metrics["both"].shape == (3, 2)
    assert list(np.asarray(ev.failed_sample)) == [-1, -1, -1]

    def loss(gain):
        return jnp.mean(studies.evaluate(p, {"gain": gain}, keys).metrics["error"])

    np.testing.assert_allclose(jax.jit(loss)(2.0), loss(2.0), rtol=1e-12)
    batched = jax.vmap(loss)(jnp.array([0.5, 2.0]))
    np.testing.assert_allclose(batched[1], loss(2.0), rtol=1e-12)
    h = 1e-6
    fd = (loss(2.0 + h) - loss(2.0 - h)) / (2 * h)
    np.testing.assert_allclose(jax.grad(loss)(2.0), fd, rtol=1e-6)


def test_solution_is_one_run_of_evaluate_jit_vmap_grad():
    p = toy()
    sol = studies.solution(p, {"gain": 2.0}, 1)
    np.testing.assert_allclose(
        abs(float(sol.value) - p.truth), by_hand(p, 2.0, (0.0, 0.0), 1), rtol=1e-12
    )
    same_key = studies.solution(p, {"gain": 2.0}, jax.random.key(1))
    assert float(same_key.value) == float(sol.value)
    ev = studies.evaluate(p, {"gain": 2.0}, jnp.array([1]))
    np.testing.assert_allclose(ev.metrics["error"][0], abs(float(sol.value) - 2.0), rtol=1e-12)
    assert float(studies.solution(p, None, 1, method="baseline").value) == pytest.approx(
        float(jnp.mean(p.inputs(jax.random.key(1)))), rel=1e-12
    )

    def value(gain):
        return studies.solution(p, {"gain": gain}, 1).value

    np.testing.assert_allclose(jax.jit(value)(2.0), sol.value, rtol=1e-12)
    np.testing.assert_allclose(jax.vmap(value)(jnp.array([0.5, 2.0]))[1], sol.value, rtol=1e-12)
    h = 1e-6
    np.testing.assert_allclose(
        jax.grad(value)(2.0), (value(2.0 + h) - value(2.0 - h)) / (2 * h), rtol=1e-6
    )
    with pytest.raises(ValueError, match="`key` must be"):
        studies.solution(p, None, -1)
    with pytest.raises(ValueError, match="unknown method"):
        studies.solution(p, None, 0, method="ekf")


def test_failed_runs_flagged_never_scored():
    p = toy(limit=2.0)  # a positive offset pushes the estimate past the limit
    ev = studies.evaluate(p, {"offset": 0.5}, jnp.arange(2))
    assert result_names(ev.result) == ["diverged", "diverged"]
    assert np.isnan(ev.metrics["error"]).all() and list(np.asarray(ev.failed_sample)) == [0, 0]


def test_sweep_rows_equal_evaluate_and_values_checked():
    p = toy(limit=2.3)
    points = {"gain": np.array([0.5, 1.0, 4.0]), "offset": np.array([0.0, 0.0, 0.5])}
    table = studies.sweep(p, points, jnp.arange(2)).to_pandas()
    assert list(table.columns[:5]) == ["run", "point", "gain", "offset", "seed"]
    for _, row in table.iterrows():
        ev = studies.evaluate(p, {"gain": row["gain"], "offset": row["offset"]},
                              jnp.array([int(row["seed"])]))  # fmt: skip
        if row["offset"] > 0:
            assert row["result"] == "diverged" and np.isnan(row["error"])
        else:
            assert row["result"] == "successful"
            np.testing.assert_allclose(row["error"], ev.metrics["error"][0], rtol=1e-12)
            np.testing.assert_allclose(row["both_1"], row["error"] ** 2, rtol=1e-12)
    # the baseline ignores the parameters
    base = studies.sweep(
        p, {"gain": np.array([0.5, 4.0])}, jnp.arange(1), method="baseline"
    ).to_pandas()
    assert base["error"].nunique() == 1
    # values checked before any run: positivity, finiteness, names
    for bad, match in (
        ({"gain": np.array([1.0, -1.0])}, "positive"),
        ({"gain": np.array([np.nan])}, "non-finite"),
        ({"gains": np.array([1.0])}, "unknown parameter"),
    ):
        with pytest.raises(ValueError, match=match):
            studies.sweep(p, bad, jnp.arange(1))
    with pytest.raises(ValueError, match="metrics"):
        studies.sweep(p, points, jnp.arange(1), metrics=lambda s: {})


def test_rebuilt_problem_with_equal_fields_does_not_recompile():
    points = {"gain": np.array([0.5, 1.0])}
    studies.sweep(toy(), points, jnp.arange(2))
    n = TRACES["n"]
    again = studies.sweep(toy(), points, jnp.arange(2)).to_pandas()  # a new, equal problem
    assert TRACES["n"] == n and (again["result"] == "successful").all()
    assert studies.fingerprint(toy()) == studies.fingerprint(toy())
    assert studies.fingerprint(toy()) != studies.fingerprint(toy(noise=0.2))
    studies.sweep(toy(noise=0.2), points, jnp.arange(2))
    assert TRACES["n"] > n  # a different problem compiles its own


def test_compare_over_a_problem():
    p = toy(limit=2.05)
    records = studies.compare(p, range(2), params={"gain": 3.0}, study=studies.Study(repeats=1))
    assert [(r["method"], r["seed"]) for r in records] == [
        ("estimator", 0), ("baseline", 0), ("estimator", 1), ("baseline", 1)
    ]  # fmt: skip
    for r in records:
        if r["result"] == "successful":
            assert isinstance(r["error"], float) and len(r["both"]) == 2
            if r["method"] == "estimator":
                assert r["error"] == pytest.approx(by_hand(p, 3.0, (0, 0), r["seed"]), rel=1e-12)
        else:
            assert r["error"] is None and r["both"] is None  # never a failed run's numbers
    with pytest.raises(ValueError, match="inputs"), pytest.warns(FutureWarning):
        studies.compare(p, lambda k: k, seeds=1)


def test_tune_and_objective_over_a_problem():
    p = toy(noise=0.0, samples=jnp.linspace(1.0, 3.0, 32), truth=1.5)
    # the weighted mean of a ramp from 1 to 3 equals 1.5 at one gain: tune finds it
    r = studies.tune(p, {"gain": 1.0}, jnp.arange(1), steps=60)
    assert r.loss < 1e-2 * r.loss0
    obj = studies.objective(p, jnp.arange(1))
    g = jax.grad(obj)({"gain": jnp.log(1.0)})["gain"]
    h = 1e-6
    fd = (obj({"gain": jnp.log(1.0) + h}) - obj({"gain": jnp.log(1.0) - h})) / (2 * h)
    np.testing.assert_allclose(g, fd, rtol=1e-6)
    with pytest.raises(ValueError, match="negative"):
        studies.tune(p, {"offset": 1.0}, jnp.arange(1))
    with pytest.raises(ValueError, match="positive"):
        studies.tune(p, {"gain": -1.0}, jnp.arange(1))


def test_the_contract_is_enforced():
    class NoMetrics(studies.AbstractProblem):
        methods = ("estimator",)
        metric = "error"

        def parameters(self):
            return {}

        def inputs(self, key):
            return key

        def solve(self, method, params, inputs, *, outputs=False):
            return inputs

    with pytest.raises(TypeError):
        NoMetrics()

    class NoMethodNames(studies.AbstractProblem):  # every method, no `methods`, `metric`
        def parameters(self):
            return {}

        def inputs(self, key):
            return key

        def solve(self, method, params, inputs, *, outputs=False):
            return inputs

        def metrics(self, method, solution):
            return {}

    with pytest.raises(TypeError, match="methods|metric"):
        NoMethodNames()


def test_registry():
    def build(*, noise_px: float = 0.1, duration: float = 1.0):
        return toy(noise=noise_px, samples=jnp.full(int(32 * duration), 2.0))

    studies.register_problem("toy_mean", build, aliases=("toy",), replace=True)
    assert "toy_mean" in studies.problem_names() and "velocity" in studies.problem_names()
    with pytest.warns(FutureWarning, match="'toy' is deprecated: it is now 'toy_mean'"):
        p = studies.problem("toy", noise_px=0.3, duration=2.0, rate_hz=None)
    assert p.noise == 0.3 and p.samples.shape == (64,)
    # the point-depth problem's name before version 0.4, read with the same warning
    with pytest.warns(FutureWarning, match="now 'point_depth'"):
        assert studies.registered("point-depth") is studies.registered("point_depth")
    with pytest.raises(ValueError, match="takes no --rate"):
        studies.problem("toy_mean", rate_hz=10.0)
    with pytest.raises(ValueError, match="registered already"):
        studies.register_problem("toy_mean", build)
    with pytest.raises(ValueError, match="unknown problem"):
        studies.problem("no_such_problem")
    studies.register_problem("toy_bad", lambda: 3, replace=True)
    with pytest.raises(studies.UserCodeError, match="returned int, not a visjax.studies.Abstr"):
        studies.problem("toy_bad")


def test_held_out_points_equal_their_evaluations_on_the_same_keys():
    """`studies.held_out`: each named point's mean metric over the keys whose run succeeded,
    against `evaluate` of the same point (an independent path: no sweep); a vector
    parameter named by one value is broadcast; bad points are refused by name."""
    problem = Mean(samples=jnp.full(8, 2.0), truth=2.0, noise=0.3, limit=2.2)
    keys = jnp.arange(10, 16)
    points = {"low": {"gain": 0.5, "offset": 0.0}, "high": {"gain": 4.0, "offset": (0.1, 0.0)}}
    held = studies.held_out(problem, points, keys, study=studies.Study(chunk=4))
    for name, point in points.items():
        ev = studies.evaluate(problem, point, keys)
        errors = np.asarray(ev.metrics["error"])
        ok = np.isfinite(errors)
        assert held[name]["failed"] == int((~ok).sum())
        np.testing.assert_allclose(held[name]["metric"], errors[ok].mean(), rtol=1e-12)
    assert held["high"]["params"] == {"gain": 4.0, "offset": [0.1, 0.0]}
    with pytest.raises(ValueError, match="has no parameter \\['gane'\\]"):
        studies.held_out(problem, {"x": {"gane": 1.0}}, keys)
    with pytest.raises(ValueError, match="the same parameters"):
        studies.held_out(problem, {"x": {"gain": 1.0}, "y": {"offset": 0.0}}, keys)
