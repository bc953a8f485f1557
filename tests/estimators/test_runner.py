"""The runner: zero-order hold, solver steps, saving, reducers, compile-once, errors."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax import RESULTS
from visjax.estimators import AbstractEstimator, Stream, run, summary_rms, window_rms_reducer

TRACES = {"count": 0}


class LinearObserver(AbstractEstimator):
    """ds/dt = -a s + b y: a smooth toy estimator with a gain."""

    a: jax.Array
    b: jax.Array

    def init(self, y0):
        return jnp.zeros_like(y0)

    def vector_field(self, t, state, y):
        TRACES["count"] += 1  # runs at trace time only
        return -self.a * state + self.b * y

    def output(self, t, state, y):
        return 2.0 * state


class Accumulator(AbstractEstimator):
    """ds/dt = y: integrates the held samples, to check the hold."""

    def init(self, y0):
        return jnp.zeros_like(y0)

    def vector_field(self, t, state, y):
        return y

    def output(self, t, state, y):
        return state


def _stream(n=200, dt=0.01, dtype=jnp.float64):
    ts = jnp.arange(n, dtype=dtype) * dt
    ys = jnp.stack([jnp.sin(3 * ts), jnp.cos(2 * ts)], axis=1)
    return Stream(ts=ts, ys=ys, truth=jnp.zeros_like(ys))


def _reference(est, stream, solver, substeps):
    """The same zero-order hold with one diffeqsolve per sample interval."""
    ts, ys = np.asarray(stream.ts), stream.ys
    state = est.init(ys[0])
    outs = []
    term = diffrax.ODETerm(lambda t, s, y: est.vector_field(t, s, y))
    for k in range(len(ts)):
        outs.append(est.output(ts[k], state, ys[k]))
        if k + 1 < len(ts):
            sol = diffrax.diffeqsolve(
                term,
                solver,
                ts[k],
                ts[k + 1],
                (ts[k + 1] - ts[k]) / substeps,
                state,
                args=ys[k],
                stepsize_controller=diffrax.ConstantStepSize(),
                saveat=diffrax.SaveAt(t1=True),
            )
            state = sol.ys[0]
    return jnp.stack(outs), state


@pytest.mark.parametrize("solver,substeps", [(diffrax.Euler(), 1), (diffrax.Tsit5(), 3)])
def test_scan_core_matches_diffeqsolve(solver, substeps):
    est = LinearObserver(a=jnp.array(1.5), b=jnp.array([1.0, -0.5]))
    stream = _stream(60)
    sol = run(est, stream, solver=solver, substeps=substeps)
    outs, final = _reference(est, stream, solver, substeps)
    np.testing.assert_allclose(sol.outputs, outs, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(sol.final_state, final, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_hold_uses_the_exact_sample_index(dtype):
    """y_k = k held over [t_k, t_k+1): the integral is dt * sum(k) whatever the rounding of t."""
    n, dt = 3000, 1e-3
    ts = jnp.arange(n, dtype=dtype) * jnp.asarray(dt, dtype)
    # the trap: floor(t / dt) is not the sample index for many samples
    assert np.any(np.floor(np.asarray(ts) / np.asarray(dt, dtype)).astype(int) != np.arange(n))
    ys = jnp.arange(n, dtype=dtype)[:, None]
    stream = Stream(ts=ts, ys=ys)
    h = np.diff(np.asarray(ts, np.float64))
    expected = np.sum(h * np.arange(n - 1))
    rtol = 1e-5 if dtype == jnp.float32 else 1e-12
    for solver in (diffrax.Euler(), diffrax.Heun(), diffrax.Tsit5()):
        # multi-stage solvers see only the held sample: same integral as Euler
        sol = run(Accumulator(), stream, solver=solver, save_every=None)
        np.testing.assert_allclose(sol.final_state[0], expected, rtol=rtol)


def test_saving_decimation_states_and_reducer():
    est = LinearObserver(a=jnp.array(1.0), b=jnp.array([1.0, 2.0]))
    stream = _stream(200)
    full = run(est, stream, save_states=True)
    dec = run(est, stream, save_every=20, save_states=True)
    np.testing.assert_allclose(dec.outputs, full.outputs[::20], rtol=1e-15)
    np.testing.assert_allclose(dec.states, full.states[::20], rtol=1e-15)
    np.testing.assert_allclose(dec.ts, stream.ts[::20])
    assert dec.outputs.shape == (10, 2)
    assert run(est, stream).states is None
    red = window_rms_reducer(0.5, 1.5)
    summ = run(est, stream, save_every=None, reducer=red)
    assert summ.outputs is None
    inside = (stream.ts >= 0.5) & (stream.ts < 1.5)
    np.testing.assert_allclose(
        summary_rms(summ.summary), np.sqrt(np.mean(full.outputs[inside] ** 2, axis=0)), rtol=1e-13
    )
    np.testing.assert_allclose(summ.summary["max"], np.max(np.abs(full.outputs[inside]), 0))
    np.testing.assert_allclose(summ.final_state, full.final_state, rtol=1e-15)
    # continuing from a saved state reproduces the rest of the run
    st = run(est, Stream(ts=stream.ts[:101], ys=stream.ys[:101]), save_states=True).states[100]
    cont = run(est, Stream(ts=stream.ts[100:], ys=stream.ys[100:]), state0=st)
    np.testing.assert_allclose(cont.outputs, full.outputs[100:], rtol=1e-14)


def test_vmap_over_gains_and_streams_compiles_once():
    stream = _stream(100)
    f = jax.jit(lambda a: run(LinearObserver(a=a, b=jnp.array([1.0, 1.0])), stream).outputs)
    f(jnp.array(1.0))
    before = TRACES["count"]
    f(jnp.array(2.0))
    assert TRACES["count"] == before  # a new gain value reuses the compiled run
    gains = jnp.linspace(0.5, 3.0, 5)
    batched = jax.vmap(f)(gains)
    for i, a in enumerate(gains):
        np.testing.assert_allclose(batched[i], f(a), rtol=1e-14)
    streams = jax.vmap(lambda s: Stream(ts=stream.ts, ys=stream.ys * s))(jnp.array([1.0, -2.0]))
    out = jax.vmap(
        lambda s: run(LinearObserver(a=jnp.array(1.0), b=jnp.array([1.0, 1.0])), s).outputs
    )(streams)
    np.testing.assert_allclose(out[1], -2.0 * out[0], rtol=1e-13)
    # gradient with respect to the gain, forward and reverse
    loss = lambda a: jnp.sum(f(a) ** 2)  # noqa: E731
    g_rev = jax.grad(loss)(jnp.array(1.0))
    g_fwd = jax.jacfwd(loss)(jnp.array(1.0))
    fd = (loss(jnp.array(1.0 + 1e-6)) - loss(jnp.array(1.0 - 1e-6))) / 2e-6
    np.testing.assert_allclose(g_rev, fd, rtol=1e-6)
    np.testing.assert_allclose(g_fwd, g_rev, rtol=1e-12)


def test_errors():
    est = LinearObserver(a=jnp.array(1.0), b=jnp.array([1.0, 1.0]))
    stream = _stream(100)
    with pytest.raises(ValueError, match="must divide"):
        run(est, stream, save_every=7)
    with pytest.raises(ValueError, match="samples of `stream.ts` first"):
        run(est, Stream(ts=stream.ts, ys=stream.ys[:50]))
    with pytest.raises(ValueError, match="substeps"):
        run(est, stream, substeps=0)
    bad = Stream(ts=stream.ts, ys=stream.ys.at[10, 0].set(jnp.nan))
    with pytest.raises(Exception, match="non-finite"):
        run(est, bad)
    assert run(est, bad, throw=False).result == RESULTS.nonfinite_state
