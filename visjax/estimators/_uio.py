"""The unknown input observer (UIO) of seed 003 (Jang's thesis, chapters 2-3).

Perspective dynamics of a point seen by a moving camera, in the state
$x = [X/Z, Y/Z, 1/Z]$ with output $y = [x_1, x_2]$, measured camera velocities
$u = [v_c, \\omega]$ and the point's own velocity as unknown input (eq. (2.11)); the observer
(3.5) $\\dot z = N z + L y + M \\bar f(\\hat x, u) + M g(y, u)$, $\\hat x = z - E y$; and the
checks of chapter 3. Equation numbers are the thesis'; `THESIS_NOTES.md` restates them.
"""

from typing import final

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._results import all_finite
from .._util import as_float, check_shape, positive_finite
from ..geometry import pixel_to_normalized
from ..kinematics import camera_term, known_input_term
from ._base import AbstractEstimator, Stream

C_OUTPUT = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0))  # y = C x, eq. (3.1)


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

    **Arguments:** `A` (3, 3), `C` (2, 3), `D` (3, 1), `K` (3, 2), `Y` (3, 2).

    **Returns:** `(E, M, N, L)`, shapes (3, 2), (3, 3), (3, 3), (3, 2).
    """
    A, C, D, K, Y = (as_float(m) for m in (A, C, D, K, Y))
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
    D = as_float(D)
    return {
        "MD": jnp.linalg.norm(M @ D),
        "NM_LC_MA": jnp.linalg.norm(N @ M + L @ as_float(C) - M @ as_float(A)),
        "max_real_eig_N": jnp.max(jnp.real(jnp.linalg.eigvals(jax.lax.stop_gradient(N)))),
    }


def rank_condition(A, C, D, *, tol: float = 1e-9) -> bool:
    """The rank condition (3.20) and $\\mathrm{rank}(CD) = \\mathrm{rank}(D) = 1$.

    (3.20): $\\mathrm{rank}\\begin{bmatrix} sI_3 - A & D \\\\ C & 0 \\end{bmatrix} = 4$ for
    every complex $s$. Given $\\mathrm{rank}(CD) = \\mathrm{rank}(D)$, it holds exactly when
    $(M_0 A, C)$ is observable, $M_0 = I_3 - D(CD)^+C$ (THESIS_NOTES, ch. 3.4): the pencil can
    lose rank only at an unobservable eigenvalue of $M_0 A$. Both are evaluated here: the
    observability matrix, and the pencil's rank at every eigenvalue of $M_0 A$. NumPy, a
    design-time check (not jit).
    """
    A, C, D = (np.asarray(m, dtype=float) for m in (A, C, D))
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
class MovingCameraMeasurement(eqx.Module):
    """One sample (or, in a `Stream`, all samples: a leading axis) for the UIO: `y` (2,) the
    point's normalized image coordinates
    $[x_1, x_2]$ (eq. (3.1)); `u` (6,) the camera velocities $[v_c, \\omega]$ (camera basis)."""

    y: Float[Array, "*batch 2"]
    u: Float[Array, "*batch 6"]


@final
class UIOState(eqx.Module):
    """The observer state $z$ of eq. (3.5); $\\hat x = z - E y$."""

    z: Float[Array, "3"]


@final
class UIOOutput(eqx.Module):
    """$\\hat x = [\\hat x_1, \\hat x_2, \\hat x_3]$ ($[X/Z, Y/Z, 1/Z]$) and the point's
    position in the camera frame, $[\\hat x_1/\\hat x_3, \\hat x_2/\\hat x_3, 1/\\hat x_3]$ (in
    the units of the camera velocities)."""

    x_hat: Float[Array, "3"]
    position: Float[Array, "3"]


@final
class UnknownInputObserver(AbstractEstimator):
    """The nonlinear unknown input observer of eq. (3.5).

    $\\dot z = N z + L y + M \\bar f(\\hat x, u) + M g(y, u)$, $\\hat x = z - E y$, with
    $\\bar f(x, u) = f(x, u) - A x$ (eq. (3.2)) and $E, M, N, L$ from `uio_matrices`.
    Measurements are `MovingCameraMeasurement`s (`moving_camera_stream`).

    Checks (`checks`, under `jit` and `vmap`): $N$ Hurwitz (chapter 3),
    $x_{3,\\mathrm{guess}} > 0$, the rank condition (3.20), every matrix and gain finite,
    `bound` > 0. Valid state: the depth estimate is positive, $\\hat x_3 > 0$ (the point is
    in front of the camera, Assumption 2.1), and $\\|\\hat x\\|_\\infty$ below `bound`.
    Euler stability: the error dynamics are $\\dot e = N e$ plus the Lipschitz term, so the
    step must satisfy $h < \\min_\\lambda -2\\,\\mathrm{Re}\\lambda/|\\lambda|^2$ over the
    eigenvalues of $N$ (`max_stable_dt`).

    **Fields:** `A`, `C`, `D`, `K`, `Y` as in chapter 3 (`K`, `Y` are the gains; gradients
    flow through them); `x3_guess`: the initial guess of $1/Z$ (the observer starts at
    $\\hat x(0) = [y(0), x_{3,\\mathrm{guess}}]$); `bound` (default 1e6).
    """

    A: Float[Array, "3 3"] = eqx.field(converter=as_float)
    D: Float[Array, "3 1"] = eqx.field(converter=as_float)
    K: Float[Array, "3 2"] = eqx.field(converter=as_float)
    Y: Float[Array, "3 2"] = eqx.field(converter=as_float)
    x3_guess: Float[Array, ""] = eqx.field(converter=as_float)
    C: Float[Array, "2 3"] = eqx.field(converter=as_float, default=C_OUTPUT)
    bound: Float[Array, ""] = eqx.field(converter=as_float, default=1e6)

    def __check_init__(self):
        for name, shape in (
            ("A", (3, 3)),
            ("D", (3, 1)),
            ("K", (3, 2)),
            ("Y", (3, 2)),
            ("C", (2, 3)),
            ("x3_guess", ()),
            ("bound", ()),
        ):
            if jnp.shape(getattr(self, name)) != shape:
                raise ValueError(
                    f"`{name}` must have shape {shape}; got {jnp.shape(getattr(self, name))}."
                )

    def _matrices(self):
        return uio_matrices(self.A, self.C, self.D, self.K, self.Y)

    def _N_eigenvalues(self):
        _, _, N, _ = self._matrices()
        return jnp.linalg.eigvals(jax.lax.stop_gradient(N))

    def _rank_condition(self):
        """(3.20) in JAX, for the checks under `jit` and `vmap`: with rank(CD) = 1 it holds
        exactly when $(M_0 A, C)$ is observable, $M_0 = I_3 - D(CD)^+C$ (`rank_condition`).
        With $D = 0$ (no unknown input: the ordinary observer) $(A, C)$ must be observable."""
        A, C, D = (jax.lax.stop_gradient(m) for m in (self.A, self.C, self.D))
        CD = C @ D
        M0 = jnp.eye(3, dtype=A.dtype) - D @ _pinv_col(CD) @ C
        MA = M0 @ A
        obs = jnp.concatenate([C, C @ MA, C @ MA @ MA])
        sv = jnp.linalg.svd(obs, compute_uv=False)
        tol = 6.0 * jnp.finfo(A.dtype).eps * sv[0]
        no_input = jnp.all(D == 0.0)
        return (sv[-1] > tol) & (no_input | (jnp.sum(CD**2) > 0.0))

    def checks(self):
        lam = self._N_eigenvalues()
        return (
            (jnp.max(jnp.real(lam)) < 0, "`N` = M A - K C must be Hurwitz (chapter 3)."),
            (
                positive_finite(self.x3_guess),
                "`x3_guess` (the initial 1/Z) must be positive and finite.",
            ),
            (
                all_finite((self.A, self.C, self.D, self.K, self.Y)),
                "`A`, `C`, `D` and the gains `K`, `Y` must be finite.",
            ),
            (self.bound > 0, "`bound` must be positive."),
            (
                self._rank_condition(),
                "(A, C, D) must satisfy the rank condition (3.20) and rank(CD) = rank(D).",
            ),
        )

    def max_stable_dt(self, y=None):
        lam = self._N_eigenvalues()
        return jnp.min(-2.0 * jnp.real(lam) / jnp.abs(lam) ** 2)

    def init(self, y0: MovingCameraMeasurement) -> UIOState:
        E, _, _, _ = self._matrices()
        x3 = jnp.reshape(self.x3_guess, (1,)).astype(y0.y.dtype)
        x_hat = jnp.concatenate([y0.y, x3])
        return UIOState(z=x_hat + E @ y0.y)  # z = x_hat + E y

    def _x_hat(self, state: UIOState, y):
        E, _, _, _ = self._matrices()
        return state.z - E @ y

    def vector_field(self, t, state: UIOState, meas: MovingCameraMeasurement) -> UIOState:
        y, u = meas.y, meas.u
        E, M, N, L = self._matrices()
        x_hat = state.z - E @ y
        f_bar = camera_term(x_hat, u) - self.A @ x_hat  # eq. (3.2)
        return UIOState(z=N @ state.z + L @ y + M @ f_bar + M @ known_input_term(y, u))  # (3.5)

    def output(self, t, state: UIOState, meas: MovingCameraMeasurement) -> UIOOutput:
        x_hat = self._x_hat(state, meas.y)
        position = jnp.stack([x_hat[0], x_hat[1], jnp.ones_like(x_hat[2])]) / x_hat[2]
        return UIOOutput(x_hat=x_hat, position=position)

    def valid(self, state: UIOState, meas: MovingCameraMeasurement):
        x_hat = self._x_hat(state, meas.y)
        return (x_hat[2] > 0) & (jnp.max(jnp.abs(x_hat)) < self.bound)


def moving_camera_stream(
    ts: Float[ArrayLike, " N"],
    pixels: Float[ArrayLike, "N 2"],
    velocities: Float[ArrayLike, "N 6"],
    K_c: Float[ArrayLike, "3 3"],
    *,
    truth=None,
) -> Stream:
    """The measurement `Stream` of the UIO from raw measurements.

    **Arguments:**

    - `ts` (N,): the camera's sample times (any rate; `run(..., dt=...)` holds them).
    - `pixels` (N, 2): the tracked point's pixel coordinates.
    - `velocities` (N, 6): the camera's measured $[v_c, \\omega]$ in the camera basis
        (from the robot's joint rates, or any odometry), at the same times.
    - `K_c` (3, 3): the camera matrix used to normalise pixels ($y = K_c^{-1} p$).
    - `truth`: optional ground truth for a reducer.
    """
    ts, pixels, velocities, K_c = (as_float(x) for x in (ts, pixels, velocities, K_c))
    check_shape(ts, (None,), "ts")
    n = ts.shape[0]
    check_shape(pixels, (n, 2), "pixels")
    check_shape(velocities, (n, 6), "velocities")
    check_shape(K_c, (3, 3), "K_c")
    y = pixel_to_normalized(pixels, K_c)
    return Stream(ts=ts, ys=MovingCameraMeasurement(y=y, u=velocities), truth=truth)
