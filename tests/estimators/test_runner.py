"""The runner: zero-order hold, solver steps, saving, reducers, compile-once, errors."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax import RESULTS, result_names
from visjax._results import first_failure
from visjax.estimators import (
    AbstractEstimator,
    AbstractJumpEstimator,
    CheckpointAdjoint,
    DirectAdjoint,
    SaveAt,
    Stream,
    WindowRMS,
    run,
)

TRACES = {"count": 0}


class LinearObserver(AbstractEstimator):
    """ds/dt = -a s + b y: a smooth toy estimator with a gain; Euler-stable for h < 2/a."""

    a: jax.Array = eqx.field(converter=jnp.asarray)
    b: jax.Array = eqx.field(converter=jnp.asarray)

    def init(self, y0):
        return jnp.zeros_like(y0)

    def vector_field(self, t, state, y):
        TRACES["count"] += 1  # runs at trace time only
        return -self.a * state + self.b * y

    def output(self, t, state, y):
        return 2.0 * state

    def checks(self):
        return ((self.a > 0, "`a` must be positive."),)

    def max_stable_dt(self, y):
        return 2.0 / self.a

    def valid(self, state, y):
        return jnp.max(jnp.abs(state)) < 1e6


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


def _reference(est, stream, solver, substeps=1):
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
    sol = run(est, stream, solver=solver, dt=0.01 / substeps)
    outs, final = _reference(est, stream, solver, substeps)
    # `substeps` grid points per sample interval: compare at the samples themselves
    sol_at_samples = sol.outputs[::substeps]
    np.testing.assert_allclose(sol_at_samples, outs, rtol=1e-12, atol=1e-14)
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
        sol = run(Accumulator(), stream, solver=solver, saveat=SaveAt(outputs=False))
        np.testing.assert_allclose(sol.final_state[0], expected, rtol=rtol)


def test_saving_decimation_states_and_reducer():
    est = LinearObserver(a=1.0, b=[1.0, 2.0])
    stream = _stream(200)
    full = run(est, stream, saveat=SaveAt(states=True))
    dec = run(est, stream, saveat=SaveAt(every=20, states=True))
    np.testing.assert_allclose(dec.outputs, full.outputs[::20], rtol=1e-15)
    np.testing.assert_allclose(dec.states, full.states[::20], rtol=1e-15)
    np.testing.assert_allclose(dec.ts, stream.ts[::20])
    assert dec.outputs.shape == (10, 2)
    assert run(est, stream).states is None
    # a chunk that does not divide the steps: the last partial chunk is saved too
    odd = run(est, stream, saveat=SaveAt(every=30))
    np.testing.assert_allclose(odd.outputs, full.outputs[::30], rtol=1e-15)
    red = WindowRMS(0.5, 1.5)
    summ = run(est, stream, saveat=SaveAt(outputs=False), reducer=red)
    assert summ.outputs is None and summ.ts is None
    inside = (stream.ts >= 0.5) & (stream.ts < 1.5)
    np.testing.assert_allclose(
        summ.summary.rms, np.sqrt(np.mean(full.outputs[inside] ** 2, axis=0)), rtol=1e-13
    )
    np.testing.assert_allclose(summ.summary.max, np.max(np.abs(full.outputs[inside]), 0))
    np.testing.assert_allclose(summ.final_state, full.final_state, rtol=1e-15)
    # continuing from a saved state reproduces the rest of the run
    st = run(est, Stream(ts=stream.ts[:101], ys=stream.ys[:101]), saveat=SaveAt(states=True))
    cont = run(est, Stream(ts=stream.ts[100:], ys=stream.ys[100:]), state0=st.states[100])
    np.testing.assert_allclose(cont.outputs, full.outputs[100:], rtol=1e-14)


def test_new_gains_and_windows_never_recompile():
    stream = _stream(100)
    est = LinearObserver(a=1.0, b=[1.0, 1.0])
    run(est, stream, reducer=WindowRMS(0.1, 0.5))
    before = TRACES["count"]
    run(LinearObserver(a=2.5, b=[0.5, 1.0]), stream, reducer=WindowRMS(0.2, 0.9))
    run(LinearObserver(a=3.0, b=[0.5, 1.0]), stream, reducer=WindowRMS(0.3, 0.4))
    assert TRACES["count"] == before  # new Python-float gains and windows reuse the compile


def test_vmap_over_gains_and_streams_and_grad():
    stream = _stream(100)
    f = jax.jit(lambda a: run(LinearObserver(a=a, b=jnp.array([1.0, 1.0])), stream).outputs)
    gains = jnp.linspace(0.5, 3.0, 5)
    batched = jax.vmap(f)(gains)
    for i, a in enumerate(gains):
        np.testing.assert_allclose(batched[i], f(a), rtol=1e-14)
    streams = jax.vmap(lambda s: Stream(ts=stream.ts, ys=stream.ys * s))(jnp.array([1.0, -2.0]))
    out = jax.vmap(lambda s: run(LinearObserver(a=1.0, b=jnp.array([1.0, 1.0])), s).outputs)(
        streams
    )
    np.testing.assert_allclose(out[1], -2.0 * out[0], rtol=1e-13)
    # gradient with respect to the gain, forward and reverse, direct and checkpointed
    loss = lambda a: jnp.sum(f(a) ** 2)  # noqa: E731
    g_rev = jax.grad(loss)(jnp.array(1.0))
    g_fwd = jax.jacfwd(loss)(jnp.array(1.0))
    fd = (loss(jnp.array(1.0 + 1e-6)) - loss(jnp.array(1.0 - 1e-6))) / 2e-6
    np.testing.assert_allclose(g_rev, fd, rtol=1e-6)
    np.testing.assert_allclose(g_fwd, g_rev, rtol=1e-12)

    def loss_ckpt(a, steps):
        sol = run(
            LinearObserver(a=a, b=jnp.array([1.0, 1.0])),
            stream,
            adjoint=CheckpointAdjoint(steps),
            saveat=SaveAt(every=3),
        )
        return jnp.sum(sol.outputs**2)

    for steps in (None, 7):
        g_ck = jax.grad(loss_ckpt)(jnp.array(1.0), steps)
        direct = jax.grad(
            lambda a: jnp.sum(
                run(
                    LinearObserver(a=a, b=jnp.array([1.0, 1.0])), stream, saveat=SaveAt(every=3)
                ).outputs
                ** 2
            )
        )(jnp.array(1.0))
        np.testing.assert_allclose(g_ck, direct, rtol=1e-12)


def test_errors_and_result_codes():
    est = LinearObserver(a=1.0, b=[1.0, 1.0])
    stream = _stream(100)
    with pytest.raises(ValueError, match="samples of `stream.ts` first"):
        run(est, Stream(ts=stream.ts, ys=stream.ys[:50]))
    with pytest.raises(ValueError, match="positive int"):
        SaveAt(every=0)
    with pytest.raises(ValueError, match="`dt` must be a positive"):
        run(est, stream, dt=-1.0)
    # a NaN sample: the run stops there, the state frozen at its last valid value
    bad = Stream(ts=stream.ts, ys=stream.ys.at[10, 0].set(jnp.nan))
    with pytest.raises(RuntimeError, match="measurement sample is not finite"):
        run(est, bad)
    sol = run(est, bad, throw=False, saveat=SaveAt(states=True))
    assert sol.result == RESULTS.nonfinite_measurement and int(sol.failed_sample) == 10
    np.testing.assert_array_equal(sol.final_state, sol.states[10])
    assert np.all(np.isfinite(sol.final_state))
    good = run(est, stream)
    assert good.result == RESULTS.successful and int(good.failed_sample) == -1


def test_settings_and_stability_checks_under_jit_and_vmap():
    stream = _stream(100)  # samples every 10 ms: stable for a < 200
    with pytest.raises(ValueError, match="`a` must be positive"):
        run(LinearObserver(a=-1.0, b=[1.0, 1.0]), stream)
    with pytest.raises(ValueError, match="exceeds the Euler stability bound"):
        run(LinearObserver(a=250.0, b=[1.0, 1.0]), stream)
    run(LinearObserver(a=250.0, b=[1.0, 1.0]), stream, dt=1e-3)  # a smaller step is fine

    # inside a vmapped sweep the values are traced: result codes, per element
    def code(a):
        sol = run(LinearObserver(a=a, b=jnp.array([1.0, 1.0])), stream, throw=False)
        return sol.result._value, sol.failed_sample

    codes, failed = jax.jit(jax.vmap(code))(jnp.array([1.0, -1.0, 250.0, 2.0]))
    expected = [RESULTS.successful, RESULTS.invalid_settings, RESULTS.unstable_step]
    assert [int(c) for c in codes[:3]] == [int(r._value) for r in expected]
    assert int(codes[3]) == int(RESULTS.successful._value)
    assert list(np.asarray(failed)) == [-1, 0, 0, -1]
    with pytest.raises(RuntimeError, match="`a` must be positive"):
        jax.jit(
            jax.vmap(lambda a: run(LinearObserver(a=a, b=jnp.array([1.0, 1.0])), stream).outputs)
        )(jnp.array([1.0, -1.0]))


class Diverging(AbstractEstimator):
    """ds/dt = s: leaves the valid set |s| < 10 at t = ln 10 (states start at 1)."""

    def init(self, y0):
        return jnp.ones_like(y0)

    def vector_field(self, t, state, y):
        return state

    def output(self, t, state, y):
        return state

    def valid(self, state, y):
        return jnp.max(jnp.abs(state)) < 10.0


def test_divergence_is_a_result_code_with_the_sample():
    stream = _stream(400, dt=0.01)
    sol = run(Diverging(), stream, throw=False)
    assert sol.result == RESULTS.diverged
    # Euler: (1.01)^k >= 10 first at k = 232, reached by the step from sample 231
    assert int(sol.failed_sample) == 231
    assert float(jnp.max(sol.final_state)) < 10.0
    with pytest.raises(RuntimeError, match="left its valid set"):
        run(Diverging(), stream)


def test_dt_holds_slow_samples():
    """30 Hz samples under a 1 kHz law: the same as the samples repeated at 1 kHz."""
    est = LinearObserver(a=5.0, b=[1.0, -1.0])
    n_fast = 1000
    fast_ts = jnp.arange(n_fast, dtype=jnp.float64) / 1000
    held = (np.arange(n_fast) * 30) // 1000
    first = np.searchsorted(held, np.arange(held[-1] + 1))
    slow_ts = fast_ts[first]
    slow_ys = jnp.stack([jnp.sin(3 * slow_ts), jnp.cos(2 * slow_ts)], axis=1)
    slow = run(est, Stream(ts=slow_ts, ys=slow_ys), dt=1e-3, saveat=SaveAt(states=True))
    fast = run(est, Stream(ts=fast_ts, ys=slow_ys[held]), saveat=SaveAt(states=True))
    m = slow.states.shape[0]
    assert m == first[-1] + 1  # the grid ends at the last sample
    np.testing.assert_allclose(slow.states, fast.states[:m], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(slow.ts, fast_ts[:m], atol=1e-12)


class FlakySolver(diffrax.AbstractSolver):
    """Euler that reports a diffrax failure code once the state passes 1.5 (a stand-in for a
    solver's own failure, e.g. an implicit solver whose root find diverges)."""

    term_structure = diffrax.AbstractTerm
    interpolation_cls = diffrax.LocalLinearInterpolation

    def order(self, terms):
        return 1

    def init(self, terms, t0, t1, y0, args):
        return None

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        y1 = jax.tree_util.tree_map(lambda y, d: y + (t1 - t0) * d, y0, terms.vf(t0, y0, args))
        bad = jnp.max(jnp.abs(y1)) > 1.5
        r = diffrax.RESULTS.where(
            bad, diffrax.RESULTS.nonlinear_divergence, diffrax.RESULTS.successful
        )
        return y1, None, dict(y0=y0, y1=y1), None, r

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)


