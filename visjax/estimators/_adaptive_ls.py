"""The adaptive least-squares Euclidean structure estimator of seed 004, section IV.

Source: Nath, Dawson, Tatlicioglu, *Euclidean position estimation of static features using a
moving uncalibrated camera*. Two laws run together: the camera-parameter law (37)-(39) on
the known features, and the structure law (41)-(45) on the unknown ones, which uses the
current camera estimate; the output is the scale-recovered position of every unknown
feature (eqs. (50)-(51)).

Numerics (see the issue note):

- Eqs. (39) and (45) are integrated for the information matrices $\\Gamma_c^{-1}$, $\\Gamma^{-1}$
  (they grow linearly and stay positive definite under Euler steps), and $\\Gamma$ is solved
  for at each step; an Euler step on $\\Gamma$ itself (eq. (46)) turns it indefinite.
- The camera parameters are hundreds of pixels while the regressors hold metres. The law is
  run in normalised coordinates $\\theta_c = D\\varphi$ with a fixed diagonal $D$ (the scale
  of each parameter): eq. (39) and the resetting to $\\eta_0 I_{16}$ apply to $\\varphi$. In
  $\\theta_c$ this is $\\Gamma_c = D\\Gamma_\\varphi D$, the paper's law with a diagonal
  preconditioner.
- `Proj` is the standard continuous projection for the linear constraints
  $\\Pi_{xj}\\hat\\theta_{c2} > \\varepsilon_c$ and $\\hat\\Pi\\hat\\theta_{si} > \\varepsilon_s$:
  when an estimate sits on the boundary and the update points outwards, the update's component
  along the constraint's normal (in the $\\Gamma$ metric) is removed.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..geometry import known_feature_regressors, unknown_feature_regressors
from ._base import AbstractEstimator


class PlatformMeasurement(eqx.Module):
    """One sample for the seed-004 estimator: the measured platform pose `R_b`, `x_b`,
    homogeneous pixels of the unknown (`p_s`, (n, 3)) and known (`p_c`, (m, 3)) features,
    and the known features' regressors `W_x` (m, 3, 12), `Pi_x` (m, 4) of eq. (12)."""

    R_b: Float[Array, "3 3"]
    x_b: Float[Array, "3"]
    p_s: Float[Array, "n 3"]
    p_c: Float[Array, "m 3"]
    W_x: Float[Array, "m 3 12"]
    Pi_x: Float[Array, "m 4"]


def platform_measurements(R_b, x_b, p_s, p_c, omega_c) -> PlatformMeasurement:
    """Build the measurements of all samples at once (vmapped before the time loop).

    `R_b` (N, 3, 3), `x_b` (N, 3), pixels `p_s` (N, n, 2) and `p_c` (N, m, 2), known
    feature positions `omega_c` (m, 3).
    """
    R_b, x_b, p_s, p_c, omega_c = (jnp.asarray(x) for x in (R_b, x_b, p_s, p_c, omega_c))
    if p_s.ndim != 3 or p_c.ndim != 3 or p_s.shape[-1] != 2 or p_c.shape[-1] != 2:
        raise ValueError(
            f"`p_s` and `p_c` must be (N, n, 2) and (N, m, 2); got {p_s.shape}, {p_c.shape}."
        )
    if p_c.shape[1] != omega_c.shape[0]:
        raise ValueError(
            f"`p_c` has {p_c.shape[1]} known features but `omega_c` has {omega_c.shape[0]}."
        )

    def one(R, x):
        W, Pi = jax.vmap(lambda w: known_feature_regressors(R, x, w))(omega_c)
        return W, Pi[:, 0, :]

    W_x, Pi_x = jax.vmap(one)(R_b, x_b)
    hom = lambda p: jnp.concatenate([p, jnp.ones(p.shape[:-1] + (1,), p.dtype)], -1)  # noqa: E731
    return PlatformMeasurement(R_b=R_b, x_b=x_b, p_s=hom(p_s), p_c=hom(p_c), W_x=W_x, Pi_x=Pi_x)


def _project(tau, theta, normals, margin, Gamma):
    """Continuous projection of the update `tau` for the constraints `normals @ theta > margin`."""
    for k in range(normals.shape[0]):
        a = normals[k]
        active = (a @ theta <= margin) & (a @ tau < 0.0)
        Ga = Gamma @ a
        tau = jnp.where(active, tau - Ga * (a @ tau) / (a @ Ga), tau)
    return tau


