"""Seed 003: the perspective dynamics, the unknown input observer and its checks."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax import RESULTS
from visjax.estimators import (
    AbstractEstimator,
    MovingPointEstimator,
    SaveAt,
    rank_condition,
    run,
)
from visjax.kinematics import camera_term, known_input_term
from visjax.papers.jang import SETS, observer as observer_for, scenario as moving_camera_scenario

C = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def test_rank_condition_fails_where_it_should():
    D = np.array([[1.0], [0.0], [0.0]])
    assert not rank_condition(np.zeros((3, 3)), C, D)  # (M0 A, C) unobservable
    assert not rank_condition(np.eye(3), C, np.array([[0.0], [0.0], [1.0]]))  # C D = 0


class OrdinaryObserver(AbstractEstimator):
    """x_hat_dot = f(x_hat, u) + g(y, u) + K (y - C x_hat): a Thau-type observer."""

    K: jax.Array
    x3_guess: jax.Array

    def init(self, y0):
        return jnp.concatenate([y0.y, self.x3_guess[None]])

    def vector_field(self, t, x_hat, meas):
        y, u = meas.y, meas.u
        return camera_term(x_hat, u) + known_input_term(y, u) + self.K @ (y - x_hat[:2])

    def output(self, t, x_hat, meas):
        return x_hat


def test_reduction_oracle_without_unknown_input():
    """Static point, D unused (D = 0, Y = 0): E = 0, M = I, N = A - KC, L = K, and (3.5) is
    the ordinary nonlinear observer on the same data. (The thesis' K of set I.1 leaves
    A - KC with an eigenvalue of +0.011, which the UIO's check refuses: a third row that
    makes it Hurwitz is used.)"""
    s = SETS["I.1"]
    sc = moving_camera_scenario("I.1", 3.0)
    K = jnp.array(s.K).at[2].set(jnp.array([-0.5, -1.0]))
    uio = MovingPointEstimator(
        A=jnp.array(s.A, float),
        D=jnp.zeros((3, 1)),
        K=K,
        Y=jnp.zeros((3, 2)),
        x3_guess=jnp.array(0.01),
    )
    stream = sc.held_stream()
    a = run(uio, stream).outputs.x_hat
    b = run(OrdinaryObserver(K=K, x3_guess=jnp.array(0.01)), stream).outputs
    np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-13)


@pytest.mark.slow
def test_vmap_over_seeds_and_sets_and_grad():
    names = ["II.1", "II.2"]
    scs = [moving_camera_scenario(n, 1.0) for n in names]
    streams = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *[s.held_stream() for s in scs])
    observers = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *[observer_for(n) for n in names])
    both = jax.vmap(lambda o, st: run(o, st, saveat=SaveAt(every=100)).outputs.x_hat)(
        observers, streams
    )
    for i, n in enumerate(names):
        one = run(observer_for(n), scs[i].held_stream(), saveat=SaveAt(every=100))
        np.testing.assert_allclose(both[i], one.outputs.x_hat, rtol=1e-12)

    # noise seeds: scenario and run under vmap
    def final_error(key):
        sc = moving_camera_scenario("I.1", 1.0, noise_px=0.5, key=key)
        out = run(observer_for("I.1"), sc.held_stream(), saveat=SaveAt(every=100))
        return out.outputs.x_hat[-1] - sc.x[-1]

    keys = jax.random.split(jax.random.key(0), 3)
    errs = jax.vmap(final_error)(keys)
    np.testing.assert_allclose(errs[1], final_error(keys[1]), rtol=1e-10)
    assert not np.allclose(errs[0], errs[1])
    # gradients of a state loss with respect to the gains
    sc = scs[0]
    stream = sc.held_stream()

    def loss(K, Y):
        o = observer_for("II.1", K=K, Y=Y)
        return jnp.sum((run(o, stream, saveat=SaveAt(every=100)).outputs.x_hat - sc.x[::100]) ** 2)

    K0, Y0 = jnp.array(SETS["II.1"].K), jnp.array(SETS["II.1"].Y, float)
    gK, gY = jax.grad(loss, argnums=(0, 1))(K0, Y0)
    # With the thesis' structure C E = -I: M zeroes the first two rows, z_1,2 starts at 0
    # and stays there, and K only multiplies C z = 0. The gradient in K is finite and zero;
    # the depth's convergence is set by Y (through M A).
    assert np.all(np.isfinite(gK)) and np.all(gK == 0)
    E, _, _, _ = observer_for("II.1")._matrices()
    np.testing.assert_allclose(np.asarray(C @ E), -np.eye(2), atol=1e-15)
    assert np.all(np.isfinite(gY)) and abs(gY[2, 1]) > 0
    h = 1e-5
    fd = (loss(K0, Y0.at[2, 1].add(h)) - loss(K0, Y0.at[2, 1].add(-h))) / (2 * h)
    np.testing.assert_allclose(gY[2, 1], fd, rtol=1e-5)


def test_observer_shape_errors():
    with pytest.raises(ValueError, match=r"`K` must have shape \(3, 2\)"):
        MovingPointEstimator(
            A=jnp.zeros((3, 3)),
            D=jnp.zeros((3, 1)),
            K=jnp.zeros((2, 2)),
            Y=jnp.zeros((3, 2)),
            x3_guess=jnp.array(0.01),
        )


def test_divergence_cases_end_with_a_result_code():
    """x3_guess = 0 (an infinite depth guess): a result code naming the sample, an error
    with `throw=True` (version 1 reported it as successful). The divergence of a long run
    is the slow test below."""
    sc = moving_camera_scenario("II.3", 1.0)
    stream = sc.held_stream()
    bad_guess = eqx.tree_at(lambda o: o.x3_guess, observer_for("II.3"), jnp.asarray(0.0))
    with pytest.raises(ValueError, match="`x3_guess`"):
        run(bad_guess, stream)
    sol = jax.jit(lambda o: run(o, stream, throw=False))(bad_guess)
    assert sol.result == RESULTS.invalid_settings and int(sol.failed_sample) == 0


@pytest.mark.slow  # a 200 s run at 1 kHz: product scale
def test_set_II3_diverges_with_a_result_code_and_a_frozen_state():
    """Set II.3 run for 200 s: the depth estimate goes negative after about 44 s (version 1:
    8e4 m positions reported as successful)."""
    long = moving_camera_scenario("II.3", 200.0).held_stream()
    out = run(observer_for("II.3"), long, saveat=SaveAt(outputs=False), throw=False)
    assert out.result == RESULTS.diverged
    k = int(out.failed_sample)
    assert 0 < k < long.ts.shape[0]
    z_last = out.final_state.z - observer_for("II.3")._matrices()[0] @ long.ys.y[k - 1]
    assert float(z_last[2]) > 0  # frozen at the last valid state: depth still positive
    with pytest.raises(RuntimeError, match="left its valid set"):
        run(observer_for("II.3"), long, saveat=SaveAt(outputs=False))


def test_30hz_frames_with_dt_equal_the_held_1khz_stream():
    sc = moving_camera_scenario("I.2", 1.0, noise_px=0.1, key=jax.random.key(3))
    held = run(observer_for("I.2"), sc.held_stream(), saveat=SaveAt(states=True))
    cam = run(observer_for("I.2"), sc.camera_stream(), dt=1e-3, saveat=SaveAt(states=True))
    m = cam.states.z.shape[0]
    assert sc.camera_stream().ts.shape[0] == 30
    np.testing.assert_allclose(cam.states.z, held.states.z[:m], rtol=1e-12)
    with pytest.raises(ValueError, match="exceeds the Euler stability bound"):
        run(observer_for("I.2"), sc.camera_stream(), dt=2.0)


def test_the_rank_condition_is_checked_by_the_observer_and_the_design():
    from visjax.design import design_uio

    s = SETS["I.1"]
    good = observer_for("I.1")
    assert bool(good._rank_condition())
    A0 = jnp.zeros((3, 3))  # (M0 A, C) unobservable
    bad = eqx.tree_at(lambda o: o.A, good, A0)
    assert not bool(bad._rank_condition())
    failing = [message for ok, message in bad.checks() if not bool(ok)]
    assert any("rank condition (3.20)" in message for message in failing)
    stream = moving_camera_scenario("I.1", 1.0).held_stream()
    with pytest.raises(ValueError, match="MovingPointEstimator"):
        run(bad, stream)
    with pytest.raises(ValueError, match=r"rank condition \(3.20\)"):
        design_uio(np.zeros((3, 3)), C, np.array(s.D, float)[:, None], 1.0)
    # the JAX check agrees with the NumPy one on the thesis' sets
    for name in SETS:
        o = observer_for(name)
        assert bool(o._rank_condition()) == rank_condition(o.A, o.C, o.D)


def test_D_as_a_vector_and_the_new_fields_defaults():
    """`D` given as (3,) is the (3, 1) column; `D2`, `A_u`, `K_u`, `P` default to zero (the
    thesis' observer, unchanged); wrong shapes of the new fields are refused by name."""
    from visjax.estimators import moving_point_stream

    s = SETS["II.1"]
    col = observer_for("II.1")
    vec = MovingPointEstimator(A=s.A, D=np.array(s.D, float), K=s.K, Y=s.Y, x3_guess=0.01)
    assert vec.D.shape == (3, 1) and vec.D2.shape == (3, 1)
    assert not bool(vec.time_varying)
    assert np.all(np.asarray(vec.disturbance_input()) == 0)
    sc = moving_camera_scenario("II.1", 1.0)
    a = run(col, sc.camera_stream(), dt=1e-3, saveat=SaveAt(every=50)).outputs.x_hat
    b = run(vec, sc.camera_stream(), dt=1e-3, saveat=SaveAt(every=50)).outputs.x_hat
    np.testing.assert_array_equal(a, b)
    fields = dict(A=s.A, D=s.D, K=s.K, Y=s.Y, x3_guess=0.01)
    for name, shape in (("D2", (2,)), ("A_u", (3, 3)), ("K_u", (6, 2, 3)), ("P", (3,))):
        with pytest.raises(ValueError, match=f"`{name}` must have shape"):
            MovingPointEstimator(**fields, **{name: np.zeros(shape)})
    # a dropped first frame has nothing to hold: the builder raises, or the run still
    # stops at sample 0
    pixels = np.asarray(sc.frame_pixels).copy()
    pixels[0, 1] = np.nan
    args = (sc.frame_ts, pixels, sc.frame_velocities, sc.Kc_observer)
    with pytest.raises(RuntimeError, match="sample 0"):
        moving_point_stream(*args, dropped="hold")
    stream = moving_point_stream(*args, dropped="hold", throw=False)
    out = run(col, stream, dt=1e-3, saveat=SaveAt(outputs=False), throw=False)
    assert out.result == RESULTS.nonfinite_measurement and int(out.failed_sample) == 0


def test_moving_point_innovation_against_a_transcription():
    """Issue 44: the observer's output error at each frame, y - [x1_hat, x2_hat] with the
    estimate saved at or before the frame, against the frames' noise (changes / sqrt 2).
    An estimate on the noise-free point has ratio about 1; one 10 sigma off, about 10."""
    from visjax.estimators import moving_point_innovation

    rng = np.random.default_rng(0)
    K = np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]])
    frame_ts = np.arange(60) / 30.0
    y = np.stack([0.1 + 0.01 * np.sin(frame_ts), -0.05 + 0.01 * np.cos(frame_ts)], 1)
    sigma = 0.5 / 800.0
    noisy = y + sigma * rng.standard_normal(y.shape)
    pixels = noisy * 800.0 + np.array([320.0, 240.0])
    ts = np.arange(0, 2.0, 1e-3)
    truth = np.stack([np.interp(ts, frame_ts, y[:, 0]), np.interp(ts, frame_ts, y[:, 1])], 1)
    for offset, low, high in [(0.0, 0.6, 1.4), (10 * sigma, 8.0, 12.5)]:
        x_hat = np.c_[truth + offset, np.ones(len(ts))]
        inn = moving_point_innovation(frame_ts, pixels, K, ts, x_hat)
        k = np.searchsorted(ts, frame_ts + 1e-9, side="right") - 1
        error = noisy - x_hat[k, :2]
        noise = np.sqrt(np.mean(np.diff(noisy, axis=0) ** 2, axis=0) / 2)
        want = np.max(np.sqrt(np.mean(error**2, axis=0)) / noise)
        np.testing.assert_allclose(float(inn.ratio), want, rtol=1e-9)
        assert low < want < high, want
