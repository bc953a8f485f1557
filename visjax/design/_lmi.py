"""Gain design of the unknown input observer: the LMI of Jang's thesis, section 3.6 (cvxpy).

With $F = -D(CD)^+$, $G = I_2 - (CD)(CD)^+$, $P_K = PK$, $P_Y = PY$, condition (3.6),
$Q = N^TP + PN + (\\gamma_1^2 + \\gamma_2^2) P M M^T P + 2I_3 < 0$, is by a Schur complement

$$\\begin{bmatrix} X_{11} & X_{12} \\\\ X_{12}^T & -\\beta I_3 \\end{bmatrix} < 0,\\quad
\\beta = \\frac{1}{\\gamma_1^2 + \\gamma_2^2},$$

$X_{11} = A^T(I_3+FC)^TP + P(I_3+FC)A + A^TC^TG^TP_Y^T + P_YGCA - C^TP_K^T - P_KC + 2I_3$,
$X_{12} = P + PFC + P_YGC\\ (= PM)$; then $K = P^{-1}P_K$, $Y = P^{-1}P_Y$. The UUB variant
(a second unknown input treated as a bounded disturbance) uses $X_{11} + I_3$.

Options beyond the thesis (each with the inequality it adds, in `design_uio`): a decay rate
$\\alpha$ ($X_{11} + 2\\alpha P$), a gain structure (sparsity patterns of $K$ and $Y$, with
a diagonal $P$), and a camera-velocity range: a polytopic design with one $P$ for every
vertex of the range of $A(u)$ and a gain $K(u)$ affine in the velocity, either with (3.6)
at every vertex or, when the range contains velocities at which the depth is unobservable
(a camera that stops or reverses), the persistent-excitation form.

cvxpy's `<<` constrains only the symmetric part of an expression, so every block is built
symmetric ($S + S^T$). A pure feasibility problem returns a solver-dependent point on the
boundary, so the design minimises $\\mathrm{tr}(P) + \\mathrm{tr}(P^{-1}) + \\|P_K\\|_F +
\\|P_Y\\|_F$ (moderate, well conditioned gains), strict inequalities get a margin, only an
optimal status is accepted, and the gains are re-checked in NumPy. Design time only: never
inside jit.
"""

import itertools
from dataclasses import dataclass

import numpy as np

from ..estimators import MOVING_POINT_A_U, rank_condition, uio_matrices

_MARGIN = 1e-6


class LMIInfeasibleError(ValueError):
    """The LMI of section 3.6 has no solution for the requested Lipschitz bound."""


@dataclass(frozen=True)
class MovingPointDesign:
    """The result of `design_uio`: the LMI's `P`, the gains `K`, `Y`, and the observer
    matrices `E`, `M`, `N`, `L` (NumPy arrays), with the bound it was designed for and the
    largest eigenvalue of $Q$ of (3.6) (negative; with a velocity range, the largest over
    the vertices of the matrix each vertex must keep negative (semi)definite).

    With a velocity range: `A_u` (6, 3, 3) and `K_u` (6, 3, 2), the slopes of $A(u) = A +
    \\sum_j u_j A_{u,j}$ and $K(u) = K + \\sum_j u_j K_{u,j}$ (zeros for a fixed design);
    `N` is then $N(0)$, and `persistent` says which vertex inequality was used.
    `observer_fields()` gives the keyword arguments of
    `MovingPointEstimator` (`K`, `Y`, `A_u`, `K_u`, `P`)."""

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
    alpha: float = 0.0
    A_u: np.ndarray | None = None
    K_u: np.ndarray | None = None
    persistent: bool = False

    def observer_fields(self) -> dict:
        """`K`, `Y` (and for a velocity range `A_u`, `K_u`, `P`) as keyword arguments of
        `visjax.estimators.MovingPointEstimator`."""
        fields = {"K": self.K, "Y": self.Y}
        if self.A_u is not None:
            fields.update(A_u=self.A_u, K_u=self.K_u, P=self.P)
        return fields

    def ultimate_bound(self, D2, d2_max: float) -> float:
        """The ultimate bound on $\\|e\\|$ under a second unknown input $D_2 d_2$,
        $|d_2| \\le$ `d2_max` (the UUB split of the thesis, chapter 3), for a design
        with `uub=True`: with $V = e^TPe$ and $Q + I_3 \\prec 0$ (eq. (3.6) plus $I_3$),
        $\\dot V \\le -\\|e\\|^2 + 2\\|PMD_2\\|\\,\\|e\\|\\,|d_2|$, so $V$ decreases outside
        $\\|e\\| \\le 2\\|PMD_2\\| d_{2,\\max}$ and $\\|e\\|$ ends below
        $2\\|PMD_2\\| d_{2,\\max}\\sqrt{\\lambda_{\\max}(P)/\\lambda_{\\min}(P)}$."""
        if not self.uub:
            raise ValueError("`ultimate_bound` needs a design made with `uub=True`.")
        D2 = np.asarray(D2, float).reshape(3, 1)
        lam = np.linalg.eigvalsh(self.P)
        gain = np.linalg.norm(self.P @ self.M @ D2)
        return float(2.0 * gain * d2_max * np.sqrt(lam[-1] / lam[0]))


