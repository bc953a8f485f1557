"""Jang's thesis, chapter 4: the PUMA 560 and two-link kinematics against an independent
reference (roboticstoolbox-python's modified Denavit-Hartenberg chain built from the same
Table 4-1) and against finite differences of the forward kinematics."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.helpers import central_difference
from visjax._results import RESULTS
from visjax.kinematics import (
    PUMA560_TABLE,
    SerialChain,
    TwoLinkArm,
    link_transform,
    puma560,
    puma560_forward,
)

TOOL = np.array([0.02, -0.03, 0.08])  # a camera 8 cm out along S6, off the axis
CHAIN = puma560(TOOL)
# bound methods of a Module are not hashable by `jax.jit`: wrap them
_frames = jax.jit(jax.vmap(lambda q: CHAIN.frames(q)))
_jacobian = jax.jit(lambda q: CHAIN.jacobian(q))
_twist = jax.jit(lambda q, qdot, local: CHAIN.tool_twist(q, qdot, local=local), static_argnums=2)


def _inverse(q, twist, local):
    return CHAIN.inverse_velocity(q, twist, local=local, throw=False)


_inverse = jax.jit(_inverse, static_argnums=2)


def _rtb_puma():
    import roboticstoolbox as rtb  # a test-only dependency (the dev extra)

    links = [
        rtb.RevoluteMDH(a=a, alpha=alpha, d=S)
        for a, alpha, S in zip(PUMA560_TABLE["a"], PUMA560_TABLE["alpha"], PUMA560_TABLE["S"])
    ]
    return rtb.DHRobot(links, name="PUMA 560, Jang's Table 4-1")


def test_forward_kinematics_equals_roboticstoolbox_on_1000_joint_vectors():
    robot = _rtb_puma()
    qs = np.random.default_rng(0).uniform(-np.pi, np.pi, (1000, 6))
    T = np.asarray(jax.jit(jax.vmap(puma560_forward))(qs))
    T_ref = np.stack([robot.fkine(q).A for q in qs])
    assert np.abs(T[:, :3, 3] - T_ref[:, :3, 3]).max() < 1e-9  # metres
    assert np.abs(T[:, :3, :3] - T_ref[:, :3, :3]).max() < 1e-9
    # every intermediate frame is a proper rigid transform
    Ts = np.asarray(_frames(qs[:50]))
    R = Ts[..., :3, :3]
    assert np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)).max() < 1e-12
    assert np.abs(np.linalg.det(R) - 1).max() < 1e-12
    # the link transform (4.2) is Rx(alpha) Tx(a) Rz(theta) Tz(S)
    a, alpha, S, th = 0.3, 0.7, -0.2, 1.1
    ref = robot.links[0].__class__(a=a, alpha=alpha, d=S).A(th).A
    np.testing.assert_allclose(np.asarray(link_transform(a, alpha, S, th)), ref, atol=1e-15)


def test_jacobian_against_finite_differences_of_forward_kinematics():
    qs = np.random.default_rng(1).uniform(-np.pi, np.pi, (20, 6))
    h = 1e-5
    for q in qs:
        J = np.asarray(_jacobian(q))
        dT = central_difference(puma560_forward, q, h)  # (4, 4, 6)
        R = np.asarray(puma560_forward(q))[:3, :3]
        linear = dT[:3, 3, :]  # dP6/dq
        # angular: [w]x = dR/dt R^T, per joint rate
        W = np.einsum("abi,cb->aci", dT[:3, :3, :], R)
        angular = np.stack([W[2, 1], W[0, 2], W[1, 0]])
        np.testing.assert_allclose(J[:3], linear, atol=1e-7)
        np.testing.assert_allclose(J[3:], angular, atol=1e-7)
        # the skew part is skew: the finite difference is consistent
        assert np.abs(W + np.swapaxes(W, 0, 1)).max() < 1e-7


def test_jacobian_equals_roboticstoolbox_jacob0():
    robot = _rtb_puma()
    for q in np.random.default_rng(2).uniform(-np.pi, np.pi, (10, 6)):
        np.testing.assert_allclose(np.asarray(_jacobian(q)), robot.jacob0(q), atol=1e-12)


def test_tool_twist_is_the_derivative_of_the_tool_pose():
    rng = np.random.default_rng(3)
    q, qdot = rng.uniform(-np.pi, np.pi, 6), rng.normal(size=6)
    h = 1e-6
    (R0, p0), (R1, p1) = CHAIN.tool_pose(q - h * qdot), CHAIN.tool_pose(q + h * qdot)
    V = (np.asarray(p1) - np.asarray(p0)) / (2 * h)
    W = (np.asarray(R1) - np.asarray(R0)) / (2 * h) @ np.asarray(CHAIN.tool_pose(q)[0]).T
    w = np.array([W[2, 1], W[0, 2], W[1, 0]])
    twist = np.asarray(_twist(q, qdot, False))
    np.testing.assert_allclose(twist, np.concatenate([V, w]), atol=1e-8)
    R = np.asarray(CHAIN.tool_pose(q)[0])
    local = np.asarray(_twist(q, qdot, True))
    np.testing.assert_allclose(local, np.concatenate([R.T @ V, R.T @ w]), atol=1e-8)


@pytest.mark.parametrize("local", [False, True])
def test_inverse_velocity_reproduces_the_commanded_twist(local):
    rng = np.random.default_rng(4)
    n_checked = 0
    for _ in range(40):
        q = rng.uniform(-np.pi, np.pi, 6)
        twist = np.concatenate([rng.normal(scale=0.1, size=3), rng.normal(scale=0.3, size=3)])
        out = _inverse(q, twist, local)
        if float(out.sigma_min) < 0.02:  # near a singularity: checked below
            continue
        assert out.result == RESULTS.successful
        back = np.asarray(_twist(q, out.qdot, local))
        np.testing.assert_allclose(back, twist, atol=1e-9)
        n_checked += 1
    assert n_checked >= 20


def test_inverse_velocity_refuses_near_singularities():
    q = np.array([0.3, -0.5, 0.4, 0.2, 1e-6, 0.1])  # theta5 = 0: the wrist axes S4, S6 align
    twist = np.array([0.01, 0.0, 0.0, 0.0, 0.0, 0.1])
    out = _inverse(q, twist, False)
    assert out.result == RESULTS.singular_configuration
    assert float(out.sigma_min) < 1e-5
    with pytest.raises(eqx.EquinoxRuntimeError, match="singular"):
        CHAIN.inverse_velocity(q, twist)
    # the same configuration a little away from it is accepted, and exact
    q_ok = q.copy()
    q_ok[4] = 0.3
    out = _inverse(q_ok, twist, False)
    assert out.result == RESULTS.successful
    np.testing.assert_allclose(np.asarray(_twist(q_ok, out.qdot, False)), twist, atol=1e-9)
    # under vmap: one singular configuration in a batch is flagged alone
    batch = jax.vmap(lambda q: _inverse(q, twist, False))(jnp.stack([q, q_ok]))
    assert list(np.asarray(batch.result._value)) == [
        int(RESULTS.singular_configuration._value),
        int(RESULTS.successful._value),
    ]


def test_gradients_through_the_kinematics():
    q0 = np.array([0.2, -0.4, 0.3, 0.5, 0.6, -0.2])
    twist = np.array([0.01, 0.02, -0.01, 0.0, 0.05, 0.1])

    def loss(q):
        qdot = CHAIN.inverse_velocity(q, twist).qdot
        return jnp.sum(qdot**2) + jnp.sum(CHAIN.tool_pose(q)[1] ** 2)

    g = np.asarray(jax.jit(jax.grad(loss))(q0))
    fd = central_difference(loss, q0, 1e-6)
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-8)


def test_two_link_arm_equals_the_planar_chain_and_inverts():
    arm = TwoLinkArm(0.35, 0.25)
    # the same robot as a planar chain of eq. (4.2) (alpha = 0), tool at the end of link 2
    chain = SerialChain(a=(0.0, 0.35), alpha=(0.0, 0.0), S=(0.0, 0.0), tool=(0.25, 0.0, 0.0))
    rng = np.random.default_rng(5)
    qs = rng.uniform(-np.pi, np.pi, (100, 2))
    p = np.asarray(jax.vmap(arm.forward)(qs))
    p_chain = np.asarray(jax.vmap(lambda q: chain.tool_pose(q)[1])(qs))
    np.testing.assert_allclose(p, p_chain[:, :2], atol=1e-15)
    assert np.abs(p_chain[:, 2]).max() == 0.0
    # inverse position: round trip for both elbows
    for elbow in (1, -1):
        q_back = np.asarray(jax.vmap(lambda x: arm.inverse(x, elbow=elbow))(p))
        np.testing.assert_allclose(np.asarray(jax.vmap(arm.forward)(q_back)), p, atol=1e-12)
    # Jacobian against finite differences, and the inverse velocity
    q = np.array([0.4, 1.1])
    np.testing.assert_allclose(
        np.asarray(arm.jacobian(q)),
        central_difference(lambda q: arm.forward(q), q, 1e-6),
        atol=1e-9,
    )
    pdot = np.array([0.03, -0.02])
    out = arm.inverse_velocity(q, pdot)
    np.testing.assert_allclose(np.asarray(arm.jacobian(q) @ out.qdot), pdot, atol=1e-12)
    stretched = arm.inverse_velocity(np.array([0.4, 1e-5]), pdot, throw=False)
    assert stretched.result == RESULTS.singular_configuration
    with pytest.raises(eqx.EquinoxRuntimeError, match="out of reach"):
        arm.inverse(np.array([0.7, 0.0]))


def test_bad_shapes_are_value_errors(no_jaxtyping):
    with pytest.raises(ValueError, match=r"`q` must have shape \(6,\)"):
        puma560_forward(np.zeros(5))
    with pytest.raises(ValueError, match="`SerialChain.alpha`"):
        SerialChain(a=(0.0, 1.0), alpha=(0.0,), S=(0.0, 0.0))
    with pytest.raises(ValueError, match="square Jacobian"):
        SerialChain(a=(0.0, 1.0), alpha=(0.0, 0.0), S=(0.0, 0.0)).inverse_velocity(
            np.zeros(2), np.zeros(6)
        )
    with pytest.raises(ValueError, match="`twist` must have shape"):
        CHAIN.inverse_velocity(np.zeros(6), np.zeros(3))


def test_solve_pose_under_jit_and_vmap():
    rng = np.random.default_rng(6)
    q_true = rng.uniform(-2.0, 2.0, (4, 6))
    q_true[:, 4] = rng.uniform(0.5, 2.5, 4)  # away from the wrist singularity
    R, p = jax.vmap(CHAIN.tool_pose)(q_true)
    guesses = q_true + 0.05 * rng.normal(size=q_true.shape)
    solve = jax.jit(jax.vmap(lambda R, p, g: CHAIN.solve_pose(R, p, g, throw=False)))
    sol = solve(R, p, guesses)
    assert np.all(np.asarray(sol.result._value) == int(RESULTS.successful._value))
    R2, p2 = jax.vmap(CHAIN.tool_pose)(sol.q)
    np.testing.assert_allclose(np.asarray(R2), np.asarray(R), atol=1e-10)
    np.testing.assert_allclose(np.asarray(p2), np.asarray(p), atol=1e-10)
    assert float(np.max(np.asarray(sol.residual))) < 1e-10


def test_two_link_gradients():
    arm = TwoLinkArm(0.35, 0.25)
    q = np.array([0.3, 0.9])
    for i in range(2):
        g = np.asarray(jax.jit(jax.grad(lambda q: arm.forward(q)[i]))(q))
        np.testing.assert_allclose(g, np.asarray(arm.jacobian(q))[i], atol=1e-14)
    # the inverse's derivative is the inverse Jacobian
    p = np.asarray(arm.forward(q))
    dq = np.asarray(jax.jacfwd(lambda p: arm.inverse(p))(p))
    np.testing.assert_allclose(dq, np.linalg.inv(np.asarray(arm.jacobian(q))), atol=1e-10)
