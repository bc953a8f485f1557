"""The homography observer on SL(3) of Hamel et al. (`visjax.papers.hamel`): the innovation
against a NumPy transcription, the truth kept with det 1, convergence from the identity,
the Lyapunov function decreasing, jit/vmap/grad, bad input."""

import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest

from tests.helpers import central_difference, innovation_ratios
from visjax import RESULTS, studies
from visjax.cli import main
from visjax.estimators import SaveAt, run
from visjax.geometry import sl3_exp
from visjax.papers import hamel

K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
_RNG = np.random.default_rng(11)
# the group velocity (trace-free, constant) and the initial homography
A0 = np.array([[0.05, 0.2, 0.1], [-0.15, -0.02, 0.08], [0.03, -0.04, -0.03]])
H0 = np.asarray(sl3_exp(np.array([[0.1, -0.05, 0.2], [0.08, -0.05, -0.1], [0.05, 0.02, -0.05]])))


@pytest.fixture(scope="module")
def scene():
    """1 s at 1 kHz: H(t) = H0 exp(t A0) (so dH/dt = H A0), six reference pixels, the
    current pixels of p_i ~ H(t)^-1 p_ref_i."""
    ts = np.arange(1001) / 1000.0
    ref_px = np.array(
        [
            [100.0, 80.0],
            [540.0, 90.0],
            [560.0, 400.0],
            [90.0, 420.0],
            [330.0, 250.0],
            [250.0, 150.0],
        ]
    )
    p_ref = np.asarray(hamel.unit_bearings(ref_px, K))
    Hs = np.stack([H0 @ np.asarray(sl3_exp(t * A0)) for t in ts])
    cur = np.einsum("kij,nj->kni", np.linalg.inv(Hs), p_ref)
    assert np.all(cur[..., 2] > 0)  # every point in front in every frame
    pixels = np.einsum("ij,knj->kni", K, cur / cur[..., 2:])[..., :2]
    stream = hamel.homography_stream(ts, pixels, np.broadcast_to(A0, (ts.size, 3, 3)), K)
    return ts, p_ref, Hs, stream


def test_innovation_against_a_numpy_transcription(scene):
    ts, p_ref, Hs, stream = scene
    y = stream.measurement(500)
    H_hat = Hs[500] + 0.05 * _RNG.normal(size=(3, 3))
    ref = np.zeros((3, 3))
    for p, pr in zip(np.asarray(y.p), p_ref, strict=True):
        e = H_hat @ p / np.linalg.norm(H_hat @ p)
        ref += np.outer((np.eye(3) - np.outer(e, e)) @ pr, e)
    got = np.asarray(hamel.homography_innovation(H_hat, y.p, p_ref))
    np.testing.assert_allclose(got, ref, rtol=1e-13, atol=1e-15)
    assert abs(np.trace(got)) < 1e-15  # in sl(3)
    # zero at the truth, and the observer then moves with the truth: dH/dt = H A
    np.testing.assert_allclose(hamel.homography_innovation(Hs[500], y.p, p_ref), 0.0, atol=1e-15)
    obs = hamel.HomographyEstimator(k_P=5.0, p_ref=p_ref)
    state = hamel.HomographyState(jnp.asarray(Hs[500]), jnp.zeros((3, 3)))
    field = obs.vector_field(0.5, state, y)
    np.testing.assert_allclose(field.H, Hs[500] @ A0, atol=1e-14)