def _as_arrays(A, C, D):
    A = np.asarray(A, dtype=float)
    C = np.asarray(C, dtype=float)
    D = np.asarray(D, dtype=float)
    D = D.reshape(3, 1) if D.shape == (3,) else D
    if A.shape != (3, 3) or C.shape != (2, 3) or D.shape != (3, 1):
        raise ValueError(
            f"expected A (3, 3), C (2, 3), D (3, 1) or (3,); got {A.shape}, {C.shape}, {D.shape}."
        )
    if np.linalg.matrix_rank(C @ D) != 1:
        raise ValueError(
            "rank(CD) must be 1 (Jang's thesis, section 3.4): this D is not seen by C."
        )
    return A, C, D


def _check_rank(A, C, D, A_vertices):
    """(3.20) must hold for the fixed A, or at one vertex at least of a velocity range."""
    if not any(rank_condition(Av, C, D) for Av in A_vertices):
        raise ValueError(
            "(A, C, D) fails the rank condition (3.20) of Jang's thesis: rank [sI - A, D; C, 0]"
            " < 4 for some s, i.e. (M0 A, C) is not observable. No UIO gain exists, whatever "
            "the Lipschitz bound."
        )


def _pattern(p, shape, name):
    if p is None:
        return None
    p = np.asarray(p, dtype=bool)
    if p.shape != shape:
        raise ValueError(f"`{name}` must be a boolean array of shape {shape}; got {p.shape}.")
    return p


def _vertices(u_range):
    """The vertices of the box `u_range` = (u_min, u_max), each (6,); and which components
    vary."""
    u_min, u_max = (np.asarray(v, float) for v in u_range)
    if u_min.shape != (6,) or u_max.shape != (6,):
        raise ValueError(
            f"`u_range` must be (u_min, u_max), each of shape (6,); got {u_min.shape}, "
            f"{u_max.shape}."
        )
    if not (np.all(np.isfinite(u_min)) and np.all(np.isfinite(u_max)) and np.all(u_min <= u_max)):
        raise ValueError("`u_range` must be finite with u_min <= u_max componentwise.")
    varying = u_min < u_max
    corners = []
    for pick in itertools.product((0, 1), repeat=int(np.sum(varying))):
        v = u_min.copy()
        v[varying] = np.where(np.array(pick, bool), u_max[varying], u_min[varying])
        corners.append(v)
    return corners, varying


