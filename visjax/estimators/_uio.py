"""The unknown input observer (UIO) of Jang's thesis (chapters 2-3).

Perspective dynamics of a point seen by a moving camera, in the state
$x = [X/Z, Y/Z, 1/Z]$ with output $y = [x_1, x_2]$, measured camera velocities
$u = [v_c, \\omega]$ and the point's own velocity as unknown input (eq. (2.11)); the observer
(3.5) $\\dot z = N z + L y + M \\bar f(\\hat x, u) + M g(y, u)$, $\\hat x = z - E y$; and the
checks of chapter 3. Equation numbers are the thesis'; `THESIS_NOTES.md` restates them.

Beyond the thesis' examples the observer takes any $(A, C, D)$ of the thesis' class: $D$
given as (3,) or (3, 1); a second unknown input $D_2$ treated as a bounded disturbance
(the UUB split $D d = D_1 d_1 + D_2 d_2$ of chapter 3, THESIS_NOTES "UUB extension");
and a matrix $A(u)$ that follows the measured camera velocity sample by sample, with a gain
$K(u)$ scheduled on it (both affine in $u$; `visjax.design.design_uio` designs them).
"""

import functools
from typing import final

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .._results import all_finite
from .._util import as_float, check_shape, positive_finite
from ..geometry import pixel_to_normalized
from ..kinematics import camera_term, known_input_term
from ._base import (
    AbstractEstimator,
    Innovation,
    Stream,
    checked_samples,
    innovation,
    reject_mask,
)

C_OUTPUT = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0))  # y = C x, eq. (3.1)


def _moving_point_A_u() -> np.ndarray:
    """$A(u) = \\sum_j u_j A_j$ with $A(u) = [[0, \\omega_z, -v_{cx}], [-\\omega_z, 0,
    -v_{cy}], [0, 0, 0]]$, the thesis' $A$ of the camera velocities (Jang's thesis, ch. 6;
    THESIS_NOTES ch. 3.4, restored); $u = [v_{cx}, v_{cy}, v_{cz}, \\omega_x, \\omega_y,
    \\omega_z]$."""
    A_u = np.zeros((6, 3, 3))
    A_u[0, 0, 2] = -1.0  # -v_cx
    A_u[1, 1, 2] = -1.0  # -v_cy
    A_u[5, 0, 1] = 1.0  # w_z
    A_u[5, 1, 0] = -1.0  # -w_z
    return A_u


MOVING_POINT_A_U = _moving_point_A_u()
"""(6, 3, 3): the slopes $A_j = \\partial A / \\partial u_j$ of the thesis' $A(u)$; pass it as
`MovingPointEstimator(A=np.zeros((3, 3)), A_u=MOVING_POINT_A_U, ...)` for $A$ from the measured
camera velocities."""


_ZEROS_33 = ((0.0,) * 3,) * 3  # immutable defaults of the fields
_ZEROS_633 = (_ZEROS_33,) * 6
_ZEROS_632 = (((0.0,) * 2,) * 3,) * 6


def _column(x):
    """A direction of an unknown input as a (3, 1) column: (3,) is accepted."""
    x = as_float(x)
    return jnp.reshape(x, (3, 1)) if x.shape == (3,) else x


def _pinv_col(CD):
    """Pseudo-inverse of a 2x1 column in closed form (differentiable); 0 for a zero column,
    so that D = 0 (no unknown input) gives the ordinary observer."""
    n2 = jnp.sum(CD**2)
    nonzero = n2 > 0.0
    return jnp.where(nonzero, CD.T / jnp.where(nonzero, n2, 1.0), 0.0)