def test_truth_kept_and_convergence_from_the_identity(scene):
    """Started on the truth: kept to 1e-5 (Euler at 1 kHz; measured 3.3e-6). Started at
    the identity (the truth is 0.28 away), with k_P = 100 the error |H_hat H^-1 - I| falls
    below 2e-4 within 1 s (measured 5.1e-5; 1.2e-3 with k_P = 50: six points in a
    60-degree field of view leave one slow direction), the correspondence cost never
    increases by more than round-off, and det = 1 to 1e-12 at every saved sample."""
    ts, p_ref, Hs, stream = scene
    kept = run(hamel.HomographyEstimator(k_P=5.0, p_ref=p_ref, H0=Hs[0]), stream)
    assert kept.result == RESULTS.successful
    assert np.abs(np.asarray(kept.outputs.H) - Hs).max() < 1e-5
    sol = run(hamel.HomographyEstimator(k_P=100.0, p_ref=p_ref), stream)
    assert sol.result == RESULTS.successful
    H = np.asarray(sol.outputs.H)
    err = np.linalg.norm(H @ np.linalg.inv(Hs) - np.eye(3), axis=(1, 2))
    assert err[0] > 0.2 and err[-1] < 2e-4, (err[0], err[-1])
    np.testing.assert_allclose(np.linalg.det(H), 1.0, atol=1e-12)
    cost = np.asarray(sol.outputs.cost)
    assert np.all(np.diff(cost) < 1e-12) and cost[-1] < 1e-6 * cost[0]


def test_jit_vmap_grad(scene):
    ts, p_ref, Hs, stream = scene

    def final_error(k):
        sol = run(
            hamel.HomographyEstimator(k_P=k, p_ref=p_ref), stream, saveat=SaveAt(outputs=False)
        )
        return jnp.sum((sol.final_state.H @ jnp.linalg.inv(Hs[-1]) - jnp.eye(3)) ** 2)

    ks = jnp.array([2.0, 5.0])
    batched = jax.jit(jax.vmap(final_error))(ks)
    for k, b in zip(ks, batched, strict=True):
        np.testing.assert_allclose(final_error(k), b, rtol=1e-10)
    assert batched[1] < batched[0]
    g = jax.grad(final_error)(2.0)
    fd = central_difference(lambda k: final_error(k[0]), np.array([2.0]), 1e-4)
    np.testing.assert_allclose(g, fd[0], rtol=1e-5)


def test_bad_input(scene, no_jaxtyping):
    ts, p_ref, Hs, stream = scene
    good_px = np.zeros((ts.size, 6, 2)) + 300.0
    bad_px = good_px.copy()
    bad_px[7, 3] = np.nan
    A = np.broadcast_to(A0, (ts.size, 3, 3))
    with pytest.raises(Exception, match="sample 7"):
        hamel.homography_stream(ts, bad_px, A, K)
    with pytest.raises(ValueError, match="group_velocity"):
        hamel.homography_stream(ts, good_px, A[:, :2], K)
    with pytest.raises(ValueError, match="n >= 4"):
        hamel.HomographyEstimator(k_P=1.0, p_ref=p_ref[:3])
    # an estimate that sends a point more than 90 degrees from its reference direction
    obs = hamel.HomographyEstimator(k_P=1.0, p_ref=p_ref)
    y = stream.measurement(0)
    assert obs.valid(hamel.HomographyState(jnp.asarray(Hs[0]), jnp.zeros((3, 3))), y)
    flipped = np.diag([1.0, -1.0, -1.0]) @ Hs[0]  # det 1, every bearing turned about x
    assert not obs.valid(hamel.HomographyState(jnp.asarray(flipped), jnp.zeros((3, 3))), y)
    with pytest.raises(ValueError, match="H0"):
        run(hamel.HomographyEstimator(k_P=1.0, p_ref=p_ref, H0=np.zeros((3, 3))), stream)


# ---------------------------------------------------------------------------------------
# The integral term (a group velocity measured in part, or not at all)


