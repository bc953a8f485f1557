"""`studies.sweep`, `best`, `summarise`, `save_table` and the grid helpers; `tune` and its
gradients on the velocity estimator of Chitrakaran et al.; sharding over a mesh of four
host devices and over two `jax.distributed` processes (subprocesses)."""

import io
import json
import os
import socket
import subprocess
import sys
import textwrap

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
import pandas as pd
import pytest

from tests.helpers import euclidean_scene_file
from visjax import papers, studies
from visjax._results import RESULTS
from visjax.estimators import CheckpointAdjoint


class Out(eqx.Module):
    value: jax.Array
    result: RESULTS
    failed_sample: jax.Array


def toy(params, key):
    """value = a + noise; a > 5 'diverges' at sample 3; a == 4 gives a NaN 'success'."""
    x = params["a"] + 0.1 * jax.random.normal(key, (3,), dtype=jnp.float64)
    x = jnp.where(params["a"] == 4.0, jnp.nan, x)
    bad = params["a"] > 5.0
    return Out(x, RESULTS.where(bad, RESULTS.diverged, RESULTS.successful), jnp.where(bad, 3, -1))


def toy_metrics(sol):
    return {"m": jnp.mean(sol.value), "v": sol.value}


def test_grid_helpers():
    np.testing.assert_allclose(studies.log_axis(1e-2, 1e1, 4), [1e-2, 1e-1, 1.0, 1e1])
    g = studies.grid(a=[1, 2], b=[3, 4, 5])
    np.testing.assert_array_equal(g["a"], [1, 1, 1, 2, 2, 2])
    np.testing.assert_array_equal(g["b"], [3, 4, 5, 3, 4, 5])
    p = studies.parse_grid("K=1e-2:1e1:4, rho=0.1/1")
    assert len(p["K"]) == 8
    np.testing.assert_allclose(sorted(set(p["K"])), [1e-2, 1e-1, 1.0, 1e1])
    np.testing.assert_allclose(sorted(set(p["rho"])), [0.1, 1.0])
    r = studies.random_points(jax.random.key(0), 200, K=(1e-2, 1e2))
    assert np.all((r["K"] >= 1e-2) & (r["K"] <= 1e2))
    # log-uniform: a quarter of the decades below 1e-1 holds about a quarter of the points
    assert 0.15 < np.mean(r["K"] < 1e-1) < 0.35
    for bad in ("K", "K=1:2", "K=1e-2:1e1:x", "K=1,K=2"):
        with pytest.raises(ValueError):
            studies.parse_grid(bad)
    with pytest.raises(ValueError, match="positive"):
        studies.log_axis(0.0, 1.0, 3)


def test_table_rows_flags_and_summary(tmp_path):
    table = studies.sweep(
        studies.FunctionProblem(toy, toy_metrics),
        studies.grid(a=[1.0, 2.0, 4.0, 6.0]),
        jnp.arange(3),
        study=studies.Study(chunk=5),
    ).to_pandas()
    assert len(table) == 12 and list(table["seed"][:4]) == [0, 1, 2, 0]
    assert list(table.columns[:4]) == ["run", "point", "a", "seed"]
    assert {"result", "failed_sample", "m", "v_0", "v_2"} <= set(table.columns)
    # each row is the unbatched run of its point and seed
    for _, row in table.iterrows():
        sol = toy({"a": jnp.asarray(row["a"])}, jax.random.key(int(row["seed"])))
        if row["result"] == "successful":
            np.testing.assert_allclose(row["v_1"], sol.value[1], rtol=0, atol=1e-15)
    # a diverging point: its code, its sample, NaN metrics (never the frozen numbers)
    div = table[table["a"] == 6.0]
    assert set(div["result"]) == {"diverged"} and set(div["failed_sample"]) == {3}
    assert div["m"].isna().all()
    # a NaN metric under a 'successful' code is reported as such
    assert set(table[table["a"] == 4.0]["result"]) == {"nonfinite_output"}
    s = studies.summarise(table, "m")
    assert list(s["n_failed"]) == [0, 0, 3, 3]
    np.testing.assert_allclose(s["m_mean"][:2], table.groupby("point")["m"].mean()[:2])
    b = studies.best(table, "m")
    assert b["params"] == {"a": 1.0} and b["point"] == 0
    paths = studies.save_table(table, tmp_path / "out")
    back = pd.read_parquet(paths["parquet"])
    pd.testing.assert_frame_equal(back, table)
    csv = pd.read_csv(paths["csv"])
    np.testing.assert_allclose(csv["m"], table["m"], rtol=1e-15)
    with pytest.raises(ValueError, match="every parameter point"):
        studies.best(table[table["a"] > 3.0], "m")