class AdaptiveStructureEstimator(AbstractEstimator):
    """Seed 004: camera-parameter law (37)-(39) and structure law (41)-(45), output (50)-(51).

    **State:** `(theta_c (16,), info_c (16, 16), theta_s (n, 4), info_s (n, 4, 4), resets)`,
    with `info_c` $= \\Gamma_\\varphi^{-1}$ (normalised, see the module docstring), `info_s`
    the diagonal blocks of $\\Gamma^{-1}$ (eq. (45): $\\bar W_s$ is block diagonal, eq. (22)),
    and `resets` the number of covariance resets so far.

    **Fields:** `alpha_c`, `alpha`: the gains of eqs. (38) and (42) (positive constants
    here: $1 + \\bar\\rho/\\bar\\varepsilon$ with constant bounds); `eta0 > eta1 > 0` of eq. (39);
    `gamma_s0`: the initial structure covariance $\\Gamma(t_0) = \\gamma_{s0} I$; `D` (16,) the
    scale of each camera parameter; `eps_c`, `eps_s`: the projection margins on the
    predicted depths (metres); `theta_c0` (16,), `theta_s0` (n, 4): initial estimates.
    """

    alpha_c: Float[Array, ""]
    alpha: Float[Array, ""]
    eta0: Float[Array, ""]
    eta1: Float[Array, ""]
    gamma_s0: Float[Array, ""]
    D: Float[Array, "16"]
    eps_c: Float[Array, ""]
    eps_s: Float[Array, ""]
    theta_c0: Float[Array, "16"]
    theta_s0: Float[Array, "n 4"]

    def __check_init__(self):
        if jnp.shape(self.theta_c0) != (16,) or jnp.shape(self.D) != (16,):
            raise ValueError(
                f"`theta_c0` and `D` must have shape (16,); got {jnp.shape(self.theta_c0)} "
                f"and {jnp.shape(self.D)}."
            )
        if jnp.ndim(self.theta_s0) != 2 or jnp.shape(self.theta_s0)[1] != 4:
            raise ValueError(f"`theta_s0` must have shape (n, 4); got {jnp.shape(self.theta_s0)}.")
        if not isinstance(self.eta0, jax.core.Tracer) and not isinstance(
            self.eta1, jax.core.Tracer
        ):
            if not float(self.eta0) > float(self.eta1) > 0:
                raise ValueError(f"need eta0 > eta1 > 0 (eq. (39)); got {self.eta0}, {self.eta1}.")

    def init(self, y0: PlatformMeasurement):
        dtype = y0.p_s.dtype
        n = self.theta_s0.shape[0]
        info_c = jnp.eye(16, dtype=dtype) / self.eta0  # Gamma_phi(t0) = eta0 I
        info_s = jnp.broadcast_to(jnp.eye(4, dtype=dtype) / self.gamma_s0, (n, 4, 4))
        return (self.theta_c0, info_c, self.theta_s0, info_s, jnp.zeros((), dtype))

    def _signals(self, state, y: PlatformMeasurement):
        theta_c, info_c, theta_s, info_s, _ = state
        t1, t2 = theta_c[:12], theta_c[12:]
        # known features: eqs. (30)-(36)
        p_hat_c = (y.W_x @ t1) / (y.Pi_x @ t2)[:, None]
        p_tilde_c = y.p_c - p_hat_c
        Pi_x = -(p_hat_c[:, :, None] * y.Pi_x[:, None, :])  # eq. (33)
        W_c = jnp.concatenate([y.W_x, Pi_x], axis=-1).reshape(-1, 16)  # eq. (36)
        # unknown features: eqs. (15), (20), (22) with the current camera estimate
        W, Pi = unknown_feature_regressors(y.R_b, y.x_b, t1, t2)
        depth_s = theta_s @ Pi[0]
        p_hat_s = (theta_s @ W.T) / depth_s[:, None]
        p_tilde_s = y.p_s - p_hat_s
        W_bar = W[None, :, :] - p_hat_s[:, :, None] * Pi[None, :, :]  # blocks of eq. (22)
        return p_tilde_c, W_c, p_tilde_s, W_bar, Pi[0]

    def vector_field(self, t, state, y: PlatformMeasurement):
        theta_c, info_c, theta_s, info_s, _ = state
        p_tilde_c, W_c, p_tilde_s, W_bar, Pi_hat = self._signals(state, y)
        WD = W_c * self.D
        Gamma_phi = jnp.linalg.inv(info_c)
        Gamma_c = self.D[:, None] * Gamma_phi * self.D[None, :]
        tau_c = self.alpha_c * Gamma_c @ (W_c.T @ p_tilde_c.reshape(-1))  # eq. (37)
        normals_c = jnp.concatenate([jnp.zeros((y.Pi_x.shape[0], 12), y.Pi_x.dtype), y.Pi_x], 1)
        tau_c = _project(tau_c, theta_c, normals_c, self.eps_c, Gamma_c)
        d_info_c = 2.0 * WD.T @ WD  # eq. (39)
        Gamma_s = jnp.linalg.inv(info_s)
        tau_s = self.alpha * jnp.einsum(
            "nij,nkj,nk->ni", Gamma_s, W_bar, p_tilde_s
        )  # eq. (41), per feature
        tau_s = jax.vmap(lambda tau, th, G: _project(tau, th, Pi_hat[None, :], self.eps_s, G))(
            tau_s, theta_s, Gamma_s
        )
        d_info_s = 2.0 * jnp.einsum("nki,nkj->nij", W_bar, W_bar)  # eq. (45)
        return (tau_c, d_info_c, tau_s, d_info_s, jnp.zeros_like(state[4]))

    def jump(self, state, y):
        """Covariance resetting of eq. (39): $\\Gamma_\\varphi \\to \\eta_0 I$ when its minimum
        eigenvalue reaches $\\eta_1$ (the largest eigenvalue of `info_c` reaches $1/\\eta_1$)."""
        theta_c, info_c, theta_s, info_s, resets = state
        lam_max = jnp.linalg.eigvalsh(jax.lax.stop_gradient(info_c))[-1]
        reset = lam_max >= 1.0 / self.eta1
        info_c = jnp.where(reset, jnp.eye(16, dtype=info_c.dtype) / self.eta0, info_c)
        return (theta_c, info_c, theta_s, info_s, resets + reset.astype(resets.dtype))

    def output(self, t, state, y):
        theta_c, info_c, theta_s, info_s, resets = state
        p_tilde_c, _, p_tilde_s, W_bar, Pi_hat = self._signals(state, y)
        lam = theta_s[:, 3]  # eq. (50)
        return {
            "omega_s": theta_s[:, :3] / lam[:, None],  # eq. (51)
            "p_tilde_c": jnp.linalg.norm(p_tilde_c[:, :2], axis=-1),
            "p_tilde_s": jnp.linalg.norm(p_tilde_s[:, :2], axis=-1),
            "depth_s": theta_s @ Pi_hat,
            "depth_c": y.Pi_x @ theta_c[12:],
            "lambda_min_gamma_c": 1.0 / jnp.linalg.eigvalsh(jax.lax.stop_gradient(info_c))[-1],
            "resets": resets,
            "theta_c": theta_c,
            "info_rate_s": jnp.einsum("nki,nkj->nij", W_bar, W_bar),  # integrand of (49)
        }


