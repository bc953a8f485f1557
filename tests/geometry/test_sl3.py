"""SL(3) and sl(3): the projection, the group exponential against `jax.scipy.linalg.expm`
and against `so3_exp` on rotations, determinant 1, the representative of a homography;
jit, vmap and grad."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.helpers import central_difference
from visjax.geometry import skew, sl3_exp, sl3_normalize, sl3_project, so3_exp

# random 3x3 matrices at norms from 1e-8 to 40 (the exponential spans e^-40 to e^40)
_RNG = np.random.default_rng(7)
_SCALES = np.array([1e-8, 1e-3, 0.3, 1.0, 3.0, 10.0, 40.0])
_XS = _RNG.normal(size=(_SCALES.size, 3, 3)) * _SCALES[:, None, None] / 3.0


def test_projection_is_the_orthogonal_projection_onto_trace_free_matrices():
    M = _RNG.normal(size=(3, 3))
    P = np.asarray(sl3_project(M))
    assert abs(np.trace(P)) < 1e-15
    np.testing.assert_allclose(sl3_project(P), P, atol=1e-15)  # idempotent
    np.testing.assert_allclose(M - P, np.trace(M) / 3.0 * np.eye(3), atol=1e-15)
    A = np.asarray(sl3_project(_RNG.normal(size=(3, 3))))  # any trace-free matrix
    assert abs(np.sum((M - P) * A)) < 1e-14  # <M - P(M), A> = tr((M - P(M))^T A) = 0


def test_exponential_against_expm_with_determinant_one():
    batched = jax.jit(jax.vmap(sl3_exp))
    E = np.asarray(batched(_XS))
    ref = np.asarray(jax.vmap(jax.scipy.linalg.expm)(jax.vmap(sl3_project)(_XS)))
    for k, scale in enumerate(_SCALES):
        np.testing.assert_allclose(E[k], ref[k], rtol=0, atol=1e-12 * np.abs(ref[k]).max())
        # det = 1 to 1e-12 up to norm 3; beyond, to what float64 can resolve in a matrix of
        # that condition (the exponential at norm 40 has singular values 1e8 and 1e-8)
        tol = 1e-12 if scale <= 3.0 else 100 * np.finfo(float).eps * np.linalg.cond(E[k])
        assert abs(np.linalg.det(E[k]) - 1.0) < tol, (scale, np.linalg.det(E[k]))
        # a group: exp(X) exp(-X) = I
        inv = np.asarray(sl3_exp(-_XS[k]))
        np.testing.assert_allclose(E[k] @ inv, np.eye(3), atol=1e-12 * np.abs(E[k]).max() ** 2)
    # the trace is ignored: exp(P(X)), never a determinant other than 1
    np.testing.assert_allclose(sl3_exp(_XS[3] + 5.0 * np.eye(3)), E[3], rtol=1e-13)


def test_exponential_of_a_rotation_generator_is_the_rotation():
    """so(3) is inside sl(3): exp([w]x) is the Rodrigues rotation of `so3_exp`, an
    independent closed form."""
    for w in ([0.0, 0.0, 0.0], [1e-9, 2e-9, -1e-9], [0.3, -0.2, 0.5], [2.0, 1.0, -2.5]):
        w = jnp.asarray(w)
        np.testing.assert_allclose(sl3_exp(skew(w)), so3_exp(w), atol=1e-14)


def test_exponential_jit_vmap_grad():
    X = _XS[4]
    np.testing.assert_allclose(jax.jit(sl3_exp)(X), sl3_exp(X), rtol=1e-15)
    batch = jax.vmap(sl3_exp)(_XS)
    for k in range(len(_XS)):
        np.testing.assert_allclose(batch[k], sl3_exp(_XS[k]), rtol=1e-15)
    W = _RNG.normal(size=(3, 3))

    def f(x):
        return jnp.sum(sl3_exp(x.reshape(3, 3)) * W)

    for X in (_XS[2], _XS[4]):
        g = jax.grad(f)(X.reshape(-1))
        fd = central_difference(f, X.reshape(-1), 1e-6)
        np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-8)


def test_normalize_gives_the_unit_determinant_representative():
    H = np.array([[1.2, 0.1, 30.0], [-0.05, 0.9, -12.0], [1e-4, 2e-4, 1.0]])
    N = np.asarray(sl3_normalize(H))
    assert abs(np.linalg.det(N) - 1.0) < 1e-12
    np.testing.assert_allclose(N / N[2, 2], H / H[2, 2], rtol=1e-13)  # the same homography
    np.testing.assert_allclose(sl3_normalize(7.5 * H), N, rtol=1e-13)  # scale-free
    np.testing.assert_allclose(sl3_normalize(-H), N, rtol=1e-13)  # odd: -H is the same map
    g = jax.grad(lambda h: sl3_normalize(h)[0, 2])(jnp.asarray(H))
    fd = central_difference(lambda h: sl3_normalize(h)[0, 2], H, 1e-6)
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-9)
    # a non-invertible homography or a NaN: NaN, never a finite matrix; batched, per element
    bad = np.stack([H, np.outer([1.0, 2.0, 3.0], [1.0, 0.0, 1.0]), H * np.nan])
    out = np.asarray(jax.vmap(sl3_normalize)(bad))
    assert np.all(np.isfinite(out[0])) and np.all(np.isnan(out[1:]))


def test_wrong_shapes_are_refused(no_jaxtyping):
    for f in (sl3_project, sl3_exp, sl3_normalize):
        with pytest.raises(ValueError, match="shape"):
            f(np.eye(4))
    assert np.all(np.isnan(sl3_exp(np.full((3, 3), np.nan))))
