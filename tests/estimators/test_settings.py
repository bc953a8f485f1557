"""Every bad estimator setting is refused: 46 cases over the three estimators.

A wrong shape raises `ValueError` naming the field when the estimator is built. A bad
value fails one of the estimator's `checks()`, with a message naming the field; `run`
raises it as a `ValueError` when the values are concrete, and under `jit(vmap)` over a
batch of settings every bad element gets `RESULTS.invalid_settings` while the good one runs.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax import RESULTS
from visjax.estimators import (
    MovingPointEstimator,
    SaveAt,
    StaticPointsEstimator,
    VelocityEstimator,
    fixed_camera,
    run,
    velocity_stream,
)
from visjax.papers import chitrakaran, jang, nath

NAN, INF = float("nan"), float("inf")


def _velocity():
    sc = chitrakaran.section6_scenario(0.3, 1000.0)
    camera = fixed_camera(sc.pixels, sc.A, sc.R_star, sc.s[0], n_star=sc.n_star, z1_star=sc.z1_star)
    stream = velocity_stream(sc.ts, sc.pixels, camera)
    return VelocityEstimator(K=chitrakaran.K_EQ63, rho=chitrakaran.RHO_EQ63), stream


def _uio():
    sc = jang.scenario("II.1", 1.0)
    return jang.observer("II.1"), sc.camera_stream()


def _adaptive():
    sc = nath.scenario(0.05)
    return nath.initial_estimator(sc), nath.stream(sc)


def _set(index, value):
    """A setter for `eqx.tree_at`: entry `index` of a field set to `value`."""
    return lambda x: jnp.asarray(x).at[index].set(value)


# (field, how to make it bad, a word the failing check's message contains)
VALUE_CASES = {
    "velocity": [
        ("K", _set(2, -1.0), "`K`"),
        ("K", _set(0, 0.0), "`K`"),
        ("K", _set(5, NAN), "`K`"),
        ("K", _set(1, INF), "`K`"),
        ("rho", _set(3, -0.5), "`rho`"),
        ("rho", _set(0, 0.0), "`rho`"),
        ("rho", _set(4, NAN), "`rho`"),
        ("rho", _set(2, INF), "`rho`"),
        ("bound", lambda b: 0.0 * b, "`bound`"),
        ("bound", lambda b: -b, "`bound`"),
        ("bound", lambda b: b * NAN, "`bound`"),
    ],
    "uio": [
        ("K", lambda K: -K, "Hurwitz"),
        ("K", _set((0, 0), NAN), "finite"),
        ("Y", _set((1, 1), NAN), "finite"),
        ("A", _set((2, 2), NAN), "finite"),
        ("A", lambda A: jnp.zeros_like(A), "rank condition"),
        ("D", lambda D: jnp.asarray([[0.0], [0.0], [1.0]]), "rank condition"),
        ("C", _set((0, 0), INF), "finite"),
        ("x3_guess", lambda x: 0.0 * x, "`x3_guess`"),
        ("x3_guess", lambda x: -x, "`x3_guess`"),
        ("x3_guess", lambda x: x * NAN, "`x3_guess`"),
        ("bound", lambda b: -b, "`bound`"),
        ("bound", lambda b: b * NAN, "`bound`"),
    ],
    "adaptive": [
        ("alpha_c", lambda a: -a, "`alpha_c`"),
        ("alpha_c", lambda a: a * NAN, "`alpha_c`"),
        ("alpha_c", lambda a: a * INF, "`alpha_c`"),
        ("alpha", lambda a: -a, "`alpha`"),
        ("alpha", lambda a: 0.0 * a, "`alpha`"),
        ("eta0", lambda e: jnp.asarray(1e-9), "eta0 > eta1"),
        ("eta1", lambda e: 0.0 * e, "eta0 > eta1"),
        ("eta1", lambda e: -e, "eta0 > eta1"),
        ("gamma_s0", lambda g: -g, "`gamma_s0`"),
        ("gamma_s0", lambda g: g * NAN, "`gamma_s0`"),
        ("D", _set(3, 0.0), "`D`"),
        ("D", _set(7, -1.0), "`D`"),
        ("eps_c", lambda e: -e, "projection margins"),
        ("eps_s", lambda e: 0.0 * e, "projection margins"),
        ("theta_c0", _set(5, NAN), "initial estimates"),
        ("theta_s0", _set((1, 2), INF), "initial estimates"),
        ("scale_min", lambda s: -jnp.ones_like(s), "`scale_min`"),
    ],
}

SHAPE_CASES = {
    "velocity": [("K", (5,)), ("rho", (6, 6))],
    "uio": [("K", (2, 3)), ("D", (3, 2))],
    "adaptive": [("theta_s0", (4, 3)), ("D", (12,))],
}

BUILD = {"velocity": _velocity, "uio": _uio, "adaptive": _adaptive}
CLASSES = {
    "velocity": VelocityEstimator,
    "uio": MovingPointEstimator,
    "adaptive": StaticPointsEstimator,
}


def test_the_enumeration_has_46_cases():
    n = sum(len(v) for v in VALUE_CASES.values()) + sum(len(v) for v in SHAPE_CASES.values())
    assert n == 46


def _bad(est, field, make_bad):
    return eqx.tree_at(lambda e: getattr(e, field), est, make_bad(getattr(est, field)))


@pytest.mark.parametrize("kind", sorted(SHAPE_CASES))
def test_wrong_shapes_are_refused_when_built(kind):
    est, _ = BUILD[kind]()
    fields = {k: v for k, v in vars(est).items()}
    for field, shape in SHAPE_CASES[kind]:
        with pytest.raises(ValueError, match=f"`{field}`"):
            CLASSES[kind](**{**fields, field: jnp.ones(shape)})


@pytest.mark.parametrize("kind", sorted(VALUE_CASES))
def test_bad_values_fail_their_check_and_are_flagged_in_a_batch(kind):
    est, stream = BUILD[kind]()
    assert all(bool(ok) for ok, _ in est.checks())
    bads = []
    for field, make_bad, word in VALUE_CASES[kind]:
        bad = _bad(est, field, make_bad)
        failing = [message for ok, message in bad.checks() if not bool(ok)]
        assert any(word in m for m in failing), (field, failing)
        bads.append(bad)
    # concrete values: refused before the run
    with pytest.raises(ValueError, match=VALUE_CASES[kind][0][2]):
        run(bads[0], stream, saveat=SaveAt(outputs=False))
    # under jit(vmap): the good element runs, every bad one is flagged at sample 0
    batch = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), est, *bads)
    short = eqx.tree_at(
        lambda s: (s.ts, s.ys),
        stream,
        jax.tree_util.tree_map(lambda x: x[:20], (stream.ts, stream.ys)),
    )

    @jax.jit
    @jax.vmap
    def results(e):
        sol = run(e, short, saveat=SaveAt(outputs=False), throw=False)
        return sol.result._value, sol.failed_sample

    codes, failed = (np.asarray(x) for x in results(batch))
    assert codes[0] == RESULTS.successful._value
    assert np.all(codes[1:] == RESULTS.invalid_settings._value), codes
    assert np.all(failed[1:] == 0)
