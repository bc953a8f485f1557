"""The generic EKF core: on a linear model it is the linear Kalman filter (a reduction
oracle written independently in NumPy), it skips missing components and dropped samples,
and it flags a diverging run under `vmap` without touching the others."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax._results import RESULTS
from visjax.baselines._ekf import AbstractEKFModel, extended_kalman_filter

N = 40
DT = 0.1


class Linear(AbstractEKFModel):
    """A constant-velocity target in the plane with a known acceleration input,
    position measured: x = [p, v] (4,)."""

    q: jax.Array = eqx.field(converter=jnp.asarray)
    r: jax.Array = eqx.field(converter=jnp.asarray)
    limit: jax.Array = eqx.field(converter=jnp.asarray, default=1e6)

    def transition(self, x, u, dt):
        return jnp.concatenate([x[:2] + dt * x[2:] + 0.5 * dt**2 * u, x[2:] + dt * u])

    def process_noise(self, x, u, dt):
        G = jnp.concatenate([0.5 * dt**2 * jnp.eye(2), dt * jnp.eye(2)])
        return self.q * G @ G.T

    def measure(self, x, u):
        return x[:2]

    def measurement_noise(self, x, u):
        return self.r * jnp.eye(2)

    def valid(self, x, u):
        return jnp.all(jnp.abs(x) < self.limit)


def numpy_kalman(ts, zs, us, x0, P0, q, r, present, substeps):
    """The linear Kalman filter, written out in NumPy (the oracle)."""
    xs, Ps = [], []
    x, P = x0.copy(), P0.copy()
    for k in range(len(ts)):
        if present[k]:
            seen = np.isfinite(zs[k])
            H = np.eye(2, 4)[seen]
            R = r * np.eye(int(seen.sum()))
            S = H @ P @ H.T + R
            K = P @ H.T @ np.linalg.inv(S)
            x = x + K @ (zs[k][seen] - H @ x)
            P = (np.eye(4) - K @ H) @ P
        xs.append(x.copy())
        Ps.append(P.copy())
        if k + 1 < len(ts):
            h = (ts[k + 1] - ts[k]) / substeps
            F = np.block([[np.eye(2), h * np.eye(2)], [np.zeros((2, 2)), np.eye(2)]])
            G = np.concatenate([0.5 * h**2 * np.eye(2), h * np.eye(2)])
            for _ in range(substeps):
                x = F @ x + G @ us[k]
                P = F @ P @ F.T + q * G @ G.T
    return np.array(xs), np.array(Ps)


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(3)
    ts = np.cumsum(np.r_[0.0, rng.uniform(0.05, 0.15, N - 1)])  # non-uniform rate
    us = rng.normal(size=(N, 2))
    zs = rng.normal(size=(N, 2)) + np.linspace(0, 5, N)[:, None]
    zs[5, 1] = np.nan  # one missing component
    zs[9] = np.nan  # a whole missing frame
    present = np.ones(N, bool)
    present[20] = False  # a dropped sample
    x0 = np.array([0.0, 0.0, 1.0, -1.0])
    P0 = np.diag([1.0, 2.0, 3.0, 4.0])
    return ts, zs, us, x0, P0, present


run = eqx.filter_jit(extended_kalman_filter)


def test_linear_case_is_the_kalman_filter(data):
    ts, zs, us, x0, P0, present = data
    model = Linear(q=0.3, r=0.05)
    sol = run(model, ts, zs, us, x0, P0, present=present, substeps=3)
    xs, Ps = numpy_kalman(ts, zs, us, x0, P0, 0.3, 0.05, present, 3)
    assert sol.result == RESULTS.successful
    assert int(sol.failed_sample) == -1
    np.testing.assert_allclose(sol.outputs.x, xs, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(sol.outputs.P, Ps, rtol=1e-9, atol=1e-12)


def test_vmap_flags_one_seed_and_keeps_the_others(data):
    ts, zs, us, x0, P0, present = data
    model = Linear(q=0.3, r=0.05, limit=50.0)
    noise = np.random.default_rng(0).normal(size=(3, N, 2)) * 0.1
    batch = zs[None] + noise
    batch[1, 30:] = 1e3  # this seed's measurements run away: the state leaves the valid set
    batch[2, 12, 0] = np.inf  # a bad measurement
    sols = jax.vmap(lambda z: run(model, ts, z, us, x0, P0, present=present, throw=False))(batch)
    codes = np.asarray(sols.result._value)
    assert codes[0] == RESULTS.successful._value
    assert codes[1] == RESULTS.diverged._value and int(sols.failed_sample[1]) == 30
    assert codes[2] == RESULTS.nonfinite_measurement._value
    assert int(sols.failed_sample[2]) == 12
    one = run(model, ts, batch[0], us, x0, P0, present=present)
    np.testing.assert_allclose(sols.outputs.x[0], one.outputs.x, rtol=1e-12, atol=1e-12)
    assert np.all(np.isfinite(sols.outputs.x))  # frozen at the last good values, never NaN
    with pytest.raises(RuntimeError):
        run(model, ts, batch[1], us, x0, P0, present=present).outputs.x.block_until_ready()


def test_gradient_against_finite_differences(data):
    ts, zs, us, x0, P0, present = data
    model = Linear(q=0.3, r=0.05)
    zs = np.nan_to_num(zs, nan=1.0)

    def loss(scale):
        sol = extended_kalman_filter(model, ts, zs * scale, us, x0, P0, present=present)
        return jnp.sum(sol.outputs.x**2)

    g = jax.grad(loss)(1.0)
    h = 1e-6
    fd = (loss(1.0 + h) - loss(1.0 - h)) / (2 * h)
    np.testing.assert_allclose(g, fd, rtol=1e-6)


def test_bad_shapes(data, no_jaxtyping):
    ts, zs, us, x0, P0, present = data
    model = Linear(q=0.3, r=0.05)
    with pytest.raises(ValueError, match="zs"):
        extended_kalman_filter(model, ts, zs[:-1], us, x0, P0)
    with pytest.raises(ValueError, match="P0"):
        extended_kalman_filter(model, ts, zs, us, x0, P0[:3])
    with pytest.raises(ValueError, match="substeps"):
        extended_kalman_filter(model, ts, zs, us, x0, P0, substeps=0)


# ---------------------------------------------------------------------------------------
# The outlier gate


def test_chi2_quantile_against_scipy():
    from scipy.stats import chi2

    from visjax.baselines._ekf import chi2_quantile

    for dof in (1, 2, 3, 6):
        for p in (0.5, 0.9, 0.99, 0.999, 0.999999):
            got = float(chi2_quantile(jnp.asarray(p), dof))
            np.testing.assert_allclose(got, chi2.ppf(p, dof), rtol=1e-9)


@pytest.fixture(scope="module")
def tracked():
    """The linear model simulated (its own noise), then 4 samples replaced by outliers 40
    standard deviations off."""
    rng = np.random.default_rng(11)
    n, dt, q, r = 60, 0.1, 0.5, 0.01
    ts = dt * np.arange(n)
    us = rng.normal(size=(n, 2))
    x = np.array([0.0, 0.0, 1.0, -1.0])
    zs = []
    for k in range(n):
        zs.append(x[:2] + np.sqrt(r) * rng.normal(size=2))
        G = np.concatenate([0.5 * dt**2 * np.eye(2), dt * np.eye(2)])
        F = np.block([[np.eye(2), dt * np.eye(2)], [np.zeros((2, 2)), np.eye(2)]])
        x = F @ x + G @ (us[k] + np.sqrt(q) * rng.normal(size=2))
    zs = np.array(zs)
    bad = np.array([7, 19, 33, 50])
    outliers = zs.copy()
    outliers[bad] += 40.0 * np.sqrt(r) * np.array([1.0, -0.5])
    x0, P0 = np.array([0.0, 0.0, 1.0, -1.0]), np.eye(4)
    return ts, zs, outliers, us, x0, P0, Linear(q=q, r=r), bad


def test_the_gate_rejects_exactly_the_outliers(tracked):
    ts, zs, outliers, us, x0, P0, model, bad = tracked
    missing = outliers.copy()
    missing[bad] = np.nan
    ekf = eqx.filter_jit(extended_kalman_filter)
    gated = ekf(model, ts, outliers, us, x0, P0, gate=0.9999)
    oracle = ekf(model, ts, missing, us, x0, P0)  # the outliers known and left out
    plain = ekf(model, ts, outliers, us, x0, P0)
    assert gated.result == RESULTS.successful
    # the gate finds the 4 outliers and nothing else: the filter that was told
    np.testing.assert_allclose(gated.outputs.x, oracle.outputs.x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(gated.outputs.P, oracle.outputs.P, rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(gated.outputs.rejected, np.cumsum(np.isin(np.arange(60), bad)))
    assert float(oracle.outputs.rejected[-1]) == 0.0
    # without the gate the outliers pull the estimate off: worst position error vs the gated
    clean = ekf(model, ts, zs, us, x0, P0)
    err = lambda s: np.max(np.abs(np.asarray(s.outputs.x[:, :2] - clean.outputs.x[:, :2])))  # noqa: E731
    assert err(plain) > 10 * err(gated)


def test_the_gate_under_vmap_and_its_settings(tracked, no_jaxtyping):
    ts, zs, outliers, us, x0, P0, model, bad = tracked

    def final(p):
        sol = extended_kalman_filter(model, ts, outliers, us, x0, P0, gate=p, throw=False)
        return sol.outputs.rejected[-1], sol.result

    rejected, results = jax.jit(jax.vmap(final))(jnp.array([0.9999, 0.5, 0.0]))
    codes = np.asarray(results._value)
    # a gate at the median rejects about half of the 60 samples
    assert float(rejected[0]) == 4.0 and 15 < float(rejected[1]) < 45
    assert codes[0] == codes[1] == RESULTS.successful._value
    # a probability of 0 is not a gate: a result code under jit, not garbage
    assert codes[2] == RESULTS.invalid_settings._value
    with pytest.raises(ValueError, match="`gate` must be a probability"):
        extended_kalman_filter(model, ts, outliers, us, x0, P0, gate=1.5)
    with pytest.raises(ValueError, match="`gate_size` 3 must divide"):
        extended_kalman_filter(model, ts, outliers, us, x0, P0, gate=0.99, gate_size=3)
