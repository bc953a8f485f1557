"""Joint trajectories from commanded tool twists (Jang's thesis, eq. (4.6) integrated),
encoder velocities, and the planar path, against closed forms and finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax._results import RESULTS
from visjax.kinematics import puma560
from visjax.sim import encoder_twist, follow_tool_twist, planar_path, quantise

CHAIN = puma560((0.0, 0.0, 0.1))
DOWN = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
Q_GUESS = np.array([-0.10, 0.30, -0.08, 0.0, 2.92, 3.04])
TWIST = np.array([0.003, 0.015, 0.0, 0.0, 0.0, -0.05])  # set I.1's A read in cm/s, in m/s


def _constant(t):  # one function for every test: diffrax compiles once per function
    return jnp.asarray(TWIST) + 0 * t


@pytest.fixture(scope="module")
def q_start():
    return CHAIN.solve_pose(DOWN, np.array([0.5, 0.1, 0.2]), Q_GUESS).q


def _body_twist_by_differences(qs, dt):
    """The tool's twist in its own frame from finite differences of the forward kinematics."""
    R, p = jax.vmap(CHAIN.tool_pose)(jnp.asarray(qs))
    R, p = np.asarray(R), np.asarray(p)
    V = (p[2:] - p[:-2]) / (2 * dt)
    W = np.einsum("nij,nkj->nik", (R[2:] - R[:-2]) / (2 * dt), R[1:-1])  # dR/dt R^T
    w = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
    Rm = R[1:-1]
    return np.concatenate([np.einsum("nji,nj->ni", Rm, V), np.einsum("nji,nj->ni", Rm, w)], 1)


def test_solve_pose_reaches_the_pose(q_start):
    R, p = CHAIN.tool_pose(q_start)
    np.testing.assert_allclose(np.asarray(R), DOWN, atol=1e-12)
    np.testing.assert_allclose(np.asarray(p), [0.5, 0.1, 0.2], atol=1e-12)
    far = CHAIN.solve_pose(DOWN, np.array([3.0, 0.0, 0.0]), Q_GUESS, throw=False)
    assert far.result != RESULTS.successful  # 3 m is out of the PUMA's reach
    assert float(far.residual) > 1.0


def test_follow_tool_twist_forwards_and_backwards(q_start):
    dt = 0.01
    ts = jnp.arange(201.0) * dt  # 2 s
    for direction in (1.0, -1.0):
        jt = follow_tool_twist(CHAIN, q_start, _constant, direction * ts)
        assert jt.result == RESULTS.successful and int(jt.failed_sample) == -1
        twist = _body_twist_by_differences(np.asarray(jt.q), direction * dt)
        np.testing.assert_allclose(twist, np.broadcast_to(TWIST, twist.shape), atol=2e-7)
    # a time-varying twist, checked at the samples
    f = lambda t: jnp.array([0.01 * jnp.sin(t), 0.02, 0.0, 0.0, 0.05 * jnp.cos(t), -0.05])  # noqa: E731
    jt = follow_tool_twist(CHAIN, q_start, f, ts)
    twist = _body_twist_by_differences(np.asarray(jt.q), dt)
    expected = np.asarray(jax.vmap(f)(ts[1:-1]))
    np.testing.assert_allclose(twist, expected, atol=2e-6)


def test_follow_tool_twist_stops_at_a_singular_configuration(q_start):
    # 1 m/s along the camera's -z (upwards, away from the table): the arm stretches out
    ts = jnp.arange(101.0) * 0.01
    up = jnp.array([0.0, 0.0, -1.0, 0.0, 0.0, 0.0])
    jt = follow_tool_twist(CHAIN, q_start, lambda t: up + 0 * t, ts)
    assert jt.result == RESULTS.singular_configuration
    k = int(jt.failed_sample)
    assert 0 < k < 101
    assert np.all(np.isfinite(np.asarray(jt.q[:k])))
    assert float(jt.sigma_min[k - 1]) < 0.2  # close to the singularity when it stopped