def test_integral_term_against_numpy_and_its_lyapunov_function(scene):
    """The observer's field with k_I > 0 against a NumPy transcription (dGamma/dt = k_I
    H^T Delta H^-T, trace-free); with nothing of the group velocity measured (A_m = 0,
    Gamma = A0 constant) the function f + |A0 - Gamma_hat|^2 / (2 k_I) of the module
    docstring never increases (by more than 1e-7; measured: it falls at every step, from
    0.11 to 1e-6) and the estimate converges (final error below 5e-3, Gamma_hat within
    0.05 of A0, whose largest entry is 0.2; measured 1.5e-3 and 0.018)."""
    ts, p_ref, Hs, stream = scene
    blind = hamel.homography_stream(ts, _pixels(p_ref, Hs), np.zeros((ts.size, 3, 3)), K)
    obs = hamel.HomographyEstimator(k_P=100.0, p_ref=p_ref, k_I=500.0)
    y = blind.measurement(300)
    H = Hs[300] + 0.03 * _RNG.normal(size=(3, 3))
    G = 0.1 * _RNG.normal(size=(3, 3))
    field = obs.vector_field(0.3, hamel.HomographyState(jnp.asarray(H), jnp.asarray(G)), y)
    delta = np.zeros((3, 3))
    for p, pr in zip(np.asarray(y.p), p_ref, strict=True):
        e = H @ p / np.linalg.norm(H @ p)
        delta += np.outer((np.eye(3) - np.outer(e, e)) @ pr, e)
    np.testing.assert_allclose(field.H, H @ G + 100.0 * delta @ H, rtol=1e-12, atol=1e-14)
    gamma_dot = 500.0 * H.T @ delta @ np.linalg.inv(H).T
    np.testing.assert_allclose(field.Gamma, gamma_dot, rtol=1e-10, atol=1e-13)
    assert abs(np.trace(gamma_dot)) < 1e-12

    sol = run(obs, blind, saveat=SaveAt(outputs=True, states=True))
    assert sol.result == RESULTS.successful
    gamma = np.asarray(sol.states.Gamma)
    lyap = np.asarray(sol.outputs.cost) + np.sum((A0 - gamma) ** 2, axis=(1, 2)) / (2 * 500.0)
    assert np.max(np.diff(lyap)) < 1e-7 and lyap[-1] < 0.05 * lyap[0], (np.diff(lyap).max(), lyap)
    err = np.linalg.norm(np.asarray(sol.outputs.H)[-1] @ np.linalg.inv(Hs[-1]) - np.eye(3))
    assert err < 5e-3 and np.abs(gamma[-1] - A0).max() < 0.05, (err, gamma[-1] - A0)


def _pixels(p_ref, Hs):
    cur = np.einsum("kij,nj->kni", np.linalg.inv(Hs), p_ref)
    return np.einsum("ij,knj->kni", K, cur / cur[..., 2:])[..., :2]


# ---------------------------------------------------------------------------------------
# The problem `homography`


@pytest.fixture(scope="module")
def tracking():
    return hamel.homography_problem(noise_px=0.0, duration=1.0, rate_hz=500.0)


def test_scene_group_velocity_and_bearings(tracking):
    """The scene's homography maps the current bearings to the reference ones (to 1e-14),
    and its group velocity, plane_group_velocity, is H^-1 dH/dt (central differences, to
    1e-5 at 500 Hz)."""
    sc = tracking.scene
    p = hamel.unit_bearings(sc.pixels[200], sc.K) @ np.asarray(sc.H[200]).T
    p = p / np.linalg.norm(p, axis=1, keepdims=True)
    np.testing.assert_allclose(p, hamel.unit_bearings(sc.reference, sc.K), atol=1e-14)
    H, dt = np.asarray(sc.H), float(sc.ts[1] - sc.ts[0])
    A_fd = np.linalg.solve(H[1:-1], (H[2:] - H[:-2]) / (2 * dt))
    np.testing.assert_allclose(A_fd, sc.A[1:-1], atol=1e-5)
    np.testing.assert_allclose(np.trace(np.asarray(sc.A), axis1=1, axis2=2), 0.0, atol=1e-15)