def test_the_solvers_own_result_code_is_kept():
    sol = run(Diverging(), _stream(400, dt=0.01), solver=FlakySolver(), throw=False)
    assert sol.result == RESULTS.promote(diffrax.RESULTS.nonlinear_divergence)
    assert int(sol.failed_sample) == 40  # (1.01)^41 > 1.5 first from sample 40


def test_dropped_samples_are_held_over():
    """`Stream.present`: a dropped sample (NaN or not) is as if it never arrived: the
    previous present sample is held, exactly as a stream without it, and the reducer's
    truth stays at the grid's own sample."""
    est = LinearObserver(a=5.0, b=[1.0, -1.0])
    stream = _stream(200)
    rng = np.random.default_rng(0)
    present = rng.random(200) > 0.1
    present[0] = True
    latest = np.maximum.accumulate(np.where(present, np.arange(200), 0))
    ys = np.asarray(stream.ys).copy()
    ys[~present] = np.nan  # a dropped sample may hold anything
    dropped = Stream(ts=stream.ts, ys=jnp.asarray(ys), truth=stream.truth, present=present)
    held = Stream(ts=stream.ts, ys=stream.ys[latest], truth=stream.truth)
    for dt in (None, 2.5e-3):
        a = run(est, dropped, dt=dt, saveat=SaveAt(states=True))
        b = run(est, held, dt=dt, saveat=SaveAt(states=True))
        assert a.result == RESULTS.successful
        np.testing.assert_allclose(a.states, b.states, rtol=1e-13, atol=1e-15)
    # the reducer scores against the truth of the arrived sample, not the held one
    truth = stream.ys  # the signal itself as "truth" of 2 * state
    red = WindowRMS(0.0, 2.0)
    a = run(est, Stream(ts=stream.ts, ys=dropped.ys, truth=truth, present=present), reducer=red)
    b = run(est, Stream(ts=stream.ts, ys=held.ys, truth=truth), reducer=red)
    np.testing.assert_allclose(a.summary.rms, b.summary.rms, rtol=1e-12)
    c = run(est, Stream(ts=stream.ts, ys=held.ys, truth=truth[latest]), reducer=red)
    assert not np.allclose(a.summary.rms, c.summary.rms, rtol=1e-6)
    # the first sample must be present; a wrong shape is refused
    first_missing = present.copy()
    first_missing[0] = False
    with pytest.raises(ValueError, match="first sample"):
        run(est, Stream(ts=stream.ts, ys=stream.ys, present=first_missing))
    with pytest.raises(ValueError, match="present"):
        run(est, Stream(ts=stream.ts, ys=stream.ys, present=present[:10]))


