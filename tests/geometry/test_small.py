"""The closed-form small-matrix helpers against NumPy / JAX's general routines."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax._small import dot, eigh3, mm, mv, norm, sall, smax, spd_solve, ssum

rng = np.random.default_rng(3)
N = 2000
Q = np.linalg.qr(rng.normal(size=(N, 3, 3)))[0]


def _spectra(kind):
    one = np.ones(N)
    if kind == "random":
        X = rng.normal(size=(N, 3, 3))
        return X + np.transpose(X, (0, 2, 1))
    d = {
        "repeated_low": np.stack([one, one + 1e-9 * rng.random(N), 2 * one], 1),
        "repeated_high": np.stack([one, 2 * one + 1e-9 * rng.random(N), 2 * one], 1),
        "triple": np.stack([one, one, one + 1e-12 * rng.random(N)], 1),
        "HtH_near_identity": None,
    }[kind]
    if d is None:
        H = np.eye(3) + 1e-7 * rng.normal(size=(N, 3, 3))
        return np.einsum("bji,bjk->bik", H, H)
    return np.einsum("bij,bj,bkj->bik", Q, d, Q)


_eigh3_batch = jax.jit(jax.vmap(eigh3))


@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
@pytest.mark.parametrize(
    "kind", ["random", "repeated_low", "repeated_high", "triple", "HtH_near_identity"]
)
@pytest.mark.parametrize("scale", [1.0, 1e-12, 1e12])
def test_eigh3_matches_numpy_and_is_orthonormal(kind, dtype, scale):
    A = jnp.asarray(_spectra(kind) * scale, dtype)
    lam, V = _eigh3_batch(A)
    assert lam.dtype == dtype and V.dtype == dtype
    A64 = np.asarray(A, np.float64)
    ref = np.linalg.eigvalsh(A64)
    size = np.max(np.abs(ref), axis=1, keepdims=True)
    eps = float(jnp.finfo(dtype).eps)
    # ascending eigenvalues to a few eps of the norm, orthonormal vectors, A V = V diag(lam)
    assert np.max(np.abs(np.asarray(lam, np.float64) - ref) / size) < 20 * eps
    V64 = np.asarray(V, np.float64)
    assert np.max(np.abs(np.einsum("bji,bjk->bik", V64, V64) - np.eye(3))) < 20 * eps
    resid = np.einsum("bij,bjk->bik", A64, V64) - V64 * np.asarray(lam, np.float64)[:, None, :]
    assert np.max(np.abs(resid) / size[:, :, None]) < 50 * eps


def test_eigh3_identity_nan_and_derivative():
    lam, V = eigh3(jnp.eye(3))
    np.testing.assert_array_equal(lam, np.ones(3))
    np.testing.assert_array_equal(V, np.eye(3))
    lam, V = eigh3(jnp.full((3, 3), jnp.nan))
    assert np.all(np.isnan(lam))

    # the derivative of a smooth function of the eigenpairs (sign-invariant) agrees with
    # jnp.linalg.eigh's, and with a central finite difference
    def f(eig):
        def g(A):
            lam, V = eig(A)
            return jnp.sum(lam * jnp.arange(1.0, 4.0)) + jnp.sum(V[:, 1] ** 2 * jnp.arange(3.0))

        return g

    X = jnp.asarray(rng.normal(size=(3, 3)))
    A = X + X.T
    g3 = jax.jit(jax.grad(f(eigh3)))(A)
    gl = jax.grad(f(jnp.linalg.eigh))((A + A.T) / 2)
    np.testing.assert_allclose(g3, (gl + gl.T) / 2, atol=1e-10)
    dA = jnp.asarray(rng.normal(size=(3, 3)))
    dA = dA + dA.T
    h = 1e-6
    fd = (f(eigh3)(A + h * dA) - f(eigh3)(A - h * dA)) / (2 * h)
    np.testing.assert_allclose(jnp.sum(g3 * dA), fd, rtol=1e-6)


def test_unrolled_reductions_and_products_match_jax():
    x = jnp.asarray(rng.normal(size=(4, 3)))
    for axis in (None, 0, 1, -1):
        np.testing.assert_allclose(ssum(x, axis), jnp.sum(x, axis), rtol=1e-14)
        np.testing.assert_array_equal(smax(x, axis), jnp.max(x, axis))
        np.testing.assert_array_equal(sall(x > 0, axis), jnp.all(x > 0, axis))
    long = jnp.asarray(rng.normal(size=(100,)))  # beyond the unrolling limit
    np.testing.assert_allclose(ssum(long), jnp.sum(long), rtol=1e-13)
    # NaN propagates through the unrolled max, in a vmapped batch too
    y = x.at[2, 1].set(jnp.nan)
    assert np.isnan(smax(y))
    assert np.isnan(jax.vmap(smax)(jnp.broadcast_to(y, (1000, 4, 3)))).all()
    A = jnp.asarray(rng.normal(size=(3, 4)))
    B = jnp.asarray(rng.normal(size=(4, 2)))
    v = jnp.asarray(rng.normal(size=(4,)))
    np.testing.assert_allclose(mm(A, B), A @ B, rtol=1e-13)
    np.testing.assert_allclose(mv(A, v), A @ v, rtol=1e-13)
    np.testing.assert_allclose(dot(v, v), v @ v, rtol=1e-14)
    np.testing.assert_allclose(norm(A), jnp.linalg.norm(A), rtol=1e-14)
    np.testing.assert_allclose(
        jax.vmap(mm)(jnp.stack([A, 2 * A]), jnp.stack([B, B])), jnp.stack([A @ B, 2 * A @ B])
    )
    g = jax.grad(lambda A: jnp.sum(mm(A, B) ** 2))(A)
    np.testing.assert_allclose(g, 2 * (A @ B) @ B.T, rtol=1e-12)


@pytest.mark.parametrize("n", [1, 3, 6])
def test_spd_solve_matches_numpy_under_vmap_and_its_gradient_a_finite_difference(n):
    """`spd_solve` (elimination unrolled, no LAPACK call) against `np.linalg.solve` on a
    batch of SPD matrices of condition up to ~1e4, under `jit(vmap)`; its gradient with
    respect to `G` against a central difference."""
    X = rng.normal(size=(200, n, n))
    G = np.einsum("bij,bkj->bik", X, X) + 1e-2 * np.eye(n)
    b = rng.normal(size=(200, n))
    x = jax.jit(jax.vmap(spd_solve))(G, b)
    np.testing.assert_allclose(x, np.linalg.solve(G, b[..., None])[..., 0], rtol=1e-8, atol=1e-8)

    def f(G):
        return jnp.sum(spd_solve(G, b[0]) ** 2)

    g = jax.grad(f)(jnp.asarray(G[0]))
    D = np.zeros((n, n))
    D[0, n - 1] = D[n - 1, 0] = 1.0  # a symmetric perturbation
    h = 1e-6
    fd = (f(G[0] + h * D) - f(G[0] - h * D)) / (2 * h)
    np.testing.assert_allclose(np.sum(g * D), fd, rtol=1e-5)


def test_barrier_is_the_cpus_only(monkeypatch):
    """The per-frame barriers materialise shared quantities for XLA's CPU compiler (no
    multi-output fusion there); elsewhere they would only cut the fusions (issue 47)."""
    from visjax._small import barrier

    def prims(f):
        return {e.primitive.name for e in jax.make_jaxpr(f)(jnp.ones(3)).jaxpr.eqns}

    assert "optimization_barrier" in prims(lambda x: barrier(x * 2.0))
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    assert "optimization_barrier" not in prims(lambda x: barrier(x * 2.0))
    assert float(barrier(jnp.asarray(2.0))) == 2.0