def uio_matrices(A, C, D, K, Y):
    """$E, M, N, L$ of the observer (3.5) from $(A, C, D, K, Y)$.

    $E = -D(CD)^+ + Y(I_2 - (CD)(CD)^+)$, $M = I_3 + E C$, $N = M A - K C$,
    $L = K(I_2 + C E) - M A E$.

    **Arguments:** `A` (3, 3), `C` (2, 3), `D` (3, 1) or (3,), `K` (3, 2), `Y` (3, 2).

    **Returns:** `(E, M, N, L)`, shapes (3, 2), (3, 3), (3, 3), (3, 2).
    """
    A, C, K, Y = (as_float(m) for m in (A, C, K, Y))
    D = _column(D)
    check_shape(A, (3, 3), "A")
    check_shape(C, (2, 3), "C")
    check_shape(D, (3, 1), "D")
    check_shape(K, (3, 2), "K")
    check_shape(Y, (3, 2), "Y")
    CD = C @ D
    CD_pinv = _pinv_col(CD)
    I2 = jnp.eye(2, dtype=A.dtype)
    E = -D @ CD_pinv + Y @ (I2 - CD @ CD_pinv)
    M = jnp.eye(3, dtype=A.dtype) + E @ C
    N = M @ A - K @ C
    L = K @ (I2 + C @ E) - M @ A @ E
    return E, M, N, L


def uio_residuals(A, C, D, K, Y) -> dict:
    """The conditions of chapter 3 as numbers: `MD` ($\\|MD\\|$, must be 0), `NM_LC_MA`
    ($\\|NM + LC - MA\\|$, must be 0), `max_real_eig_N` (must be < 0: $N$ Hurwitz)."""
    E, M, N, L = uio_matrices(A, C, D, K, Y)
    D = _column(D)
    return {
        "MD": jnp.linalg.norm(M @ D),
        "NM_LC_MA": jnp.linalg.norm(N @ M + L @ as_float(C) - M @ as_float(A)),
        "max_real_eig_N": jnp.max(jnp.real(jnp.linalg.eigvals(jax.lax.stop_gradient(N)))),
    }


def rank_condition(A, C, D, *, tol: float = 1e-9) -> bool:
    """The rank condition (3.20) and $\\mathrm{rank}(CD) = \\mathrm{rank}(D) = 1$.

    (3.20): $\\mathrm{rank}\\begin{bmatrix} sI_3 - A & D \\\\ C & 0 \\end{bmatrix} = 4$ for
    every complex $s$. Given $\\mathrm{rank}(CD) = \\mathrm{rank}(D)$, it holds exactly when
    $(M_0 A, C)$ is observable, $M_0 = I_3 - D(CD)^+C$ (the thesis, section 3.4): the pencil can
    lose rank only at an unobservable eigenvalue of $M_0 A$. Both are evaluated here: the
    observability matrix, and the pencil's rank at every eigenvalue of $M_0 A$. NumPy, a
    design-time check (not jit).
    """
    A, C = (np.asarray(m, dtype=float) for m in (A, C))
    D = np.asarray(D, dtype=float).reshape(3, -1)
    if np.linalg.matrix_rank(C @ D, tol) != 1 or np.linalg.matrix_rank(D, tol) != 1:
        return False
    CD = C @ D
    M0 = np.eye(3) - D @ np.linalg.pinv(CD) @ C
    MA = M0 @ A
    obs = np.vstack([C, C @ MA, C @ MA @ MA])
    if np.linalg.matrix_rank(obs, tol) < 3:
        return False
    for s in np.linalg.eigvals(MA):
        pencil = np.block([[s * np.eye(3) - A, D], [C, np.zeros((2, 1))]])
        if np.linalg.matrix_rank(pencil, tol) < 4:
            return False
    return True


@final
class MovingPointMeasurement(eqx.Module):
    """One sample (or, in a `Stream`, all samples: a leading axis) for the UIO: `y` (2,) the
    point's normalized image coordinates
    $[x_1, x_2]$ (eq. (3.1)); `u` (6,) the camera velocities $[v_c, \\omega]$ (camera basis)."""

    y: Float[Array, "*batch 2"]
    u: Float[Array, "*batch 6"]


@final
class MovingPointState(eqx.Module):
    """The observer state $z$ of eq. (3.5); $\\hat x = z - E y$."""

    z: Float[Array, "3"]