@pytest.mark.parametrize(  # the second: the unit tier's time
    "saveat", [SaveAt(states=True), pytest.param(SaveAt(every=7), marks=pytest.mark.slow)]
)
def test_unrolled_loop_gives_the_same_run(saveat):
    """`unroll` changes how many steps one loop iteration holds, not the run: outputs,
    states, reducer and result code equal the plain loop's, also for a failing run, under
    `vmap`, and in the gradient (direct and checkpointed, where the blocks are unrolled)."""
    stream = _stream(103)  # no multiple of any unroll below
    est = LinearObserver(a=1.5, b=[1.0, -0.5])
    red = WindowRMS(0.2, 0.8)
    plain = run(est, stream, saveat=saveat, reducer=red)
    for unroll in (3, 200):  # neither divides the 102 steps; 200 holds them all
        sol = run(est, stream, saveat=saveat, reducer=red, unroll=unroll)
        np.testing.assert_allclose(sol.outputs, plain.outputs, rtol=1e-15, atol=1e-300)
        np.testing.assert_allclose(sol.summary.rms, plain.summary.rms, rtol=1e-15)
        np.testing.assert_allclose(sol.final_state, plain.final_state, rtol=1e-15)
    # a run that diverges at a sample: the same result code, sample and frozen state
    bad = jnp.where(stream.ts >= 0.5, 1e9, 1.0)[:, None] * stream.ys
    failing = Stream(ts=stream.ts, ys=bad)
    ref = run(est, failing, saveat=saveat, throw=False)
    sol = run(est, failing, saveat=saveat, throw=False, unroll=8)
    assert ref.result == RESULTS.diverged and sol.result == ref.result
    assert int(sol.failed_sample) == int(ref.failed_sample) == 50
    np.testing.assert_allclose(sol.final_state, ref.final_state, rtol=1e-15)
    if saveat.every == 1:
        return  # the gradient once, with decimated saving (the more intricate case)
    # vmap over gains and the gradient, both adjoints
    gains = jnp.array([0.7, 1.5, 2.5])

    def loss(a, unroll, adjoint):
        sol = run(LinearObserver(a=a, b=jnp.array([1.0, 1.0])), stream, saveat=saveat,
                  adjoint=adjoint, unroll=unroll)  # fmt: skip
        return jnp.sum(sol.outputs**2)

    for adjoint in (DirectAdjoint(), CheckpointAdjoint(9)):
        grads = [jax.vmap(jax.grad(loss), (0, None, None))(gains, u, adjoint) for u in (1, 4)]
        np.testing.assert_allclose(grads[1], grads[0], rtol=1e-13)
        assert np.all(np.isfinite(grads[0])) and np.all(grads[0] != 0)
    with pytest.raises(ValueError, match="`unroll` must be a positive int"):
        run(est, stream, unroll=0)


