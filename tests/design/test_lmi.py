"""Seed 003, section 3.6: the LMI gain design with cvxpy and Clarabel."""

import numpy as np
import pytest

from visjax.design import LMIInfeasibleError, design_uio, max_lipschitz
from visjax.estimators import uio_residuals
from visjax.papers.jang import SETS

C = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


@pytest.mark.parametrize("name", list(SETS))
def test_design_is_feasible_and_passes_the_checks(name):
    s = SETS[name]
    A, D = np.array(s.A, float), np.array(s.D, float)[:, None]
    bound = max_lipschitz(A, C, D)
    assert bound > 0
    for uub in (False, True):
        b = max_lipschitz(A, C, D, uub=uub) if uub else bound
        d = design_uio(A, C, D, 0.9 * b, uub=uub)
        r = uio_residuals(A, C, D, d.K, d.Y)
        assert r["MD"] < 1e-9 and r["NM_LC_MA"] < 1e-9
        assert r["max_real_eig_N"] < 0
        assert d.max_eig_Q < 0
        # Q of (3.6) recomputed from scratch
        Q = (
            d.N.T @ d.P
            + d.P @ d.N
            + 0.9 * b * d.P @ d.M @ d.M.T @ d.P
            + (3 if uub else 2) * np.eye(3)
        )
        assert np.max(np.linalg.eigvalsh((Q + Q.T) / 2)) < 0
    # UUB asks for more (X11 + I): its largest bound is smaller
    assert max_lipschitz(A, C, D, uub=True) < bound


def test_infeasible_bound_raises_with_the_largest_feasible_one():
    s = SETS["I.1"]
    A, D = np.array(s.A, float), np.array(s.D, float)[:, None]
    best = max_lipschitz(A, C, D)
    with pytest.raises(
        LMIInfeasibleError,
        match=r"infeasible for gamma1\^2 \+ gamma2\^2 = 11\.2\d*.*largest feasible",
    ):
        design_uio(A, C, D, 10.0 * best)
    inside = design_uio(A, C, D, 0.99 * best)  # just inside: feasible
    assert np.max(np.real(np.linalg.eigvals(np.asarray(inside.N)))) < 0


def test_bad_input():
    with pytest.raises(ValueError, match="expected A"):
        design_uio(np.eye(2), C, np.ones((3, 1)), 1.0)
    with pytest.raises(ValueError, match="rank\\(CD\\)"):
        design_uio(np.eye(3), C, np.array([[0.0], [0.0], [1.0]]), 1.0)
    s = SETS["I.1"]
    with pytest.raises(ValueError, match="positive"):
        design_uio(np.array(s.A, float), C, np.array(s.D, float)[:, None], -1.0)
    with pytest.raises(ValueError, match=r"rank condition \(3.20\)"):
        design_uio(np.zeros((3, 3)), C, np.array([[1.0], [0.0], [0.0]]), 1.0)


def _A(u):
    from visjax.estimators import MOVING_POINT_A_U

    return np.einsum("j,jab->ab", np.asarray(u, float), MOVING_POINT_A_U)


@pytest.mark.parametrize("alpha", [0.3, 1.0])
def test_decay_rate_option(alpha):
    """Q + 2 alpha P < 0 (recomputed here): every eigenvalue of N has real part <= -alpha,
    and a simulated error e' = N e decays at least like exp(-alpha t) times the bound
    sqrt(cond P) of the docstring."""
    s = SETS["I.1"]
    A, D = np.array(s.A, float), np.array(s.D, float)
    b = max_lipschitz(A, C, D[:, None])
    d = design_uio(A, C, D, 0.5 * b, alpha=alpha)
    assert np.max(np.real(np.linalg.eigvals(d.N))) <= -alpha
    Q = d.N.T @ d.P + d.P @ d.N + 0.5 * b * d.P @ d.M @ d.M.T @ d.P + 2 * np.eye(3)
    assert np.max(np.linalg.eigvalsh(Q + 2 * alpha * d.P)) < 0
    from scipy.linalg import expm

    lam = np.linalg.eigvalsh(d.P)
    for t in (0.5, 2.0, 5.0):
        assert np.linalg.norm(expm(d.N * t), 2) <= np.sqrt(lam[-1] / lam[0]) * np.exp(-alpha * t)