@final
class MovingPointOutput(eqx.Module):
    """$\\hat x = [\\hat x_1, \\hat x_2, \\hat x_3]$ ($[X/Z, Y/Z, 1/Z]$) and the point's
    position in the camera frame, $[\\hat x_1/\\hat x_3, \\hat x_2/\\hat x_3, 1/\\hat x_3]$ (in
    the units of the camera velocities)."""

    x_hat: Float[Array, "3"]
    position: Float[Array, "3"]


@final
class MovingPointEstimator(AbstractEstimator):
    """The nonlinear unknown input observer of eq. (3.5).

    $\\dot z = N z + L y + M \\bar f(\\hat x, u) + M g(y, u)$, $\\hat x = z - E y$, with
    $\\bar f(x, u) = f(x, u) - A x$ (eq. (3.2)) and $E, M, N, L$ from `uio_matrices`.
    Measurements are `MovingPointMeasurement`s (`moving_point_stream`).

    **The system.** $\\dot x = A x + \\bar f(x, u) + g(y, u) + D_1 d_1 + D_2 d_2$ (eqs. (3.1),
    (3.2)). $D_1$ (`D`) is decoupled exactly ($M D_1 = 0$, eq. (3.5)); $D_2$ (`D2`, default
    0) is the second unknown input of the UUB split (the thesis, chapter 3), not
    decoupled: it enters the error as $\\dot e = N e + M(\\bar f(\\hat x) - \\bar f(x)) -
    M D_2 d_2$ (`disturbance_input` returns $M D_2$), so the error is uniformly ultimately
    bounded, in proportion to $\\sup |d_2|$, when $N$ satisfies the UUB condition $Q + I_3 <
    0$ of (3.6) (`visjax.design.design_uio(..., uub=True)`).

    **Time-varying A.** With `A_u` (6, 3, 3) or `K_u` (6, 3, 2) non-zero, $A$ and $K$
    follow the held camera velocity $u$ of each sample:
    $A(u) = A + \\sum_j u_j A_{u,j}$ (`MOVING_POINT_A_U` gives the thesis' $A$ of the camera
    velocities, $[[0, \\omega_z, -v_{cx}], [-\\omega_z, 0, -v_{cy}], [0, 0, 0]]$) and
    $K(u) = K + \\sum_j u_j K_{u,j}$; then $N(u) = M A(u) - K(u) C$, $L(u) = K(u)(I_2 + C E)
    - M A(u) E$, and (3.5) holds sample by sample ($E$, $M$ stay constant, so
    $N M + L C - M A = 0$ and $M D_1 = 0$ at every $u$). A frozen-time Hurwitz test proves
    nothing for a time-varying $N(u)$ (and fails wherever the camera stops: $N(0) = -KC$ is
    singular), so the time-varying observer carries the common Lyapunov matrix `P` of its
    design instead: `checks` requires `P` symmetric positive definite, and `valid` checks
    the design's certificate $N(u)^T P + P N(u) \\preceq 0$ at the held sample (the camera's
    velocity inside the range the gains were designed for; outside it the run stops with
    `RESULTS.diverged`). The depth then converges when the camera's velocity is
    persistently exciting (`visjax.design.design_uio` with `u_range`).

    Checks (`checks`, under `jit` and `vmap`): for a fixed $A$, $N$ Hurwitz (chapter 3); for
    a time-varying one, `P` positive definite; $x_{3,\\mathrm{guess}} > 0$, the rank
    condition (3.20) (of the constant $A$, or for a time-varying one of $A$ plus one of its
    slopes at unit velocity), every matrix and gain finite,
    `bound` > 0. Valid state: the depth estimate is positive, $\\hat x_3 > 0$ (the point is
    in front of the camera, Assumption 2.1), $\\|\\hat x\\|_\\infty$ below `bound`, and with
    a time-varying $A$ the certificate above. Euler stability: the error dynamics are
    $\\dot e = N e$ plus the Lipschitz term, so the step must satisfy $h < \\min_\\lambda
    -2\\,\\mathrm{Re}\\lambda/|\\lambda|^2$ over the eigenvalues of $N$ (`max_stable_dt`;
    of $N(u_0)$ at the first sample for a time-varying $A$, eigenvalues at 0 ignored).

    **Fields:** `A`, `C`, `D`, `K`, `Y` as in chapter 3 (`K`, `Y` are the gains; gradients
    flow through them; `D` (3, 1) or (3,)); `x3_guess`: the initial guess of $1/Z$ (the
    observer starts at $\\hat x(0) = [y(0), x_{3,\\mathrm{guess}}]$); `bound` (default
    1e6); `D2` (3, 1) or (3,), default 0; `A_u` (6, 3, 3) and `K_u` (6, 3, 2), default 0
    (a fixed $A$ and $K$); `P` (3, 3), the design's Lyapunov matrix (needed only with a
    time-varying $A$ or $K$).
    """

    A: Float[Array, "3 3"] = eqx.field(converter=as_float)
    D: Float[Array, "3 1"] = eqx.field(converter=_column)
    K: Float[Array, "3 2"] = eqx.field(converter=as_float)
    Y: Float[Array, "3 2"] = eqx.field(converter=as_float)
    x3_guess: Float[Array, ""] = eqx.field(converter=as_float)
    C: Float[Array, "2 3"] = eqx.field(converter=as_float, default=C_OUTPUT)
    bound: Float[Array, ""] = eqx.field(converter=as_float, default=1e6)
    D2: Float[Array, "3 1"] = eqx.field(converter=_column, default=(0.0, 0.0, 0.0))
    A_u: Float[Array, "6 3 3"] = eqx.field(converter=as_float, default=_ZEROS_633)
    K_u: Float[Array, "6 3 2"] = eqx.field(converter=as_float, default=_ZEROS_632)
    P: Float[Array, "3 3"] = eqx.field(converter=as_float, default=_ZEROS_33)

    def __check_init__(self):
        for name, shape in (
            ("A", (3, 3)),
            ("D", (3, 1)),
            ("K", (3, 2)),
            ("Y", (3, 2)),
            ("C", (2, 3)),
            ("x3_guess", ()),
            ("bound", ()),
            ("D2", (3, 1)),
            ("A_u", (6, 3, 3)),
            ("K_u", (6, 3, 2)),
            ("P", (3, 3)),
        ):
            if jnp.shape(getattr(self, name)) != shape:
                raise ValueError(
                    f"`{name}` must have shape {shape}; got {jnp.shape(getattr(self, name))}."
                )

    def _matrices(self):
        return uio_matrices(self.A, self.C, self.D, self.K, self.Y)

    @property
    def time_varying(self):
        """Whether $A$ or $K$ follow the camera velocity (a traced bool)."""
        return jnp.any(self.A_u != 0.0) | jnp.any(self.K_u != 0.0)

    def A_of(self, u):
        """$A(u) = A + \\sum_j u_j A_{u,j}$ (the thesis' $A$ of the camera velocities with
        `A_u = MOVING_POINT_A_U`)."""
        return self.A + jnp.einsum("j,jab->ab", u, self.A_u)

    def K_of(self, u):
        """$K(u) = K + \\sum_j u_j K_{u,j}$, the gain scheduled on the camera velocity."""
        return self.K + jnp.einsum("j,jab->ab", u, self.K_u)

    def matrices_at(self, u):
        """$(E, M, N(u), L(u))$ of eq. (3.5) at the camera velocity `u` (6,)."""
        E, M, _, _ = self._matrices()
        A, K = self.A_of(u), self.K_of(u)
        I2 = jnp.eye(2, dtype=A.dtype)
        return E, M, M @ A - K @ self.C, K @ (I2 + self.C @ E) - M @ A @ E

    def disturbance_input(self):
        """$M D_2$ (3, 1): how the second unknown input $d_2$ of the UUB split enters the
        estimation error, $\\dot e = N e + M\\Delta\\bar f - M D_2 d_2$ (eq. (3.5))."""
        _, M, _, _ = self._matrices()
        return M @ self.D2

    def _N_eigenvalues(self, u=None):
        if u is None:
            _, _, N, _ = self._matrices()
        else:
            N = self.matrices_at(u)[2]
        return jnp.linalg.eigvals(jax.lax.stop_gradient(N))

    def _rank_condition(self):
        """(3.20) in JAX, for the checks under `jit` and `vmap`: with rank(CD) = 1 it holds
        exactly when $(M_0 A, C)$ is observable, $M_0 = I_3 - D(CD)^+C$ (`rank_condition`).
        With $D = 0$ (no unknown input: the ordinary observer) $(A, C)$ must be observable.
        With a time-varying $A$ it is checked on the constant part $A$ together with the
        slopes $A_{u,j}$: $(M_0 [A, A_{u,1}, \\ldots], C)$ must be observable for some
        velocity, a necessary condition for the persistent-excitation argument."""
        A, C, D = (jax.lax.stop_gradient(m) for m in (self.A, self.C, self.D))
        A_u = jax.lax.stop_gradient(self.A_u)
        CD = C @ D
        M0 = jnp.eye(3, dtype=A.dtype) - D @ _pinv_col(CD) @ C

        def observable(A):
            MA = M0 @ A
            obs = jnp.concatenate([C, C @ MA, C @ MA @ MA])
            sv = jnp.linalg.svd(obs, compute_uv=False)
            return sv[-1] > 6.0 * jnp.finfo(A.dtype).eps * sv[0]

        fixed = observable(A)
        # a time-varying A: observable at the constant part plus one slope at unit velocity
        varying = jnp.any(jax.vmap(lambda Aj: observable(A + Aj) & jnp.any(Aj != 0.0))(A_u))
        obs = jnp.where(jnp.any(A_u != 0.0), fixed | varying, fixed)
        no_input = jnp.all(D == 0.0)
        return obs & (no_input | (jnp.sum(CD**2) > 0.0))

    def _lyapunov_ok(self, u):
        """The design's certificate at `u`: $\\lambda_{\\max}(N(u)^T P + P N(u)) \\le 0$, to a
        relative tolerance of 1e-7."""
        N = jax.lax.stop_gradient(self.matrices_at(u)[2])
        P = jax.lax.stop_gradient(self.P)
        S = N.T @ P + P @ N
        tol = 1e-7 * (jnp.linalg.norm(P) * jnp.linalg.norm(N) + 1e-300)
        return jnp.max(jnp.linalg.eigvalsh(0.5 * (S + S.T))) <= tol

    def checks(self):
        lam = self._N_eigenvalues()
        P = jax.lax.stop_gradient(self.P)
        P_ok = jnp.all(P == P.T) & (jnp.min(jnp.linalg.eigvalsh(P)) > 0)
        stable = jnp.where(self.time_varying, P_ok, jnp.max(jnp.real(lam)) < 0)
        return (
            (
                stable,
                "`N` = M A - K C must be Hurwitz (chapter 3); with a time-varying A(u) or "
                "K(u), `P` (the design's common Lyapunov matrix) must be symmetric positive "
                "definite.",
            ),
            (
                positive_finite(self.x3_guess),
                "`x3_guess` (the initial 1/Z) must be positive and finite.",
            ),
            (
                all_finite((self.A, self.C, self.D, self.K, self.Y, self.D2))
                & all_finite((self.A_u, self.K_u, self.P)),
                "`A`, `C`, `D`, `D2`, `A_u`, `K_u`, `P` and the gains `K`, `Y` must be finite.",
            ),
            (self.bound > 0, "`bound` must be positive."),
            (
                self._rank_condition(),
                "(A, C, D) must satisfy the rank condition (3.20) and rank(CD) = rank(D).",
            ),
        )

    def max_stable_dt(self, y=None):
        lam = self._N_eigenvalues(None if y is None else y.u)
        a2 = jnp.abs(lam) ** 2
        per = jnp.where(a2 > 0, -2.0 * jnp.real(lam) / jnp.where(a2 > 0, a2, 1.0), jnp.inf)
        return jnp.min(per)

    def init(self, y0: MovingPointMeasurement) -> MovingPointState:
        E, _, _, _ = self._matrices()
        x3 = jnp.reshape(self.x3_guess, (1,)).astype(y0.y.dtype)
        x_hat = jnp.concatenate([y0.y, x3])
        return MovingPointState(z=x_hat + E @ y0.y)  # z = x_hat + E y

    def _x_hat(self, state: MovingPointState, y):
        E, _, _, _ = self._matrices()
        return state.z - E @ y

    def vector_field(
        self, t, state: MovingPointState, meas: MovingPointMeasurement
    ) -> MovingPointState:
        y, u = meas.y, meas.u
        E, M, N, L = self.matrices_at(u)  # N(u), L(u): the constant ones when A_u = K_u = 0
        x_hat = state.z - E @ y
        f_bar = camera_term(x_hat, u) - self.A_of(u) @ x_hat  # eq. (3.2)
        return MovingPointState(
            z=N @ state.z + L @ y + M @ f_bar + M @ known_input_term(y, u)
        )  # (3.5)

    def output(self, t, state: MovingPointState, meas: MovingPointMeasurement) -> MovingPointOutput:
        x_hat = self._x_hat(state, meas.y)
        position = jnp.stack([x_hat[0], x_hat[1], jnp.ones_like(x_hat[2])]) / x_hat[2]
        return MovingPointOutput(x_hat=x_hat, position=position)

    def valid(self, state: MovingPointState, meas: MovingPointMeasurement):
        x_hat = self._x_hat(state, meas.y)
        ok = (x_hat[2] > 0) & (jnp.max(jnp.abs(x_hat)) < self.bound)
        return ok & (~self.time_varying | self._lyapunov_ok(meas.u))