def test_encoder_twist_and_quantisation(q_start):
    rate = 1000.0
    ts = jnp.arange(201.0) / rate
    jt = follow_tool_twist(CHAIN, q_start, _constant, ts)
    fine = np.asarray(encoder_twist(CHAIN, jt.q, rate, resolution=1e-12, window=33))
    # the mean joint rate over the last 33 ms through J at the latest sample: the linear
    # velocity lags by half the window, turned by w_z T / 2 (|v| |w_z| T / 2 = 1.3e-5 m/s)
    lag = np.linalg.norm(TWIST[:2]) * abs(TWIST[5]) * 0.033 / 2
    err = np.abs(fine[33:] - TWIST)
    assert err[:, :2].max() < 2 * lag and err[:, 2:].max() < 1e-8
    assert np.all(fine[0] == 0.0)  # no history at sample 0
    res = 2 * np.pi / 2**18
    coarse = np.asarray(encoder_twist(CHAIN, jt.q, rate, resolution=res, window=33))
    err = np.abs(coarse[33:] - TWIST).max()
    # at most one count per joint over the window, through the Jacobian (|J| < 1.5 m, 1)
    assert 1e-6 < err < 6 * 1.5 * res / 0.033
    qq = np.asarray(quantise(jt.q, res))
    np.testing.assert_allclose(qq / res, np.round(qq / res), atol=1e-6)
    assert np.abs(qq - np.asarray(jt.q)).max() <= res / 2 + 1e-15
    with pytest.raises(ValueError, match="resolution"):
        quantise(jt.q, 0.0)
    # one resolution per joint: each column rounded to its own
    per_joint = res * np.arange(1.0, 7.0)
    qj = np.asarray(quantise(jt.q, per_joint))
    for j in range(6):
        np.testing.assert_array_equal(qj[:, j], np.asarray(quantise(jt.q[:, j], per_joint[j])))
    with pytest.raises(ValueError, match="resolution"):
        quantise(jt.q, per_joint * np.r_[1, 1, 1, 1, 1, -1])
    with pytest.raises(ValueError, match="window"):
        encoder_twist(CHAIN, jt.q, rate, resolution=res, window=0)
    # under jit and grad: the encoder twist is differentiable in the joint angles
    g = jax.grad(lambda q: jnp.sum(encoder_twist(CHAIN, q, rate, resolution=1e-12, window=3) ** 2))(
        jt.q[:10]
    )
    assert np.all(np.isfinite(np.asarray(g)))


def test_planar_path_equals_the_closed_form():
    omega, v = -0.07, np.array([0.0115, -0.013])
    ts = jnp.linspace(0.0, 30.0, 301)
    psi, c = planar_path(lambda t: jnp.asarray(v) + 0 * t, omega, ts, 15.0)
    tau = np.asarray(ts) - 15.0
    s, co = np.sin(omega * tau), np.cos(omega * tau)
    expected = np.stack([s * v[0] + (co - 1) * v[1], (1 - co) * v[0] + s * v[1]], 1) / omega
    np.testing.assert_allclose(np.asarray(c), expected, atol=1e-11)
    np.testing.assert_allclose(np.asarray(psi), omega * tau, atol=1e-15)


@pytest.mark.slow
def test_planar_path_and_follow_tool_twist_differentiate(q_start):
    ts = jnp.linspace(0.0, 30.0, 301)
    v = jnp.array([0.0115, -0.013])

    def end_x(omega):
        return planar_path(lambda t: v + 0 * t, omega, ts, 15.0)[1][-1, 0]

    g = jax.jit(jax.grad(end_x))(-0.07)
    h = 1e-6
    np.testing.assert_allclose(g, (end_x(-0.07 + h) - end_x(-0.07 - h)) / (2 * h), rtol=1e-6)

    ts1 = jnp.linspace(0.0, 1.0, 11)

    def first_joint(scale):
        return follow_tool_twist(CHAIN, q_start, lambda t: scale * _constant(t), ts1).q[-1, 0]

    g = jax.grad(first_joint)(1.0)
    fd = (first_joint(1.0 + h) - first_joint(1.0 - h)) / (2 * h)
    np.testing.assert_allclose(g, fd, rtol=1e-6)
    assert abs(float(g)) > 1e-3