def test_bad_arguments():
    with pytest.raises(ValueError, match="leading axis"):
        studies.sweep(
            studies.FunctionProblem(toy, toy_metrics),
            {"a": jnp.ones(3), "b": jnp.ones(2)},
            jnp.arange(2),
        )
    with pytest.raises(ValueError, match="seeds"):
        studies.sweep(studies.FunctionProblem(toy, toy_metrics), {"a": jnp.ones(3)}, jnp.ones(2))
    with pytest.raises(ValueError, match="chunk"):
        studies.sweep(
            studies.FunctionProblem(toy, toy_metrics),
            {"a": jnp.ones(3)},
            jnp.arange(2),
            study=studies.Study(chunk=0),
        )


# The velocity estimator, 2 s of the section-6 simulation at 1 kHz, 0.1 px noise: one
# problem (one noise-free calibration) for the module.


@pytest.fixture(scope="module")
def velocity():
    return papers.velocity_problem(noise_px=0.1, duration=2.0)


@pytest.mark.slow
def test_velocity_rows_equal_one_by_one_and_divergence_flagged(velocity):
    params = {"K_scale": jnp.array([0.01, 1.0, 10.0]), "rho_scale": jnp.array([0.1, 1.0, 1.0])}
    table = studies.sweep(velocity, params, jnp.arange(2)).to_pandas()

    # evaluate closes over the problem (its arrays are the scene's constants): jit the
    # function of the parameters
    @jax.jit
    def metrics(p, key):
        return studies.evaluate(velocity, p, key[None]).metrics

    def one(p, key):
        return metrics(p, key)

    for _, row in table[table["point"] < 2].iterrows():
        p = {"K_scale": jnp.asarray(row["K_scale"]), "rho_scale": jnp.asarray(row["rho_scale"])}
        m = one(p, jax.random.key(int(row["seed"])))
        np.testing.assert_allclose(
            row[[f"rms_{a}" for a in papers.chitrakaran.AXES]].to_numpy(float),
            m["rms"][0],
            rtol=1e-12,
            atol=0,
        )
    # a parameter is the parameter: the gain K itself (the published one times 0.01) runs
    # as its multiplier does
    K63 = np.asarray(velocity.K)
    row = table.iloc[0]
    m = one({"K": 0.01 * K63, "rho_scale": 0.1}, jax.random.key(int(row["seed"])))
    np.testing.assert_allclose(m["rms_worst"][0], row["rms_worst"], rtol=1e-12)
    # K x 10: (K + 1) dt = 3 > 2, past Euler's stability bound: a flagged row, no numbers
    bad = table[table["K_scale"] == 10.0]
    assert set(bad["result"]) == {"unstable_step"} and bad["rms_worst"].isna().all()
    ok = table[table["K_scale"] < 10.0]
    assert (ok["result"] == "successful").all() and np.isfinite(ok["rms_worst"]).all()
    # the stream's chunk (a speed setting) does not change a number
    for bad in (0, -3):
        with pytest.raises(ValueError, match="chunk"):
            papers.velocity_problem(duration=2.0, chunk=bad)
    small = papers.velocity_problem(noise_px=0.1, duration=2.0, chunk=16)
    assert small.settings()["chunk"] == 16 and velocity.settings()["chunk"] == 256
    key = jax.random.key(1)
    m16 = studies.evaluate(small, {}, key[None]).metrics
    np.testing.assert_allclose(m16["rms"], one({}, key)["rms"], rtol=1e-10, atol=0)