def moving_point_stream(
    ts: Float[ArrayLike, " N"],
    pixels: Float[ArrayLike, "N 2"],
    velocities: Float[ArrayLike, "N 6"],
    K_c: Float[ArrayLike, "3 3"],
    *,
    truth=None,
    dropped: str = "stop",
    reject: Bool[ArrayLike, " N"] | None = None,
    throw: bool = True,
) -> Stream:
    """The measurement `Stream` of the UIO from raw measurements.

    **Arguments:**

    - `ts` (N,): the camera's sample times (any rate; `run(..., dt=...)` holds them).
    - `pixels` (N, 2): the tracked point's pixel coordinates.
    - `velocities` (N, 6): the camera's measured $[v_c, \\omega]$ in the camera basis
        (from the robot's joint rates, or any odometry), at the same times.
    - `K_c` (3, 3): the camera matrix used to normalise pixels ($y = K_c^{-1} p$).
    - `truth`: optional ground truth for a reducer.
    - `dropped`: what a dropped frame is replaced by. A dropped frame is a pixel row with a
        non-finite coordinate (NaN: the tracker lost the point, or it left the image).
        `"stop"` (default): it stops the run (`RESULTS.nonfinite_measurement`, naming the
        frame). `"hold"`: the last seen pixels are held over the dropped frames (the
        observer keeps the output injection $L y$, $E y$ of eq. (3.5) of the last frame it
        saw). `"extrapolate"`: the pixels are extrapolated causally from the last two seen
        frames at constant image velocity, $p_k = p_a + (t_k - t_a)(p_a - p_b)/(t_a - t_b)$
        ($a$ the last seen frame, $b$ the one seen before it; held if there is none). In
        both the camera velocities keep their own samples, and a dropped first frame has
        nothing to hold and still stops the run at sample 0. A held pixel is stale: with a
        fast camera and a large scheduled depth gain this costs accuracy
        (`benchmarks/scenes_uio.py`: with 5% of the 50 Hz frames dropped, the sideways
        scene's depth RMS goes from 2.3 mm to 12.8 mm held, 2.2 mm extrapolated).
    - `reject` (N,) bool: the frames an outlier test rejected; their pixels are replaced as
        a dropped frame's (held, or extrapolated with `dropped="extrapolate"`; held with
        `"stop"`: a rejected frame never stops the run), the camera velocities keep their
        own samples. A rejected first frame has nothing to hold: it stops the run.
    - `throw`: a sample that is still not finite (a dropped frame with `dropped="stop"`, a
        dropped first frame, a non-finite camera velocity) raises here, naming the sample;
        with `throw=False` `run` stops there with `RESULTS.nonfinite_measurement`.
    """
    ts, pixels, velocities, K_c = (as_float(x) for x in (ts, pixels, velocities, K_c))
    check_shape(ts, (None,), "ts")
    n = ts.shape[0]
    check_shape(pixels, (n, 2), "pixels")
    check_shape(velocities, (n, 6), "velocities")
    check_shape(K_c, (3, 3), "K_c")
    if dropped not in ("stop", "hold", "extrapolate"):
        raise ValueError(f'`dropped` must be "stop", "hold" or "extrapolate"; got {dropped!r}.')
    reject = reject_mask(reject, n)
    if reject is None:
        y = _normalized_held(ts, pixels, K_c, dropped)
    else:
        marked = jnp.where(reject[:, None], jnp.nan, pixels)
        y = _normalized_held(ts, marked, K_c, "hold" if dropped == "stop" else dropped)
        if dropped == "stop":  # a frame that is NaN without being rejected still stops
            y = jnp.where(reject[:, None], y, pixel_to_normalized(pixels, K_c))
    stream = Stream(ts=ts, ys=MovingPointMeasurement(y=y, u=velocities), truth=truth)
    return checked_samples(stream, "moving_point_stream", throw)


