"""Every gain's step bound, `rho` too; divergence by growth; the step count bounded before
anything is allocated (issue: "no silent garbage from plausible mistakes").

Version 1 checked only `K`'s Euler bound: `rho = 1e9` ran "successfully" to 1.6e7 rad/s
(the state stayed below the 1e8 bound), and a large `K` in a data file asked
`integration_step` for a step of 1e-12 s, i.e. terabytes of saved outputs."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax._results import result_names
from visjax.estimators import (
    FixedCamera,
    SaveAt,
    VelocityEstimator,
    VelocityState,
    _base,
    integration_step,
    run,
    velocity_stream,
)
from visjax.papers.chitrakaran import K_EQ63, RHO_EQ63, section6_scenario

K = jnp.array(K_EQ63)
RHO = jnp.array(RHO_EQ63)
BIG_RHO = jnp.full(6, 1e9)


def _camera(sc):
    return FixedCamera(sc.pixels[0], sc.A, sc.R_star, sc.s[0], sc.n_star, sc.z1_star)


@pytest.fixture(scope="module")
def short():
    """0.3 s of section 6 at the paper's 1 kHz, clean and with 1 px of pixel noise."""
    sc = section6_scenario(0.3, 1000.0)
    noisy = sc.pixels + jax.random.normal(jax.random.key(7), sc.pixels.shape)
    stream = velocity_stream(sc.ts, sc.pixels, _camera(sc), throw=False)
    return sc, stream, noisy


@pytest.fixture(scope="module")
def frames30():
    """2 s of section 6 at 30 Hz (60 frames): what a data file holds."""
    sc = section6_scenario(2.0, 30.0)
    return velocity_stream(sc.ts, sc.pixels, _camera(sc))


def _codes(sol):
    return result_names(sol.result), [int(k) for k in np.asarray(sol.failed_sample)]


def test_rho_is_refused_concretely_and_growth_is_checked(short):
    """rho = 1e9 at 1 kHz: a `ValueError` naming `rho`, its bound and the step, before
    anything runs; `valid` flags an estimate that left its signal while the state is far
    below the fixed 1e8 bound."""
    _, stream, _ = short
    with pytest.raises(ValueError, match=r"step 0\.001 s exceeds the chattering bound of `rho`"):
        run(VelocityEstimator(K=K, rho=BIG_RHO), stream)
    y0 = stream.measurement(0)
    est = VelocityEstimator(K=K, rho=BIG_RHO)
    state = VelocityState(e_hat=y0.e.at[4].add(1e3), eta=jnp.full(6, 1e6))
    assert bool(est.valid(state)) and not bool(est.valid(state, y0))


@pytest.mark.slow  # a vmapped velocity run of four elements: the unit tier's time
def test_rho_is_flagged_in_vmap(short):
    """Inside a vmapped run rho = 1e9 at 1 kHz gives `chattering_step` at sample 0 for that
    element only. Beside it the paper's gains (clean and with 1 px of noise) succeed, and an
    estimate 1e3 rad from the signal (a state far below the 1e8 bound) is `diverged` at
    sample 0."""
    sc, stream, noisy = short
    offset = jnp.zeros(6).at[3].set(1e3)  # 1e3 rad on e_omega: |e_hat| < 1e8 still

    def one(rho, pixels, off):
        s = eqx.tree_at(lambda s: s.ys, stream, pixels)
        y0 = s.measurement(0)
        state0 = VelocityState(e_hat=y0.e + off, eta=jnp.zeros(6))  # init's, plus `off`
        est = VelocityEstimator(K=K, rho=rho)
        return run(est, s, state0=state0, saveat=SaveAt(outputs=False), throw=False)

    rhos = jnp.stack([RHO, RHO, BIG_RHO, RHO])
    pixels = jnp.stack([sc.pixels, noisy, sc.pixels, sc.pixels])
    offsets = jnp.stack([jnp.zeros(6), jnp.zeros(6), jnp.zeros(6), offset])
    sol = jax.vmap(one)(rhos, pixels, offsets)
    names, failed = _codes(sol)
    assert names == ["successful", "successful", "chattering_step", "diverged"]
    assert failed == [-1, -1, 0, 0]
    # the old state bound alone would not have flagged the offset estimate
    assert float(jnp.max(jnp.abs(sol.final_state.e_hat[3]))) < 1e8