class _Problem:
    """The decision variables and the constraints of one design."""

    def __init__(self, C, D, diagonal_P, K_pattern, Y_pattern, K_u_pattern, Y_fixed=None):
        import cvxpy as cp

        self.C, self.D = C, D
        CD = C @ D
        CD_pinv = np.linalg.pinv(CD)
        self.F = -D @ CD_pinv
        self.G = np.eye(2) - CD @ CD_pinv
        if diagonal_P:
            p = cp.Variable(3)
            self.P = cp.diag(p)
            self.P_floor = [p >= _MARGIN]
        else:
            self.P = cp.Variable((3, 3), symmetric=True)
            self.P_floor = [self.P >> _MARGIN * np.eye(3)]
        self.PK = self._masked(cp, (3, 2), K_pattern)
        self.Y_fixed = Y_fixed
        if Y_fixed is None:
            self.PY = self._masked(cp, (3, 2), Y_pattern)
        else:  # a given Y: P_Y = P Y is linear in P
            self.PY = self.P @ Y_fixed
        self.PK_u = [
            None
            if K_u_pattern is None or not K_u_pattern[j].any()
            else self._masked(cp, (3, 2), K_u_pattern[j])
            for j in range(6)
        ]

    @staticmethod
    def _masked(cp, shape, pattern):
        if pattern is None:
            return cp.Variable(shape)
        free = cp.Variable(shape)
        return cp.multiply(pattern.astype(float), free)

    def PK_at(self, u):
        PK = self.PK
        for j, PKj in enumerate(self.PK_u):
            if PKj is not None and u[j] != 0.0:
                PK = PK + u[j] * PKj
        return PK

    def X11(self, A, u, strict: float, alpha: float, output_decay: bool):
        """$N^TP + PN$ (with $PN = P(I+FC)A + P_YGCA - P_K(u)C$) plus the decay and strict
        terms; symmetric by construction."""
        C = self.C
        S = self.P @ (np.eye(3) + self.F @ C) @ A + self.PY @ self.G @ C @ A - self.PK_at(u) @ C
        X = S + S.T + strict * np.eye(3)
        if output_decay:  # persistent excitation: only the measured error decays
            CtC = C.T @ C
            X = X + 2.0 * alpha * CtC @ self.P @ CtC + 2.0 * CtC
        elif alpha > 0:
            X = X + 2.0 * alpha * self.P
        return X

    def PM(self):
        C = self.C
        return self.P + self.P @ self.F @ C + self.PY @ self.G @ C

    def values(self):
        P = np.asarray(self.P.value, float)
        P = 0.5 * (P + P.T)
        K = np.linalg.solve(P, np.asarray(self.PK.value, float))
        if self.Y_fixed is None:
            Y = np.linalg.solve(P, np.asarray(self.PY.value, float))
        else:
            Y = np.array(self.Y_fixed, float)
        K_u = np.zeros((6, 3, 2))
        for j, PKj in enumerate(self.PK_u):
            if PKj is not None:
                K_u[j] = np.linalg.solve(P, np.asarray(PKj.value, float))
        return P, K, Y, K_u


def _constraints(prob, A_list, u_list, beta, lipschitz, uub, alpha, persistent):
    import cvxpy as cp

    cons = list(prob.P_floor)
    for A, u in zip(A_list, u_list):
        if persistent:
            X = prob.X11(A, u, 0.0, alpha, True)
            cons.append(X << 0)
        else:
            X = prob.X11(A, u, 3.0 if uub else 2.0, alpha, False)
            if lipschitz == 0:
                cons.append(X << -_MARGIN * np.eye(3))
            else:
                X12 = prob.PM()
                block = cp.bmat([[X, X12], [X12.T, -beta * np.eye(3)]])
                cons.append(block << -_MARGIN * np.eye(6))
    return cons


def _solve(problem):
    import cvxpy as cp

    try:
        problem.solve(solver=cp.CLARABEL)
    except cp.error.SolverError as err:  # pragma: no cover - solver crash
        return f"solver error: {err}"
    return problem.status