def test_velocity_constants_from_the_calibration_or_from_each_draw(velocity):
    """`constants="calibration"`: n* and z1* from the noise-free frames, shared by every
    draw; `"per_draw"`: measured from each draw's noisy frames with the known length (the
    square's diagonal), as `fixed_camera` measures them."""
    from visjax.estimators import fixed_camera

    per_draw = papers.velocity_problem(noise_px=0.1, duration=2.0, constants="per_draw")
    assert per_draw.known_length[:2] == (0, 2) and per_draw.known_length == velocity.known_length
    inputs = per_draw.inputs(jax.random.key(3))
    measured = per_draw.camera(inputs)
    ref = fixed_camera(
        inputs["pixels"], per_draw.A, per_draw.R_star, per_draw.s1,
        known_length=per_draw.known_length,
    )  # fmt: skip
    np.testing.assert_allclose(measured.z1_star, ref.z1_star, rtol=1e-12)
    np.testing.assert_allclose(measured.n_star, ref.n_star, rtol=1e-12, atol=1e-15)
    calibration = velocity.camera(inputs)
    assert float(calibration.z1_star) == float(velocity.z1_star)
    assert abs(float(velocity.z1_star) - 1.99) < 1e-9  # the truth, eq. (60)-(61)
    assert 1e-7 < abs(float(measured.z1_star) - 1.99) < 0.05  # the noise moves it, a little
    with pytest.raises(ValueError, match="constants"):
        papers.velocity_problem(duration=2.0, constants="noisy")


@pytest.mark.slow
def test_tune_lowers_velocity_loss_tenfold_and_gradients(velocity):
    keys = jnp.arange(2)
    start = {"K_scale": 1.0, "rho_scale": 1.0}
    r = studies.tune(velocity, start, keys, steps=20, optimiser=optax.adam(0.3))
    assert r.loss0 > 1.0  # the paper's gains at 0.1 px (a metre per second)
    assert r.loss < r.loss0 / 10, (r.loss0, r.loss, r.params)
    assert pd.DataFrame(r.history)["loss"].min() == pytest.approx(r.loss)
    # forward mode (the default), reverse mode and central differences agree at a point
    # where the loss is smooth (no sign flip of the sign-based term within the step)
    z = {"K_scale": jnp.log(0.01), "rho_scale": jnp.log(0.1)}
    fwd = studies.objective(velocity, keys)
    g_fwd = jax.jit(jax.grad(fwd))(z)
    f = jax.jit(fwd)
    h = 1e-6
    for k in z:
        fd = (f({**z, k: z[k] + h}) - f({**z, k: z[k] - h})) / (2 * h)
        np.testing.assert_allclose(g_fwd[k], fd, rtol=1e-5)
    # many gains: the six gains of K and of rho themselves, reverse mode through the
    # checkpointed runner; by the chain rule the per-axis log-gradients sum to the scalar
    # multiplier's
    ckpt = papers.velocity_problem(noise_px=0.1, duration=2.0, adjoint=CheckpointAdjoint())
    rev = studies.objective(ckpt, keys, mode="reverse")
    z6 = {
        "K": jnp.log(0.01 * jnp.asarray(ckpt.K)),
        "rho": jnp.log(0.1 * jnp.asarray(ckpt.rho)),
    }
    g_rev = jax.jit(jax.grad(rev))(z6)
    for k, scale in (("K", "K_scale"), ("rho", "rho_scale")):
        assert g_rev[k].shape == (6,)
        np.testing.assert_allclose(jnp.sum(g_rev[k]), g_fwd[scale], rtol=1e-9)
    with pytest.raises(ValueError, match="positive"):
        studies.tune(velocity, {"K_scale": -1.0, "rho_scale": 1.0}, keys)