@functools.partial(jax.jit, static_argnums=3)  # one program per length outside `jit`
def _normalized_held(ts, pixels, K_c, dropped):
    n = ts.shape[0]
    if dropped != "stop":
        seen = jnp.all(jnp.isfinite(pixels), axis=1)
        index = jnp.where(seen, jnp.arange(n), -1)
        last = jnp.maximum(jax.lax.cummax(index, axis=0), 0)  # a: the last seen frame
        held = pixels[last]
        if dropped == "hold":
            pixels = held
        else:
            before = jnp.concatenate([jnp.zeros(1, last.dtype), last[:-1]])
            prev = before[last]  # b: the frame seen before a (a itself if none)
            has_prev = seen[prev] & (prev < last)
            span = jnp.where(has_prev, ts[last] - ts[prev], 1.0)
            slope = jnp.where(has_prev[:, None], (held - pixels[prev]) / span[:, None], 0.0)
            ahead = (ts - ts[last])[:, None]
            pixels = jnp.where(seen[:, None], pixels, held + ahead * slope)
    return pixel_to_normalized(pixels, K_c)


def moving_point_innovation(
    frame_ts: Float[ArrayLike, " N"],
    pixels: Float[ArrayLike, "N 2"],
    K_c: Float[ArrayLike, "3 3"],
    ts: Float[ArrayLike, " M"],
    x_hat: Float[ArrayLike, "M 3"],
    *,
    t_start: float = -jnp.inf,
    t_end: float = jnp.inf,
) -> Innovation:
    """The output error of the unknown input observer (Jang's thesis, eq. (3.5)), $y -
    \\hat y$ with $y = [x_1, x_2]$ a frame's normalized image coordinates and $\\hat y = [\\hat
    x_1, \\hat x_2]$ the observer's prediction of them when the frame arrives (its estimate
    saved at or before the frame's time, `ts`, `x_hat`), against the noise level the frames
    imply (`Innovation`): a check of a run without the truth. Frames with a NaN pixel (not
    seen) and outside `[t_start, t_end)` do not count. Pure JAX (`jit`, `vmap`, `grad`)."""
    frame_ts = as_float(frame_ts)
    ts = as_float(ts)
    x_hat = jnp.asarray(x_hat)
    if x_hat.shape != (ts.shape[0], 3):
        raise ValueError(f"`x_hat` must be (M, 3) for `ts` (M,); got {tuple(x_hat.shape)}.")
    y = pixel_to_normalized(jnp.asarray(pixels), K_c)
    k = jnp.searchsorted(ts, frame_ts + 1e-9, side="right") - 1
    predicted = x_hat[jnp.clip(k, 0, ts.shape[0] - 1), :2]
    used = (k >= 0) & (frame_ts >= t_start) & (frame_ts < t_end)
    return innovation(y, y - predicted, used)