def design_uio(
    A,
    C,
    D,
    lipschitz: float,
    *,
    uub: bool = False,
    alpha: float = 0.0,
    K_pattern=None,
    Y_pattern=None,
    u_range=None,
    A_u=None,
    K_u_pattern=None,
    persistent: bool = False,
    depth_weight: float | None = None,
    Y=None,
) -> MovingPointDesign:
    """Observer gains $(K, Y)$ from the LMI of section 3.6 (Jang's thesis, eq. (3.6)).

    **Arguments:**

    - `A` (3, 3), `C` (2, 3), `D` (3, 1) or (3,): the system (3.1)-(3.2); with `u_range`,
      `A` is the constant part of $A(u)$.
    - `lipschitz`: the bound $\\gamma_1^2 + \\gamma_2^2$ on the squared Lipschitz constant of
      $\\bar f$ (eq. (3.2)); 0 when $\\bar f = f - Ax$ vanishes (no Schur block: $X_{11}
      \\prec 0$ alone), e.g. a camera that only translates parallel to the image plane, with
      $A(u)$ the thesis' $A$ of the camera velocities.
    - `uub`: the UUB variant ($X_{11} + I_3$) for a second unknown input treated as a
      bounded disturbance (`MovingPointDesign.ultimate_bound`).
    - `alpha`: a decay rate $\\alpha \\ge 0$: $X_{11} + 2\\alpha P$ in place of $X_{11}$,
      i.e. $Q + 2\\alpha P \\prec 0$, so $\\dot V \\le -2\\alpha V$ for $V = e^TPe$ and
      $\\|e(t)\\| \\le \\sqrt{\\lambda_{\\max}(P)/\\lambda_{\\min}(P)}\\,\\|e(0)\\|
      e^{-\\alpha t}$ (Theorem 3.1 with the rate made explicit); every eigenvalue of $N$
      then has real part $\\le -\\alpha$.
    - `K_pattern`, `Y_pattern`: (3, 2) booleans, `True` where the gain may be non-zero
      (a structured gain, like the thesis' published ones). $K = P^{-1}P_K$ keeps the
      sparsity of $P_K$ only for a diagonal $P$, so with a pattern $P$ is diagonal (a
      restriction: the structured LMI may be infeasible where the full one is not).
    - `u_range`: `(u_min, u_max)`, each (6,): the range of the camera velocity
      $u = [v_c, \\omega]$. The design is then polytopic: $A(u) = A + \\sum_j u_j A_{u,j}$
      (`A_u`, default `MOVING_POINT_A_U`, the thesis' $A$ of the camera velocities) and
      $K(u) = K + \\sum_j u_j K_{u,j}$ for the varying components ($K_{u,j}$ free where
      `K_u_pattern` (6, 3, 2) allows, default every entry of every varying component);
      one $P$ for all vertices of the box. $N(u)^TP + PN(u)$ is affine in $u$, so the
      inequality at the vertices holds on the whole box.
    - `persistent`: with `u_range`, the persistent-excitation form. If the box contains a
      velocity at which the depth is unobservable (the camera at rest, or a sideways
      velocity that changes sign), no $P$ can make $V$ decrease in the depth direction
      there, and every strict form above is infeasible. The persistent form asks, at every
      vertex, $N(u)^TP + PN(u) + 2\\alpha C^TCPC^TC + 2C^TC \\preceq 0$: $V$ never
      increases and the measured error decays ($\\dot V \\le -2\\|Ce\\|^2$). The depth error
      then converges exponentially when the camera velocity is persistently exciting (the
      usual argument for a Lyapunov function whose derivative is negative in the measured
      directions: the pair $(N(u(t)), C)$ uniformly observable over a window), at a rate
      set by the excitation, not by $\\alpha$. It needs `lipschitz = 0` (the Lipschitz
      term is strict in every direction).
    - `Y`: a given (3, 2) $Y$ instead of a designed one ($P_Y = PY$ is then linear in
      $P$). The persistent form fixes `Y = 0` by default: then $E = -D(CD)^+$ and the
      measured rows of $M = I_3 + EC$ are the projector $I_2 - (CD)(CD)^+$, so the depth
      error stays visible in the measured error. (The thesis' choice $CE = -I_2$ zeroes
      those rows: the depth error then reaches the measured error only through
      $N_{33} = (MA(u))_{33}$, which changes sign with the velocity and which the
      persistent form must therefore set to 0, leaving the depth uncorrected.)
    - `depth_weight`: an upper bound on $P_{33}$, the weight of the depth error in
      $V = e^TPe$ (a linear constraint). With the persistent form, a small weight makes
      the depth gain ($K_{u,31} \\approx P_{11}(1 + Y_{11})/P_{33}$ for a sideways
      velocity, the cross terms of $V$ cancelling) large, and the depth converge faster
      under the same excitation (`convergence_rate`, `design_uio_for_motion`).

    **Returns:** a `MovingPointDesign` (`observer_fields()` for `MovingPointEstimator`). Raises
    `LMIInfeasibleError` (a `ValueError`) if the LMI is infeasible, with the largest
    feasible bound in the message for the fixed design.
    """
    import cvxpy as cp

    A, C, D = _as_arrays(A, C, D)
    if not lipschitz >= 0:
        raise ValueError(
            f"`lipschitz` (gamma1^2 + gamma2^2) must be positive (or 0 for a vanishing "
            f"f_bar); got {lipschitz}."
        )
    if not (np.isfinite(alpha) and alpha >= 0):
        raise ValueError(f"`alpha` (the decay rate) must be finite and >= 0; got {alpha}.")
    K_pattern = _pattern(K_pattern, (3, 2), "K_pattern")
    Y_pattern = _pattern(Y_pattern, (3, 2), "Y_pattern")
    if Y is None and persistent:
        Y = np.zeros((3, 2))
    if Y is not None:
        Y = np.asarray(Y, float)
        if Y.shape != (3, 2) or not np.all(np.isfinite(Y)):
            raise ValueError(f"`Y` must be a finite (3, 2) array; got shape {Y.shape}.")
        if Y_pattern is not None:
            raise ValueError("give either a fixed `Y` or a `Y_pattern`, not both.")
    if u_range is None:
        if persistent or A_u is not None or K_u_pattern is not None:
            raise ValueError("`persistent`, `A_u` and `K_u_pattern` need a `u_range`.")
        u_list = [np.zeros(6)]
        A_list = [A]
        A_u_arr = None
        K_u_pattern = None
    else:
        u_list, varying = _vertices(u_range)
        A_u_arr = MOVING_POINT_A_U.copy() if A_u is None else np.asarray(A_u, float)
        if A_u_arr.shape != (6, 3, 3):
            raise ValueError(f"`A_u` must have shape (6, 3, 3); got {A_u_arr.shape}.")
        if K_u_pattern is None:
            K_u_pattern = np.zeros((6, 3, 2), bool)
            K_u_pattern[varying] = True
        K_u_pattern = _pattern(K_u_pattern, (6, 3, 2), "K_u_pattern")
        A_list = [A + np.einsum("j,jab->ab", u, A_u_arr) for u in u_list]
    if persistent and lipschitz != 0:
        raise ValueError(
            "the persistent-excitation design needs `lipschitz = 0`: the Lipschitz term of "
            "(3.6) asks for strict decay in every direction, impossible where the depth is "
            "unobservable."
        )
    _check_rank(A, C, D, A_list)
    structured = (
        K_pattern is not None
        or Y_pattern is not None
        or (u_range is not None and not np.all(K_u_pattern[np.any(K_u_pattern, (1, 2))]))
    )
    prob = _Problem(C, D, structured, K_pattern, Y_pattern, K_u_pattern, Y)
    beta = 1.0 / lipschitz if lipschitz > 0 else None
    constraints = _constraints(prob, A_list, u_list, beta, lipschitz, uub, alpha, persistent)
    if depth_weight is not None:
        if not (np.isfinite(depth_weight) and depth_weight > 0):
            raise ValueError(f"`depth_weight` must be positive and finite; got {depth_weight}.")
        constraints.append(prob.P[2, 2] <= depth_weight)
    # tr(P) + tr(P^-1) keeps P near the identity's scale without restricting feasibility
    # (minimising tr(P) alone shrinks P to the margin, and K = P^-1 P_K explodes).
    gains = cp.norm(prob.PK, "fro") + (0 if Y is not None else cp.norm(prob.PY, "fro"))
    for PKj in prob.PK_u:
        if PKj is not None:
            gains = gains + cp.norm(PKj, "fro")
    objective = cp.Minimize(cp.trace(prob.P) + cp.tr_inv(prob.P) + gains)
    status = _solve(cp.Problem(objective, constraints))
    if status != cp.OPTIMAL:
        if u_range is None and alpha == 0 and not structured and lipschitz > 0:
            best = max_lipschitz(A, C, D, uub=uub)
            extra = f"; the largest feasible bound for this (A, C, D) is {best:.6g}."
        else:
            extra = " with these options (decay rate, structure, velocity range)."
        raise LMIInfeasibleError(
            f"the UIO LMI (Jang's thesis, section 3.6) is infeasible for gamma1^2 + gamma2^2 = "
            f"{lipschitz:g} (solver status: {status})" + extra
        )
    P, K, Y, K_u = prob.values()
    return _checked(A, C, D, P, K, Y, lipschitz, uub, alpha, A_u_arr, K_u, u_list, persistent)


