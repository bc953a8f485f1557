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