def test_result_names_of_a_run_and_of_a_batch():
    from visjax import result_names

    est = LinearObserver(a=1.0, b=[1.0, 1.0])
    stream = _stream(40)
    bad = Stream(ts=stream.ts, ys=stream.ys.at[10, 0].set(jnp.nan))
    assert result_names(run(est, bad, throw=False).result) == "nonfinite_measurement"
    both = jax.vmap(lambda ys: run(est, Stream(ts=stream.ts, ys=ys), throw=False).result)(
        jnp.stack([stream.ys, bad.ys])
    )
    assert result_names(both) == ["successful", "nonfinite_measurement"]


class CountingJumps(AbstractJumpEstimator):
    """Counts the samples that arrived (`jump`) and integrates the held sample."""

    def init(self, y0):
        return jnp.zeros(2, y0.dtype)

    def vector_field(self, t, state, y):
        return jnp.stack([jnp.zeros((), y.dtype), y[0]])

    def jump(self, state, y):
        return state.at[0].add(1.0)

    def output(self, t, state, y):
        return state


def test_the_contract_is_abstract_and_jump_is_a_declared_capability():
    """A subclass missing a required method cannot be built; `jump` fires once per new
    present sample (not per grid step, not for a dropped sample) and only for an
    `AbstractJumpEstimator`."""

    class NoOutput(AbstractEstimator):
        def init(self, y0):
            return y0

        def vector_field(self, t, state, y):
            return state

    with pytest.raises(TypeError, match="output"):
        NoOutput()

    class NoJump(AbstractJumpEstimator):
        def init(self, y0):
            return y0

        def vector_field(self, t, state, y):
            return state

        def output(self, t, state, y):
            return state

    with pytest.raises(TypeError, match="jump"):
        NoJump()

    n = 50
    ts = jnp.arange(n, dtype=jnp.float64) * 0.01
    ys = jnp.ones((n, 1))
    present = np.ones(n, bool)
    present[[5, 6, 20]] = False
    for dt, keep in ((None, None), (0.001, None), (None, present), (0.001, present)):
        sol = run(CountingJumps(), Stream(ts=ts, ys=ys, present=keep), dt=dt)
        arrived = n if keep is None else int(keep.sum())
        # every present sample fires the jump once, the first included
        assert float(sol.final_state[0]) == arrived
        # the held sample (1.0) integrated over the run, whatever the grid
        assert float(sol.final_state[1]) == pytest.approx(float(ts[-1] - ts[0]), rel=1e-12)
    # the jump-free estimator integrates the same and has no jump to fire
    assert not isinstance(Accumulator(), AbstractJumpEstimator)