def _uio_numpy(A, C, D, K, Y):
    """$E, M, N, L$ of eq. (3.5) as float64 NumPy arrays: `estimators.uio_matrices`, the
    one derivation, evaluated in float64 whatever the process's JAX precision (a scoped
    `jax.enable_x64`, restored on exit)."""
    import jax

    with jax.enable_x64(True):
        return tuple(np.asarray(m, float) for m in uio_matrices(A, C, D, K, Y))


def _checked(
    A,
    C,
    D,
    P,
    K,
    Y,
    lipschitz,
    uub,
    alpha=0.0,
    A_u=None,
    K_u=None,
    u_list=None,
    persistent=False,
) -> MovingPointDesign:
    """Re-check a design in NumPy: M D = 0; for a fixed design N Hurwitz with real parts
    <= -alpha and Q of (3.6) (+ 2 alpha P) negative definite; for a velocity range the
    vertex inequalities."""
    E, M, N, L = _uio_numpy(A, C, D, K, Y)
    strict = 3.0 if uub else 2.0
    problems = []
    if np.linalg.norm(M @ D) > 1e-8:
        problems.append(f"|M D| = {np.linalg.norm(M @ D):.2e}")
    if u_list is None or A_u is None:
        u_list, A_u, K_u = [np.zeros(6)], np.zeros((6, 3, 3)), np.zeros((6, 3, 2))
        fixed = True
    else:
        fixed = False
    worst = -np.inf
    scale = np.linalg.norm(P)
    for u in u_list:
        Nu = M @ (A + np.einsum("j,jab->ab", u, A_u)) - (K + np.einsum("j,jab->ab", u, K_u)) @ C
        if persistent:
            CtC = C.T @ C
            Q = Nu.T @ P + P @ Nu + 2.0 * alpha * CtC @ P @ CtC + 2.0 * CtC
            limit = 1e-6 * max(scale * np.linalg.norm(Nu), 1.0)
        else:
            Q = Nu.T @ P + P @ Nu + lipschitz * P @ M @ M.T @ P + strict * np.eye(3)
            Q = Q + 2.0 * alpha * P
            limit = 0.0
            if np.max(np.real(np.linalg.eigvals(Nu))) > -alpha + 1e-9 * (1 + alpha):
                problems.append(f"N at u = {u} has an eigenvalue with real part > -alpha")
        q = float(np.max(np.linalg.eigvalsh(0.5 * (Q + Q.T))))
        worst = max(worst, q)
        if q > limit or (not persistent and q >= 0):
            problems.append(f"Q of (3.6) at u = {u} has eigenvalue {q:.2e}")
    if problems:
        raise LMIInfeasibleError(
            "the LMI solution fails the re-check in NumPy: " + "; ".join(problems)
        )
    return MovingPointDesign(
        P,
        K,
        Y,
        E,
        M,
        N,
        L,
        float(lipschitz),
        worst,
        uub,
        float(alpha),
        None if fixed else A_u,
        None if fixed else K_u,
        bool(persistent),
    )