_SHARDED = """
import json, sys
import jax, jax.numpy as jnp, numpy as np
{setup}
jax.config.update("jax_enable_x64", True)
from jax.sharding import Mesh
from visjax import studies
sys.path.insert(0, {root!r})
from tests.studies.test_sweep import toy, toy_metrics
mesh = Mesh(np.array(jax.devices()), ("runs",))
params = studies.grid(a=[1.0, 2.0, 3.0, 6.0, 0.5])
problem = studies.FunctionProblem(toy, toy_metrics)
sharded = studies.sweep(problem, params, jnp.arange(3), study=studies.Study(chunk=6, mesh=mesh))
plain = studies.sweep(problem, params, jnp.arange(3), study=studies.Study(chunk=6))
print(json.dumps({{"devices": len(jax.devices()), "process": jax.process_index(),
    "equal": bool(sharded.equals(plain)), "rows": len(sharded),
    "table": sharded.to_json()}}))
"""

_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _python(code, env_extra, args=()):
    env = {**os.environ, **env_extra}
    return subprocess.Popen(
        [sys.executable, "-c", code, *args],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=_ROOT,
    )


def _last_json(proc):
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err[-3000:]
    return json.loads(out.strip().splitlines()[-1])


@pytest.mark.slow  # a multi-device subprocess: the second command (.ci/run)
def test_sharded_over_four_host_devices_equals_unsharded():
    code = _SHARDED.format(setup="", root=_ROOT)
    r = _last_json(_python(code, {"XLA_FLAGS": "--xla_force_host_platform_device_count=4"}))
    assert r["devices"] == 4 and r["rows"] == 15 and r["equal"]


_VELOCITY = """
import json, sys
import jax
{setup}
import jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
from jax.sharding import Mesh
from visjax import studies
from visjax import papers
setup = papers.velocity_problem(noise_px=0.1, duration=2.0)
params = {{"K_scale": np.array([0.01, 1.0, 10.0]), "rho_scale": np.array([0.1, 1.0, 1.0])}}
mesh = Mesh(np.array(jax.devices()), ("runs",))
t = studies.sweep(setup, params, jnp.arange(2), study=studies.Study(mesh=mesh)).to_pandas()
print(json.dumps({{"devices": len(jax.devices()), "process": jax.process_index(),
    "table": t.to_json(double_precision=15)}}))
"""


