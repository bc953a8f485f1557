"""Gain design of the unknown input observer: the LMI of seed 003, section 3.6 (cvxpy).

With $F = -D(CD)^+$, $G = I_2 - (CD)(CD)^+$, $P_K = PK$, $P_Y = PY$, condition (3.6),
$Q = N^TP + PN + (\\gamma_1^2 + \\gamma_2^2) P M M^T P + 2I_3 < 0$, is by a Schur complement

$$\\begin{bmatrix} X_{11} & X_{12} \\\\ X_{12}^T & -\\beta I_3 \\end{bmatrix} < 0,\\quad
\\beta = \\frac{1}{\\gamma_1^2 + \\gamma_2^2},$$

$X_{11} = A^T(I_3+FC)^TP + P(I_3+FC)A + A^TC^TG^TP_Y^T + P_YGCA - C^TP_K^T - P_KC + 2I_3$,
$X_{12} = P + PFC + P_YGC\\ (= PM)$; then $K = P^{-1}P_K$, $Y = P^{-1}P_Y$. The UUB variant
(a second unknown input treated as a bounded disturbance) uses $X_{11} + I_3$.

cvxpy's `<<` constrains only the symmetric part of an expression, so every block is built
symmetric ($S + S^T$). A pure feasibility problem returns a solver-dependent point on the
boundary, so the design minimises $\\mathrm{tr}(P) + \\mathrm{tr}(P^{-1}) + \\|P_K\\|_F +
\\|P_Y\\|_F$ (moderate, well conditioned gains), strict inequalities get a margin, only an
optimal status is accepted, and the gains are re-checked in NumPy. Design time only: never
inside jit.
"""

from dataclasses import dataclass

import numpy as np

from ..estimators import rank_condition

_MARGIN = 1e-6


class LMIInfeasibleError(ValueError):
    """The LMI of section 3.6 has no solution for the requested Lipschitz bound."""


@dataclass(frozen=True)
class UIODesign:
    """The result of `design_uio`: the LMI's `P`, the gains `K`, `Y`, and the observer
    matrices `E`, `M`, `N`, `L` (NumPy arrays), with the bound it was designed for and the
    largest eigenvalue of $Q$ of (3.6) (negative)."""

    P: np.ndarray
    K: np.ndarray
    Y: np.ndarray
    E: np.ndarray
    M: np.ndarray
    N: np.ndarray
    L: np.ndarray
    lipschitz: float
    max_eig_Q: float
    uub: bool


def _as_arrays(A, C, D):
    A = np.asarray(A, dtype=float)
    C = np.asarray(C, dtype=float)
    D = np.asarray(D, dtype=float).reshape(3, -1)
    if A.shape != (3, 3) or C.shape != (2, 3) or D.shape != (3, 1):
        raise ValueError(
            f"expected A (3, 3), C (2, 3), D (3, 1); got {A.shape}, {C.shape}, {D.shape}."
        )
    if np.linalg.matrix_rank(C @ D) != 1:
        raise ValueError("rank(CD) must be 1 (seed 003, section 3.4): this D is not seen by C.")
    if not rank_condition(A, C, D):
        raise ValueError(
            "(A, C, D) fails the rank condition (3.20) of Jang's thesis: rank [sI - A, D; C, 0]"
            " < 4 for some s, i.e. (M0 A, C) is not observable. No UIO gain exists, whatever "
            "the Lipschitz bound."
        )
    return A, C, D


def _lmi(A, C, D, beta, uub: bool):
    import cvxpy as cp

    CD = C @ D
    CD_pinv = np.linalg.pinv(CD)
    F = -D @ CD_pinv
    G = np.eye(2) - CD @ CD_pinv
    P = cp.Variable((3, 3), symmetric=True)
    PK = cp.Variable((3, 2))
    PY = cp.Variable((3, 2))
    IFC = np.eye(3) + F @ C
    S = P @ IFC @ A
    T = PY @ G @ C @ A
    U = PK @ C
    X11 = S + S.T + T + T.T - U - U.T + (3.0 if uub else 2.0) * np.eye(3)
    X12 = P + P @ F @ C + PY @ G @ C
    block = cp.bmat([[X11, X12], [X12.T, -beta * np.eye(3)]])
    constraints = [block << -_MARGIN * np.eye(6), P >> _MARGIN * np.eye(3)]
    return P, PK, PY, constraints


def _solve(problem):
    import cvxpy as cp

    try:
        problem.solve(solver=cp.CLARABEL)
    except cp.error.SolverError as err:  # pragma: no cover - solver crash
        return f"solver error: {err}"
    return problem.status