def test_structured_gains_have_the_requested_pattern():
    """The thesis' published gains have K = [[k, 0], [0, k], [k31, 0]] and Y zero but for
    its second column: the designed gains have exactly those zeros (P diagonal), and still
    pass the checks of chapter 3."""
    s = SETS["I.1"]
    A, D = np.array(s.A, float), np.array(s.D, float)[:, None]
    Kp = np.array([[True, False], [False, True], [True, False]])
    Yp = np.array([[False, False], [False, True], [False, True]])
    d = design_uio(A, C, D, 0.3, K_pattern=Kp, Y_pattern=Yp, alpha=0.2)
    assert np.all(d.K[~Kp] == 0) and np.all(d.Y[~Yp] == 0)
    assert np.all(np.abs(d.K[Kp]) > 1e-6)
    assert np.all(d.P == np.diag(np.diag(d.P)))
    r = uio_residuals(A, C, D, d.K, d.Y)
    assert r["MD"] < 1e-9 and r["NM_LC_MA"] < 1e-9 and r["max_real_eig_N"] <= -0.2
    with pytest.raises(ValueError, match="`K_pattern` must be a boolean array of shape"):
        design_uio(A, C, D, 0.3, K_pattern=np.ones((2, 2), bool))
    # no gain at all: N = M0 A has an eigenvalue 0 for set I.1, whatever P
    none = np.zeros((3, 2), bool)
    with pytest.raises(LMIInfeasibleError, match="structure"):
        design_uio(A, C, D, 0.3, K_pattern=none, Y_pattern=none)


def test_polytopic_and_persistent_designs():
    """A camera velocity range: with the camera always moving sideways (v_cx in [0.5, 1]),
    one P certifies (3.6) plus a decay rate at every vertex, hence on the whole range; a
    range through v_cx = 0 (the depth unobservable there) makes every strict form
    infeasible, and the persistent form is feasible with V non-increasing at every
    velocity of the range (checked here on a grid, not only at the vertices)."""
    D = np.array([0.0, 1.0, 0.0])
    lo, hi = np.zeros(6), np.zeros(6)
    lo[0], hi[0] = 0.5, 1.0
    d = design_uio(np.zeros((3, 3)), C, D, 0.0, u_range=(lo, hi), alpha=0.1)
    for v in np.linspace(0.5, 1.0, 7):
        u = np.array([v, 0, 0, 0, 0, 0])
        N = d.M @ _A(u) - (d.K + np.einsum("j,jab->ab", u, d.K_u)) @ C
        assert np.max(np.real(np.linalg.eigvals(N))) <= -0.1
        Q = N.T @ d.P + d.P @ N + 2 * np.eye(3) + 0.2 * d.P
        assert np.max(np.linalg.eigvalsh(Q)) < 0
    lo[0] = -1.0
    with pytest.raises(LMIInfeasibleError):
        design_uio(np.zeros((3, 3)), C, D, 0.0, u_range=(lo, hi))
    with pytest.raises(ValueError, match="lipschitz = 0"):
        design_uio(np.zeros((3, 3)), C, D, 0.1, u_range=(lo, hi), persistent=True)
    p = design_uio(np.zeros((3, 3)), C, D, 0.0, u_range=(lo, hi), persistent=True, alpha=1.0)
    assert p.persistent and np.all(p.Y == 0)
    for v in np.linspace(-1.0, 1.0, 9):
        u = np.array([v, 0, 0, 0, 0, 0])
        N = p.M @ _A(u) - (p.K + np.einsum("j,jab->ab", u, p.K_u)) @ C
        S = N.T @ p.P + p.P @ N
        assert np.max(np.linalg.eigvalsh(S)) <= 1e-7 * np.linalg.norm(p.P) * np.linalg.norm(N)
        # the measured error decays: V' <= -2 |C e|^2
        assert np.max(np.linalg.eigvalsh(S + 2 * C.T @ C)) <= 1e-6
    # the depth is coupled to the measured error through the scheduled gain only
    assert abs(p.K_u[0, 2, 0]) > 0