@pytest.mark.slow  # every method's compile at the fixture's length (10 s): the unit tier's
# budget; the unit tier keeps the estimator's convergence (above) and the estimator's and
# the DLT's result codes on a failed frame (below)
def test_problem_methods_without_noise(tracking):
    """Noise-free: the per-frame baselines are exact (DLT to 1e-12, OpenCV's RANSAC to
    1e-6); the observer from the identity (0.27 away) converges at k_P = 100, with the
    group velocity (final error below 1e-3) and with the angular velocity only (below 5e-3;
    measured 3.7e-4 and 1.2e-3); det 1 at every sample."""
    params = tracking.resolve({"k_P": 100.0})
    inputs = tracking.inputs(jax.random.PRNGKey(0))
    got = {}
    for method in tracking.methods:
        sol = tracking.solve(method, params, inputs)
        assert sol.result == RESULTS.successful, method
        got[method] = {k: float(v) for k, v in tracking.metrics(method, sol).items()}
        if method in ("estimator", "gyro"):
            np.testing.assert_allclose(np.linalg.det(np.asarray(sol.outputs.H)), 1.0, atol=1e-12)
    assert got["dlt"]["final_error"] < 1e-12 and got["ransac"]["final_error"] < 1e-6, got
    assert got["estimator"]["final_error"] < 1e-3 and got["gyro"]["final_error"] < 5e-3, got


@pytest.mark.slow  # every method's compile in a vmapped comparison (8 s): the unit tier's
# budget; the command's smoke test runs compare on the moving point
def test_compare_command(tmp_path):
    """`visjax compare homography --set tracking`: every method's records with result
    codes."""
    out = tmp_path / "compare"
    argv = ["compare", "homography", "--set", "tracking", "--seeds", "2", "--noise", "0.5"]
    assert main([*argv, "--duration", "0.4", "--quiet", "--out", str(out)]) == 0
    records = pd.read_parquet(next(out.rglob("records.parquet")))
    assert set(records["method"]) == {"estimator", "gyro", "dlt", "ransac"}
    assert (records["result"] == "successful").all() and (records["error"] < 0.2).all()


def test_a_failed_frame(tracking, no_jaxtyping):
    """A NaN pixel fails the observer (nonfinite measurement) and the DLT (a result code,
    not an exception), never a number."""
    inputs = tracking.inputs(jax.random.PRNGKey(0))
    inputs["pixels"] = inputs["pixels"].at[40, 1, 0].set(jnp.nan)
    for method in ("estimator", "dlt"):
        sol = tracking.solve(method, tracking.resolve(), inputs)
        assert sol.result != RESULTS.successful, method
        if method == "dlt":  # that frame's homography is NaN, never a number
            assert np.isnan(np.asarray(sol.H[40])).all() and np.isfinite(sol.H[39]).all()
    with pytest.raises(ValueError, match="variant"):
        hamel.homography_problem(variant="nope")
    with pytest.raises(ValueError, match="noise_px"):
        hamel.homography_problem(noise_px=-1.0)


@pytest.mark.slow  # the velocity problem's compile (14 s): the unit tier's budget
def test_velocity_front_end(tracking):
    """The observer as the velocity problem's front end (1 s at 250 Hz, noise-free): its
    pixels start on the reference image and stay within 3 px of the truth (measured 1.6
    px), and `four_point` is the velocity problem's estimator itself. A gain too high for
    the sample rate is refused (unstable step), its pixels NaN, never garbage."""
    problem = hamel.homography_problem(variant="velocity_front_end", duration=1.0, rate_hz=250.0)
    base = problem.base
    inputs = problem.inputs(jax.random.PRNGKey(0))
    params = problem.resolve()
    predicted, front = problem.observed_pixels(params, inputs)
    assert front.result == RESULTS.successful
    np.testing.assert_allclose(predicted[0], inputs["pixels"][0], atol=1e-9)
    assert float(jnp.max(jnp.abs(predicted - inputs["pixels"]))) < 3.0
    mine = problem.metrics("four_point", problem.solve("four_point", params, inputs))
    theirs = base.metrics("estimator", base.solve("estimator", base.resolve(), inputs))
    np.testing.assert_allclose(mine["rms"], theirs["rms"], rtol=1e-12)
    obs = problem.solve("observer", params, inputs)
    assert obs.result == RESULTS.successful
    assert np.isfinite(problem.metrics("observer", obs)["rms_worst"])
    too_fast = {**params, "k_P": jnp.asarray(1000.0)}
    with pytest.raises(ValueError, match="stability bound"):  # outside jit: raised
        problem.observed_pixels(too_fast, inputs)
    predicted, front = eqx.filter_jit(problem.observed_pixels)(too_fast, inputs)
    assert front.result == RESULTS.unstable_step and np.isnan(np.asarray(predicted)).all()
    # the integral term's bound, dt < k_P / k_I (here 3e-4 s against 4e-3 s)
    too_stiff = {**params, "k_P": jnp.asarray(30.0), "k_I": jnp.asarray(1e5)}
    front = eqx.filter_jit(problem.observed_pixels)(too_stiff, inputs)[1]
    assert front.result == RESULTS.unstable_step
    assert set(studies.problem("homography", variant="tracking").methods) == set(
        hamel.HomographyProblem.methods
    )