@pytest.mark.slow
def test_two_processes_with_jax_distributed(velocity):
    """Two processes on localhost (CPU collectives by gloo), one device each, the velocity
    estimator (a full run per row): every process holds the whole table, equal to the
    unsharded sweep, flagged rows included."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    setup_code = textwrap.dedent(
        f"""
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
        jax.distributed.initialize(coordinator_address="127.0.0.1:{port}",
                                   num_processes=2, process_id=int(sys.argv[1]))
        """
    )
    code = _VELOCITY.format(setup=setup_code)
    procs = [_python(code, {}, [str(i)]) for i in range(2)]
    results = [_last_json(p) for p in procs]
    assert [r["process"] for r in results] == [0, 1]
    assert all(r["devices"] == 2 for r in results)
    assert results[0]["table"] == results[1]["table"]
    sharded = pd.read_json(io.StringIO(results[0]["table"]))
    # the unsharded sweep of the module's test above (same problem, same compiled chunk)
    params = {"K_scale": np.array([0.01, 1.0, 10.0]), "rho_scale": np.array([0.1, 1.0, 1.0])}
    plain = studies.sweep(velocity, params, jnp.arange(2)).to_pandas()
    assert list(sharded["result"]) == list(plain["result"])
    assert list(plain["result"][-2:]) == ["unstable_step"] * 2
    np.testing.assert_allclose(sharded["rms_worst"], plain["rms_worst"], rtol=1e-12)


class Scalar(eqx.Module):
    value: jax.Array
    result: RESULTS


def bowl(params, key):
    """(log a - log 3)^2 + (log b + 1)^2 plus a key-dependent constant: minimum a=3, b=1/e."""
    c = jax.random.uniform(key, (), dtype=jnp.float64)
    v = (jnp.log(params["a"]) - jnp.log(3.0)) ** 2 + (jnp.log(params["b"]) + 1.0) ** 2 + c
    return Scalar(v, RESULTS.successful)


@pytest.mark.parametrize("method", ["optax", "optimistix"])
def test_tune_finds_minimum_in_log_parameters(method):
    import optimistix as optx

    opt = optax.adam(0.2) if method == "optax" else optx.BFGS(rtol=1e-8, atol=1e-10)
    problem = studies.FunctionProblem(bowl, lambda s: {"value": s.value}, metric="value")
    r = studies.tune(problem, {"a": 1.0, "b": 1.0}, jnp.arange(2), optimiser=opt, steps=100)
    tol = 1e-2 if method == "optax" else 1e-5  # adam's fixed steps jitter around the minimum
    assert r.params["a"] == pytest.approx(3.0, rel=tol)
    assert r.params["b"] == pytest.approx(np.exp(-1.0), rel=tol)
    assert r.loss < r.loss0 and r.converged
    assert r.improved and r.best_step > 0 and r.not_improved_line() is None


@pytest.mark.parametrize("method", ["optax", "optimistix"])
def test_tune_that_cannot_improve_returns_its_start_and_says_so(method):
    """Started at the bowl's minimum, no step lowers the loss: `tune` returns the start
    (`best_step` 0, `improved` False) and warns, naming the start's loss."""
    import optimistix as optx

    opt = optax.adam(0.5) if method == "optax" else optx.BFGS(rtol=1e-8, atol=1e-10)
    problem = studies.FunctionProblem(bowl, lambda s: {"value": s.value}, metric="value")
    start = {"a": 3.0, "b": float(np.exp(-1.0))}
    with pytest.warns(UserWarning, match="did not improve on its start") as caught:
        r = studies.tune(problem, start, jnp.arange(2), optimiser=opt, steps=3)
    assert not r.improved and r.best_step == 0 and r.loss == r.loss0
    assert r.params == pytest.approx(start, rel=1e-12)
    assert f"{r.loss0:.4g}" in str(caught[0].message)


@pytest.mark.slow
def test_velocity_sweep_on_a_data_file_with_dropouts(tmp_path):
    """`velocity_problem(data=FILE)`: the user's own file (features out of view as NaN, the
    file's own gains absent: eq. (63)); every run succeeds with finite metrics."""
    from tests.example_data import velocity_example

    data = velocity_example(duration=0.5, noise_px=0.0)
    assert np.isnan(data.pixels).any()
    path = data.save(tmp_path / "v.npz")
    setup = papers.velocity_problem(noise_px=0.1, data=path)
    assert setup.settings()["source"] == str(path)
    table = studies.sweep(
        setup,
        {"K_scale": jnp.array([0.01, 0.1]), "rho_scale": jnp.array([0.1, 0.1])},
        jnp.arange(2),
    ).to_pandas()
    assert (table["result"] == "successful").all()
    assert np.isfinite(table["rms_worst"]).all() and (table["rms_worst"] > 0).all()


def test_euclidean_tuning_from_a_file_equals_the_scene(tmp_path):
    """`static_points_problem(data=FILE)` on a file written from the project's scene gives the
    scene's own runs (same pixels, same noise per seed) to 1e-12; a gain past Euler's
    bound is a flagged row."""
    path = euclidean_scene_file(tmp_path / "euclidean.npz", 2.0, 20.0)
    params = {"alpha_scale": jnp.array([1.0, 30.0]), "gamma_scale": jnp.array([1.0, 30.0])}
    tables = [
        studies.sweep(s, params, jnp.arange(1))
        for s in (
            papers.static_points_problem(noise_px=0.1, duration=2.0, rate_hz=20.0),
            papers.static_points_problem(noise_px=0.1, data=path),
        )
    ]
    a, b = (t.iloc[0] for t in tables)
    assert a["result"] == b["result"] == "successful"
    np.testing.assert_allclose(b["error_worst"], a["error_worst"], rtol=1e-12)
    assert 0 < a["error_worst"] < 0.5
    assert {t.iloc[1]["result"] for t in tables} == {"unstable_step"}