def test_persistent_design_converges_faster_with_a_smaller_depth_weight():
    """`convergence_rate` (the Floquet exponent of e' = N(u(t)) e over one period of a
    sinusoidal sideways velocity) grows as the depth weight shrinks, with a fast
    measured-error decay (alpha = 5; with a slow one the coupled modes oscillate and the
    rate saturates), and is what `design_uio_for_motion` maximises under its gain bound."""
    from visjax.design import convergence_rate, design_uio_for_motion

    D = np.array([0.0, 1.0, 0.0])
    lo, hi = np.zeros(6), np.zeros(6)
    lo[0], hi[0] = -0.7, 0.7
    t = np.arange(250) * 0.02
    u = np.zeros((250, 6))
    u[:, 0] = 0.63 * np.cos(2 * np.pi * 0.2 * t)
    rates = []
    for w in (0.1, 0.01):
        d = design_uio(
            np.zeros((3, 3)),
            C,
            D,
            0.0,
            u_range=(lo, hi),
            persistent=True,
            depth_weight=w,
            alpha=5.0,
        )
        assert d.P[2, 2] <= w * (1 + 1e-6)
        rates.append(convergence_rate(d, np.zeros((3, 3)), C, u, 0.02))
    assert 0 < rates[0] < rates[1]
    best, rate = design_uio_for_motion(
        np.zeros((3, 3)), C, D, (lo, hi), u, 0.02, alphas=(5.0,), depth_weights=(0.1, 0.01)
    )
    assert rate == pytest.approx(max(rates), rel=1e-6)
    # independent check of the rate: a simulated error shrinks by exp(-rate T) per period
    from scipy.linalg import expm

    Phi = np.eye(3)
    for uk in u:
        N = best.M @ _A(uk) - (best.K + np.einsum("j,jab->ab", uk, best.K_u)) @ C
        Phi = expm(N * 0.02) @ Phi
    e = np.linalg.matrix_power(Phi, 4) @ np.array([0.0, 0.0, 0.1])
    assert np.linalg.norm(e) < 0.1 * np.exp(-rate * 20.0) * 10.0


def test_ultimate_bound_needs_a_uub_design():
    s = SETS["I.1"]
    A, D = np.array(s.A, float), np.array(s.D, float)[:, None]
    d = design_uio(A, C, D, 0.5)
    with pytest.raises(ValueError, match="uub=True"):
        d.ultimate_bound([0, 1, 0], 0.1)
    du = design_uio(A, C, D, 0.5, uub=True)
    b1, b2 = du.ultimate_bound([0, 1, 0], 0.1), du.ultimate_bound([0, 1, 0], 0.2)
    assert b1 > 0 and b2 == pytest.approx(2 * b1)


def test_certified_lipschitz_of_given_gains():
    from visjax.design import certified_lipschitz

    s = SETS["I.1"]
    A, D = np.array(s.A, float), np.array(s.D, float)[:, None]
    C = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    # gains designed for a bound certify at least that bound, and no gains certify more
    # than the largest bound any design reaches
    design = design_uio(A, C, D, 0.5)
    certified = certified_lipschitz(A, C, D, design.K, design.Y)
    assert 0.5 <= certified <= max_lipschitz(A, C, D) * (1 + 1e-3)
    # the published gains certify a positive bound; with K negated N is not Hurwitz: none
    assert certified_lipschitz(A, C, D, s.K, s.Y) > 0.0
    N_bad = certified_lipschitz(A, C, D, -np.array(s.K) * 10, s.Y)
    assert N_bad == 0.0