def max_lipschitz(A, C, D, *, uub: bool = False) -> float:
    """The largest $\\gamma_1^2 + \\gamma_2^2$ for which the LMI of section 3.6 is feasible.

    $\\beta = 1/(\\gamma_1^2 + \\gamma_2^2)$ becomes a decision variable and is minimised.
    Returns 0.0 if the LMI is infeasible for every bound.
    """
    import cvxpy as cp

    A, C, D = _as_arrays(A, C, D)
    _check_rank(A, C, D, [A])
    beta = cp.Variable(nonneg=True)
    prob = _Problem(C, D, False, None, None, None)
    constraints = _constraints(prob, [A], [np.zeros(6)], beta, 1.0, uub, 0.0, False)
    status = _solve(cp.Problem(cp.Minimize(beta), constraints))
    if status != cp.OPTIMAL or beta.value is None or beta.value <= 0:
        return 0.0
    # step back from the boundary by the solver tolerance, so the bound is itself feasible
    return float(1.0 / (beta.value * (1.0 + 1e-4) + 1e-9))


def convergence_rate(design: MovingPointDesign, A, C, u_samples, dt: float) -> float:
    """The exponential rate at which the estimation error decays over a planned camera
    motion: $-\\ln \\rho(\\Phi)/T$, with $\\Phi = \\prod_k \\exp(N(u_k)\\,dt)$ the
    transition matrix of $\\dot e = N(u(t)) e$ (eq. (3.5) with $\\bar f = 0$ and no
    unknown input: the error dynamics of the persistent design) over the held velocity
    samples `u_samples` (n, 6), `dt` apart, $T = n\\,dt$ and $\\rho$ the spectral radius.
    For a periodic motion sampled over one period this is the Floquet exponent (exact for
    the held samples); otherwise the average rate over the window.

    **Arguments:** `design` a `MovingPointDesign`; `A` (3, 3) the constant part of $A(u)$ it was
    designed for; `C` (2, 3); `u_samples` (n, 6); `dt` > 0.
    """
    from scipy.linalg import expm

    A = np.asarray(A, float)
    C = np.asarray(C, float)
    u_samples = np.asarray(u_samples, float)
    if u_samples.ndim != 2 or u_samples.shape[1] != 6:
        raise ValueError(f"`u_samples` must have shape (n, 6); got {u_samples.shape}.")
    if not dt > 0:
        raise ValueError(f"`dt` must be positive; got {dt}.")
    A_u = np.zeros((6, 3, 3)) if design.A_u is None else design.A_u
    K_u = np.zeros((6, 3, 2)) if design.K_u is None else design.K_u
    Phi = np.eye(3)
    for u in u_samples:
        N = design.M @ (A + np.einsum("j,jab->ab", u, A_u))
        N = N - (design.K + np.einsum("j,jab->ab", u, K_u)) @ C
        Phi = expm(N * dt) @ Phi
    rho = np.max(np.abs(np.linalg.eigvals(Phi)))
    return float(-np.log(max(rho, 1e-300)) / (u_samples.shape[0] * dt))