def design_uio(A, C, D, lipschitz: float, *, uub: bool = False) -> UIODesign:
    """Observer gains $(K, Y)$ from the LMI of section 3.6.

    **Arguments:**

    - `A` (3, 3), `C` (2, 3), `D` (3, 1): the system (3.1)-(3.2).
    - `lipschitz`: the bound $\\gamma_1^2 + \\gamma_2^2$ on the squared Lipschitz constant of
      $\\bar f$ (eq. (3.2)).
    - `uub`: the UUB variant ($X_{11} + I_3$) for a second unknown input treated as a
      bounded disturbance.

    **Returns:** a `UIODesign`. Raises `LMIInfeasibleError` (a `ValueError`) if the LMI is
    infeasible for that bound, with the largest feasible bound in the message.
    """
    import cvxpy as cp

    A, C, D = _as_arrays(A, C, D)
    if not lipschitz > 0:
        raise ValueError(f"`lipschitz` (gamma1^2 + gamma2^2) must be positive; got {lipschitz}.")
    P, PK, PY, constraints = _lmi(A, C, D, 1.0 / lipschitz, uub)
    # tr(P) + tr(P^-1) keeps P near the identity's scale without restricting feasibility
    # (minimising tr(P) alone shrinks P to the margin, and K = P^-1 P_K explodes).
    objective = cp.Minimize(cp.trace(P) + cp.tr_inv(P) + cp.norm(PK, "fro") + cp.norm(PY, "fro"))
    status = _solve(cp.Problem(objective, constraints))
    if status != cp.OPTIMAL:
        best = max_lipschitz(A, C, D, uub=uub)
        raise LMIInfeasibleError(
            f"the UIO LMI (seed 003, section 3.6) is infeasible for gamma1^2 + gamma2^2 = "
            f"{lipschitz:g} (solver status: {status}); the largest feasible bound for this "
            f"(A, C, D) is {best:.6g}."
        )
    Pv = np.asarray(P.value)
    K = np.linalg.solve(Pv, PK.value)
    Y = np.linalg.solve(Pv, PY.value)
    return _checked(A, C, D, Pv, K, Y, lipschitz, uub)


def _checked(A, C, D, P, K, Y, lipschitz, uub) -> UIODesign:
    """Re-check a design in NumPy: M D = 0, N Hurwitz, Q of (3.6) negative definite."""
    CD = C @ D
    CD_pinv = np.linalg.pinv(CD)
    E = -D @ CD_pinv + Y @ (np.eye(2) - CD @ CD_pinv)
    M = np.eye(3) + E @ C
    N = M @ A - K @ C
    L = K @ (np.eye(2) + C @ E) - M @ A @ E
    Q = N.T @ P + P @ N + lipschitz * P @ M @ M.T @ P + (3.0 if uub else 2.0) * np.eye(3)
    max_eig_Q = float(np.max(np.linalg.eigvalsh(0.5 * (Q + Q.T))))
    problems = []
    if np.linalg.norm(M @ D) > 1e-8:
        problems.append(f"|M D| = {np.linalg.norm(M @ D):.2e}")
    if np.max(np.real(np.linalg.eigvals(N))) >= 0:
        problems.append("N is not Hurwitz")
    if max_eig_Q >= 0:
        problems.append(f"Q of (3.6) has eigenvalue {max_eig_Q:.2e} >= 0")
    if problems:
        raise LMIInfeasibleError(
            "the LMI solution fails the re-check in NumPy: " + "; ".join(problems)
        )
    return UIODesign(P, K, Y, E, M, N, L, float(lipschitz), max_eig_Q, uub)


def max_lipschitz(A, C, D, *, uub: bool = False) -> float:
    """The largest $\\gamma_1^2 + \\gamma_2^2$ for which the LMI of section 3.6 is feasible.

    $\\beta = 1/(\\gamma_1^2 + \\gamma_2^2)$ becomes a decision variable and is minimised.
    Returns 0.0 if the LMI is infeasible for every bound.
    """
    import cvxpy as cp

    A, C, D = _as_arrays(A, C, D)
    beta = cp.Variable(nonneg=True)
    _, _, _, constraints = _lmi(A, C, D, beta, uub)
    status = _solve(cp.Problem(cp.Minimize(beta), constraints))
    if status != cp.OPTIMAL or beta.value is None or beta.value <= 0:
        return 0.0
    # step back from the boundary by the solver tolerance, so the bound is itself feasible
    return float(1.0 / (beta.value * (1.0 + 1e-4) + 1e-9))