def pe_measure(info_rate_s, ts, window: float):
    """The persistency of excitation of eq. (49) over a sliding window, per unknown feature.

    $\\int_{t-T}^{t}\\bar W_{si}^T\\bar W_{si}\\,d\\tau$ by the rectangle rule on the saved
    samples (`info_rate_s` (N, n, 4, 4) from the estimator's output, at times `ts`). Since
    $\\bar W_{si}\\hat\\theta_{si} = 0$ by construction (eq. (22): the scale direction of eq.
    (50)), its smallest eigenvalue is always 0; the measure is its second smallest
    eigenvalue divided by its largest (0: not exciting, up to 1). NaN until a full window.

    **Returns:** (N, n).
    """
    info_rate_s = jnp.asarray(info_rate_s)
    ts = jnp.asarray(ts)
    dt = ts[1] - ts[0]
    k = max(1, int(round(float(window) / float(dt))))
    csum = jnp.cumsum(info_rate_s, axis=0) * dt
    shifted = jnp.concatenate([jnp.zeros_like(csum[:k]), csum[:-k]], axis=0)
    integral = csum - shifted
    lam = jnp.linalg.eigvalsh(integral)
    measure = lam[..., 1] / jnp.maximum(lam[..., -1], jnp.finfo(lam.dtype).tiny)
    full = (jnp.arange(ts.shape[0]) >= k)[:, None]
    return jnp.where(full, measure, jnp.nan)