@pytest.mark.slow  # the sweep and run commands' compiles on this problem (4 s): the commands'
# smoke tests run them on the moving point, the compare command above on this problem
def test_sweep_and_run_commands(tmp_path, capsys):
    """`visjax sweep homography` and `visjax run homography` with no other change: the
    grid's rows, the defaults reported as visjax's own ("defaults", the JSON key staying
    `paper`), the run's figure."""
    out = tmp_path / "sweep"
    argv = ["sweep", "homography", "--set", "tracking", "--duration", "0.4", "--seeds", "1"]
    assert main([*argv, "--grid", "k_P=30/100", "--quiet", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "[tracking] defaults " in printed and "[tracking] paper " not in printed
    table = pd.read_parquet(next(out.rglob("runs.parquet")))
    assert sorted(table["k_P"]) == [30.0, 100.0] and (table["result"] == "successful").all()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["sets"]["tracking"]["paper"]["params"]["k_P"] == 30.0
    run_out = tmp_path / "run"
    argv = ["run", "homography", "--set", "tracking", "--duration", "0.4", "--quiet"]
    assert main([*argv, "--out", str(run_out)]) == 0
    assert next(run_out.rglob("run.png")).stat().st_size > 0


def test_the_trivial_estimate_is_the_identity(tracking):
    """Issue 44: `HomographyProblem.trivial()`, the identity held, scored as the methods
    are: the RMS over the second half of |H^-1 - I|_F and its last value (NumPy)."""
    H = np.asarray(tracking.scene.H)
    err = np.linalg.norm(np.linalg.inv(H) - np.eye(3), axis=(1, 2))
    got = tracking.trivial()
    np.testing.assert_allclose(
        got["error"], np.sqrt(np.mean(err[len(err) // 2 :] ** 2)), rtol=1e-12
    )
    np.testing.assert_allclose(got["final_error"], err[-1], rtol=1e-12)


def test_innovation_check_of_the_observers(tracking):
    """Issue 44: the observers' output error against the noise of the bearings
    (`HomographyProblem.innovation`), over the second half of a 1 s run with 0.5 px of
    noise: within `INNOVATION_GATE` at k_P = 100 (measured 1.65: the reference image's
    noise included), far past it at k_P = 0.1 (from the identity, 0.27 away, the estimate
    never reaches the measurements); `None` for the per-frame fits. (At the default k_P =
    30 it is 5.4: still converging over that half, and the warning says so.)"""
    from visjax.studies import INNOVATION_GATE

    noisy = hamel.homography_problem(noise_px=0.5, duration=1.0, rate_hz=500.0)
    ratios = innovation_ratios(noisy, jax.random.key(1), "k_P", (100.0, 0.1))
    assert ratios[100.0] < INNOVATION_GATE < ratios[0.1], ratios
    assert noisy.innovation("dlt", noisy.resolve({}), None, None) is None