def design_uio_for_motion(
    A,
    C,
    D,
    u_range,
    u_samples,
    dt: float,
    *,
    alphas=(0.5, 1.0, 2.0, 5.0, 10.0),
    depth_weights=(1.0, 0.3, 0.1, 0.03, 0.01, 3e-3, 1e-3),
    max_gain: float = 100.0,
    **options,
):
    """The persistent-excitation design (`design_uio(..., persistent=True)`) whose error
    decays fastest over a planned camera motion.

    For a camera whose velocity range contains velocities at which the depth is
    unobservable (it stops, or a sideways velocity changes sign), no LMI can certify a
    decay rate (see `design_uio`, `persistent`); the convergence comes from the excitation.
    This grid-searches the two knobs of the persistent LMI, the measured-error decay rate
    `alpha` and the `depth_weight`, keeps the designs whose gains stay below `max_gain`
    (largest entry of $K(u)$, $Y$ over the vertices: a bound on noise amplification), and
    returns the one with the largest `convergence_rate` over the planned velocity samples.
    Every candidate carries the LMI certificate (its Lyapunov function never increases
    over the whole `u_range`); only the choice among them uses the planned motion.

    **Arguments:** `A`, `C`, `D`, `u_range` as in `design_uio` (with `lipschitz = 0`);
    `u_samples` (n, 6), `dt`: the planned camera velocity (e.g. one period), as in
    `convergence_rate`; `alphas`, `depth_weights`: the grid; `max_gain`; other keyword
    `options` go to `design_uio`.

    **Returns:** `(design, rate)`. Raises `LMIInfeasibleError` if no candidate is feasible
    within `max_gain`.
    """
    best, best_rate = None, -np.inf
    corners, _ = _vertices(u_range)
    for alpha in alphas:
        for w in depth_weights:
            try:
                d = design_uio(
                    A,
                    C,
                    D,
                    0.0,
                    u_range=u_range,
                    persistent=True,
                    alpha=alpha,
                    depth_weight=w,
                    **options,
                )
            except LMIInfeasibleError:
                continue
            gain = max(np.max(np.abs(d.K + np.einsum("j,jab->ab", u, d.K_u))) for u in corners)
            if gain > max_gain or np.max(np.abs(d.Y)) > max_gain:
                continue
            rate = convergence_rate(d, A, C, u_samples, dt)
            if rate > best_rate:
                best, best_rate = d, rate
    if best is None:
        raise LMIInfeasibleError(
            "no persistent-excitation design on the grid is feasible with gains below "
            f"`max_gain` = {max_gain:g}."
        )
    return best, best_rate