def test_first_failure_keeps_the_first_code_and_sample():
    codes = [RESULTS.successful, RESULTS.diverged, RESULTS.successful, RESULTS.nonfinite_state]

    def loop(codes_value):
        result, failed = RESULTS.successful, jnp.array(-1, jnp.int32)
        for k in range(4):
            code = RESULTS.where(codes_value[k], codes[k], RESULTS.successful)
            result, failed = first_failure(result, failed, code, k)
        return result, failed

    result, failed = jax.jit(loop)(jnp.array([True] * 4))
    assert result_names(result) == "diverged" and int(failed) == 1
    assert failed.dtype == jnp.int32
    batch = jax.vmap(loop)(jnp.array([[True] * 4, [True, False, True, True], [False] * 4]))
    assert result_names(batch[0]) == ["diverged", "nonfinite_state", "successful"]
    assert batch[1].tolist() == [1, 3, -1]


def test_integration_step_is_one_rule():
    """The sample times when every interval is within the cap and the Euler bound; else
    min(cap, bound / 2); the chosen step runs without the runner's refusal."""
    from visjax.estimators import integration_step

    stream = _stream(n=50, dt=0.01)  # 100 Hz
    slow = LinearObserver(a=jnp.array(10.0), b=jnp.array(1.0))  # bound 0.2 s
    fast = LinearObserver(a=jnp.array(1000.0), b=jnp.array(1.0))  # bound 2 ms
    assert integration_step(stream) is None
    assert integration_step(stream, slow) is None
    assert integration_step(stream, slow, max_step=1e-3) == 1e-3
    assert integration_step(stream, fast) == pytest.approx(1e-3)  # half of 2 ms
    assert integration_step(stream, fast, max_step=5e-4) == 5e-4
    dt = integration_step(stream, fast)
    assert run(fast, stream, dt=dt).result == RESULTS.successful
    with pytest.raises(ValueError, match="Euler stability bound"):
        run(fast, stream)  # the sample times are refused for these gains
    # `dt="auto"` is that rule; with the gains traced (vmap over gains) the sample times,
    # and a gain past its bound is the run's result code
    auto = run(fast, stream, dt="auto")
    np.testing.assert_array_equal(auto.final_state, run(fast, stream, dt=dt).final_state)
    assert run(slow, stream, dt="auto").ts.shape == (50,)

    def batched(a):
        return run(LinearObserver(a=a, b=jnp.array(1.0)), stream, dt="auto", throw=False)

    codes = jax.vmap(batched)(jnp.array([10.0, 1000.0])).result
    assert result_names(codes) == ["successful", "unstable_step"]
    with pytest.raises(ValueError, match='"auto"'):
        run(fast, stream, dt="fast")
    with pytest.raises(ValueError, match="no stable step"):
        integration_step(stream, LinearObserver(a=jnp.array(jnp.inf), b=jnp.array(1.0)))
    with pytest.raises(ValueError, match="max_step"):
        integration_step(stream, max_step=0.0)