@pytest.mark.slow  # a vmapped Heun run: the unit tier's time
def test_divergence_by_growth_where_the_state_bound_misses(short):
    """Heun (no step bound is applied to it): rho = 1e9 chatters by ~1e3 rad per step and
    K x 10 grows geometrically. Both stop with `diverged` within the first steps, with the
    state far below the old 1e8 bound; the paper's gains beside them succeed."""
    _, stream, _ = short

    def one(k, rho):
        est = VelocityEstimator(K=k, rho=rho)
        return run(est, stream, solver=diffrax.Heun(), saveat=SaveAt(outputs=False), throw=False)

    sol = jax.vmap(one)(jnp.stack([K, K, 10 * K]), jnp.stack([RHO, BIG_RHO, RHO]))
    names, failed = _codes(sol)
    assert names == ["successful", "diverged", "diverged"]
    assert failed[0] == -1 and 0 < failed[1] <= 5 and 0 < failed[2] <= 30, failed
    assert np.all(np.abs(np.asarray(sol.final_state.eta)) < 1e8)
    assert np.all(np.abs(np.asarray(sol.final_state.e_hat)) < 1e8)


def test_a_large_gain_is_refused_before_allocation(frames30, monkeypatch):
    """K = 1e12 (or rho = 1e9) in a 2 s file of 30 Hz frames: `integration_step` would take
    1e-12 s (5.8e-19 s), 2e12 steps; the error names the steps, the step, the span and the
    gain's bound, and nothing is compiled (the runner's loop is never reached)."""

    def no_loop(*args):
        raise AssertionError("the run was started")

    monkeypatch.setattr(_base, "_run", no_loop)
    huge_k = VelocityEstimator(K=jnp.full(6, 1e12), rho=RHO)
    msg = r"1\.97e\+12 integration steps \(dt = 1e-12 s over 1\.967 s\).*bound of `K`"
    with pytest.raises(ValueError, match=msg):
        integration_step(frames30, huge_k)
    with pytest.raises(ValueError, match=r"integration steps.*GB for the saved outputs.*`K`"):
        run(huge_k, frames30, dt=1e-12)
    with pytest.raises(ValueError, match=r"integration steps.*chattering bound of `rho`"):
        integration_step(frames30, VelocityEstimator(K=K, rho=BIG_RHO))
    # within the step limit but not the memory limit: saving every step of a tiny `dt`
    paper = VelocityEstimator(K=K, rho=RHO)
    with pytest.raises(ValueError, match=r"about 19\.7 GB for the saved outputs.*every"):
        run(paper, frames30, dt=2e-8, saveat=SaveAt(states=True))


def test_the_papers_gains_keep_within_every_bound(short, frames30):
    """Eq. (63): at 1 kHz the sample rate is within both bounds (K's 6.7 ms, rho's 81 s);
    on 30 Hz frames `integration_step` takes half of K's bound, rho's (73 ms) being larger."""
    _, stream, _ = short
    est = VelocityEstimator(K=K, rho=RHO)
    (k_bound, *_), (rho_bound, *_) = _base._first_bounds(est, stream)
    np.testing.assert_allclose(float(k_bound), 2.0 / 300.0, rtol=1e-3)
    assert 80.0 < float(rho_bound) < 83.0
    assert integration_step(stream, est) is None
    (k_bound, *_), (rho_bound, *_) = _base._first_bounds(est, frames30)
    assert 0.07 < float(rho_bound) < 0.075
    assert integration_step(frames30, est) == pytest.approx(0.5 * float(k_bound))