def certified_lipschitz(A, C, D, K, Y, *, uub: bool = False) -> float:
    """The largest $\\gamma_1^2 + \\gamma_2^2$ for which given gains $(K, Y)$ satisfy the LMI
    of section 3.6 (Jang's thesis, condition (3.6)): some $P \\succ 0$ with
    $N^TP + PN + (\\gamma_1^2 + \\gamma_2^2)PMM^TP + 2I_3 \\prec 0$ ($+I_3$ more for `uub`),
    $N$, $M$ of eq. (3.5) from the gains. By the Schur complement of the module docstring
    with $K$, $Y$ fixed the condition is linear in $(P, \\beta)$; $\\beta$ is minimised.

    Returns 0.0 when the condition fails even for $\\bar f = 0$ (then $N$ is not Hurwitz),
    `inf` when every bound is certified (M = 0). Use it to check gains found by a sweep or
    by `studies.tune`: they satisfy the thesis' design condition for the Lipschitz bound
    the returned value covers.
    """
    import cvxpy as cp

    A, C, D = _as_arrays(A, C, D)
    K, Y = np.asarray(K, float), np.asarray(Y, float)
    _, M, N, _ = _uio_numpy(A, C, D, K, Y)  # eq. (3.5)
    P = cp.Variable((3, 3), symmetric=True)
    beta = cp.Variable(nonneg=True)
    X = N.T @ P + P @ N + (3.0 if uub else 2.0) * np.eye(3)
    X = 0.5 * (X + X.T)
    block = cp.bmat([[X, P @ M], [(P @ M).T, -beta * np.eye(3)]])
    block = 0.5 * (block + block.T)
    cons = [P >> _MARGIN * np.eye(3), block << -_MARGIN * np.eye(6)]
    status = _solve(cp.Problem(cp.Minimize(beta), cons))
    if status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or beta.value is None:
        return 0.0
    if beta.value <= 1e-12:
        return float("inf")
    return float(1.0 / (beta.value * (1.0 + 1e-4) + 1e-9))