def test_window_rms_over_a_saved_trajectory_equals_the_reducer_and_skips_nan_on_request():
    """`WindowRMS.over` (a baseline's or a data file's saved trajectory) is the in-loop
    reducer's summary; a NaN error makes it NaN (a failed run is never scored) unless
    `skip_nan`, which leaves out each NaN component on its own."""
    window = WindowRMS(1.0, 3.0)
    ts = jnp.arange(5.0)
    est = jnp.array([[9.0, 9.0], [1.0, 2.0], [3.0, jnp.nan], [4.0, 4.0], [9.0, 9.0]])
    truth = jnp.zeros((5, 2))
    acc = window.init(est[0], truth[0])
    for k in range(5):
        acc = window.update(acc, ts[k], est[k], truth[k])
    assert np.isnan(float(acc.rms[1])) and float(acc.rms[0]) == np.sqrt(5.0)
    over = window.over(ts, est, truth)
    np.testing.assert_array_equal(over.rms, acc.rms)
    skipped = window.over(ts, est, truth, skip_nan=True)
    np.testing.assert_allclose(skipped.rms, [np.sqrt(5.0), 2.0], rtol=1e-15)
    np.testing.assert_array_equal(skipped.count, [2.0, 1.0])
    np.testing.assert_array_equal(skipped.max, [3.0, 2.0])
