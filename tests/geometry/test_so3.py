import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.helpers import central_difference
from visjax.geometry import L_omega, L_omega_inv, sinc, skew, so3_exp, so3_log, vee

exp_j = jax.jit(so3_exp)
log_j = jax.jit(lambda R: so3_log(R).omega)


def _random_vectors(n, seed=0, angles=None):
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    if angles is None:
        angles = rng.uniform(0.0, np.pi, n)
    return u * np.asarray(angles)[:, None]


def test_skew_vee():
    v = np.array([0.3, -1.2, 2.0])
    w = np.array([1.0, 0.5, -0.7])
    np.testing.assert_allclose(skew(v) @ w, np.cross(v, w), rtol=1e-15)
    np.testing.assert_allclose(vee(skew(v)), v, rtol=1e-15)
    np.testing.assert_allclose(skew(v).T, -skew(v), rtol=0)


def test_exp_matches_scipy_and_is_rotation():
    omegas = _random_vectors(50)
    R = jax.vmap(exp_j)(omegas)
    np.testing.assert_allclose(R, Rotation.from_rotvec(omegas).as_matrix(), atol=1e-14)
    eye = np.broadcast_to(np.eye(3), R.shape)
    np.testing.assert_allclose(np.swapaxes(R, 1, 2) @ R, eye, atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-14)


@pytest.mark.parametrize(
    "angle", [0.0, 1e-12, 1e-9, 1e-6, 1e-3, 0.5, 1.5, 2.5, np.pi - 1e-3, np.pi - 1e-6]
)
def test_log_exp_round_trip(angle):
    omegas = _random_vectors(20, seed=1, angles=np.full(20, angle))
    back = jax.vmap(log_j)(jax.vmap(exp_j)(omegas))
    # near pi, the digits of the angle are lost at the rate of sin(theta) -> 0 in vee(R);
    # the symmetric-part branch keeps the axis to machine precision.
    np.testing.assert_allclose(back, omegas, atol=2e-14 * max(1.0, angle), rtol=1e-12)


def test_log_at_exactly_pi_is_a_valid_logarithm():
    for axis in np.eye(3):
        R = Rotation.from_rotvec(np.pi * axis).as_matrix()
        w = log_j(R)
        np.testing.assert_allclose(np.linalg.norm(w), np.pi, rtol=1e-14)
        np.testing.assert_allclose(exp_j(w), R, atol=1e-14)


def test_log_matches_scipy():
    omegas = _random_vectors(50, seed=2)
    R = Rotation.from_rotvec(omegas).as_matrix()
    np.testing.assert_allclose(jax.vmap(log_j)(R), Rotation.from_matrix(R).as_rotvec(), atol=1e-13)


def _log_exp(w):
    return so3_log(so3_exp(w)).omega


# each derivative compiled once (not dispatched op by op), evaluated at every point
_JACFWD = {f: jax.jit(jax.jacfwd(f)) for f in (so3_exp, _log_exp, L_omega, L_omega_inv)}
_JACREV = {f: jax.jit(jax.jacrev(f)) for f in _JACFWD}


def test_gradients_finite_at_identity_and_match_finite_differences():
    zero = jnp.zeros(3)
    for f in _JACFWD:
        assert np.all(np.isfinite(_JACFWD[f](zero)))
        assert np.all(np.isfinite(_JACREV[f](zero)))
    # log(exp(w)) = w: the Jacobian is the identity at and near 0
    np.testing.assert_allclose(_JACREV[_log_exp](zero), np.eye(3))
    tiny = 1e-7 * np.array([0.3, -0.8, 0.5])
    np.testing.assert_allclose(_JACREV[_log_exp](tiny), np.eye(3), atol=1e-12)
    # exp: d exp(w) / dw at 0 is the generators
    J = _JACFWD[so3_exp](zero)
    for i in range(3):
        np.testing.assert_allclose(J[:, :, i], skew(np.eye(3)[i]), atol=1e-15)
    # elsewhere, against central differences, and forward == reverse
    w = np.array([0.4, -1.1, 0.7])
    for f in _JACFWD:
        fd = central_difference(f, w, 1e-6)
        np.testing.assert_allclose(_JACFWD[f](w), fd, atol=1e-8)
        np.testing.assert_allclose(_JACREV[f](w), _JACFWD[f](w), atol=1e-13)


def test_log_gradient_near_pi_matches_finite_differences():
    w = (np.pi - 1e-3) * np.array([0.0, 0.6, 0.8])
    np.testing.assert_allclose(_JACFWD[_log_exp](w), np.eye(3), atol=1e-8)
    np.testing.assert_allclose(_JACREV[_log_exp](w), np.eye(3), atol=1e-8)


def test_sinc():
    x = np.array([0.0, 1e-9, 1e-4, 1e-2, 0.5, 2.0, 10.0])
    np.testing.assert_allclose(sinc(x), np.sinc(x / np.pi), rtol=1e-15)
    d = jax.vmap(jax.grad(sinc))(x)
    # the closed form cancels catastrophically for small x: use its series there
    closed = (x * np.cos(x) - np.sin(x)) / np.where(x == 0, 1, x) ** 2
    exact = np.where(np.abs(x) < 1e-2, -x / 3 + x**3 / 30, closed)
    np.testing.assert_allclose(d, exact, atol=1e-12)


@pytest.mark.parametrize("angle", [0.0, 1e-8, 1e-3, 0.7, 2.0, 3.0, np.pi - 1e-6])
def test_L_omega_is_the_kinematics_of_e_omega(angle):
    """e_dot = L_omega omega_e (Chitrakaran et al., eq. (26)) with
    [omega_e]x = d(R_bar)/dt R_bar^T (A.2)."""
    rng = np.random.default_rng(3)
    for _ in range(5):
        e0 = _random_vectors(1, seed=rng.integers(1000), angles=[angle])[0]
        omega = rng.normal(size=3)
        R0 = so3_exp(e0)
        # R_bar(t) = exp(t omega) R0 has d(R_bar)/dt R_bar^T = [omega]x at t = 0
        path = lambda t: so3_log(so3_exp(t * omega) @ R0).omega  # noqa: E731
        _, e_dot = jax.jvp(path, (0.0,), (1.0,))
        np.testing.assert_allclose(L_omega(e0) @ omega, e_dot, rtol=1e-8, atol=1e-12)


def test_L_omega_inverse_and_determinant():
    omegas = _random_vectors(30, seed=4)
    omegas = np.concatenate([omegas, [[0.0, 0.0, 0.0], [1e-9, 0.0, 0.0]]])
    L = jax.vmap(L_omega)(omegas)
    Li = jax.vmap(L_omega_inv)(omegas)
    np.testing.assert_allclose(L @ Li, np.broadcast_to(np.eye(3), L.shape), atol=1e-13)
    theta = np.linalg.norm(omegas, axis=1)
    # det L_omega = 1 / sinc^2(theta/2): the form that tends to 1 as theta -> 0 (eq. (31)).
    np.testing.assert_allclose(np.linalg.det(L), 1.0 / np.sinc(theta / 2 / np.pi) ** 2, rtol=1e-12)


def test_shape_errors(no_jaxtyping):
    with pytest.raises(ValueError, match=r"shape \(3,\)"):
        so3_exp(np.zeros(4))
    with pytest.raises(ValueError, match=r"shape \(3, 3\)"):
        so3_log(np.zeros((3, 4)))
