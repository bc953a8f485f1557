"""The SL(3) homography observer of Hamel, Mahony, Trumpf, Morin and Hua (*Homography
estimation on the Special Linear group based on direct point correspondence*, IEEE
CDC-ECC 2011), `HomographyEstimator`, and its stream builder `homography_stream`. Its
problem and reproduction are `visjax.papers.hamel`'s.

**The model.** The homography $H \\in SL(3)$ maps the current image to the reference one,
$\\mathring p_i \\propto H p_i$ for the bearing directions $p_i$ (current) and
$\\mathring p_i$ (reference, unit vectors) of points of a plane, and evolves as
$\\dot H = H A$ with the group velocity $A \\in \\mathfrak{sl}(3)$, here known.

**The observer** (the case of a known group velocity), with gain $k_P > 0$:
$e_i = \\hat H p_i / |\\hat H p_i|$,
$\\Delta = \\sum_i (I - e_i e_i^T)\\, \\mathring p_i\\, e_i^T$,
$\\dot{\\hat H} = \\hat H A + k_P \\Delta \\hat H$. No homography is computed per frame: the
innovation $\\Delta$ is built from the correspondences directly.

Why it converges (derived here, and what the tests check): the error $E = \\hat H H^{-1}$
obeys $\\dot E = k_P \\Delta E$ whatever $A$, $e_i = E\\mathring p_i / |E \\mathring p_i|$,
and $f = \\sum_i (1 - e_i^T \\mathring p_i)$ decreases as $\\dot f = -k_P \\|\\Delta\\|^2$;
$\\mathrm{tr}\\,\\Delta = 0$, so $\\hat H$ stays in SL(3). At $\\hat H = H$, $e_i =
\\mathring p_i$ and $\\Delta = 0$: the truth is kept. With four or more points, no three
collinear, $\\Delta = 0$ only at $E = I$ near the identity.

**A partly known group velocity** (the paper's observer with the camera's angular velocity
measured, and the rest of the group velocity estimated): with $A = A_m + \\Gamma$, $A_m$
measured (e.g. $[\\Omega]_\\times$, or zero) and $\\Gamma$ unknown and constant,
$\\dot{\\hat H} = \\hat H (A_m + \\hat\\Gamma) + k_P \\Delta \\hat H$,
$\\dot{\\hat\\Gamma} = k_I\\, \\mathrm{Ad}_{\\hat H^T} \\Delta = k_I \\hat H^T \\Delta
\\hat H^{-T}$. Derived here: now $\\dot E = (k_P \\Delta - \\hat H \\tilde\\Gamma \\hat H^{-1}) E$
with $\\tilde\\Gamma = \\Gamma - \\hat\\Gamma$, so with
$\\mathcal{L} = f + \\|\\tilde\\Gamma\\|^2 / (2 k_I)$,
$\\dot{\\mathcal{L}} = -k_P\\|\\Delta\\|^2$
$+ \\langle \\hat H^T \\Delta \\hat H^{-T} - \\dot{\\hat\\Gamma} / k_I,
\\tilde\\Gamma\\rangle = -k_P \\|\\Delta\\|^2$; $\\mathrm{Ad}_{\\hat H^T}\\Delta$ is trace-free, so
$\\hat\\Gamma$ stays in $\\mathfrak{sl}(3)$. For a camera with angular velocity $\\Omega$
and linear velocity $V$ (its own frame) before a plane of normal $n$ at distance $d$,
$A = [\\Omega]_\\times + V n^T / d - (n^T V / (3d)) I$: the unknown part is
$\\Gamma = V n^T/d - (n^T V/(3d)) I$, constant when $V / d$ and $n$ are.

The runner integrates $\\hat H$ in the ambient $\\mathbb{R}^{3\\times 3}$; at each new sample
the estimate is brought back to its unit-determinant representative (`jump`,
`visjax.geometry.sl3_normalize`), so the saved estimates have det 1 to round-off.

Equation numbers: the paper's text was not available to this transcription; the observer
is cited by name and its properties derived above and tested.
"""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from ..geometry import pixel_to_normalized, sl3_normalize
from ._base import (
    AbstractJumpEstimator,
    Stream,
    checked_samples,
    reject_mask,
    rejected_samples,
)


class HomographyMeasurement(eqx.Module):
    """One sample: `p` (n, 3) the unit bearing directions of the points in the current
    image; `A` (3, 3) the group velocity ($\\dot H = H A$, trace-free)."""

    p: Float[Array, "*batch n 3"]
    A: Float[Array, "*batch 3 3"]


class HomographyState(eqx.Module):
    """`H` (3, 3): the estimate of the homography (current to reference); `Gamma` (3, 3):
    the estimate of the unknown part of the group velocity (zero and constant with
    `k_I = 0`)."""

    H: Float[Array, "*batch 3 3"]
    Gamma: Float[Array, "*batch 3 3"]


class HomographyOutput(eqx.Module):
    """`H` (3, 3) the estimate in SL(3); `A` (3, 3) the group velocity it integrates (the
    measured part plus the estimate $\\hat\\Gamma$); `cost` the correspondence misfit
    $\\sum_i (1 - e_i^T \\mathring p_i)$ (0 at the truth)."""

    H: Float[Array, "*batch 3 3"]
    A: Float[Array, "*batch 3 3"]
    cost: Float[Array, "*batch"]


def homography_bearings(
    H: Float[ArrayLike, "3 3"], p: Float[ArrayLike, "n 3"]
) -> Float[Array, "n 3"]:
    """The unit directions $H p_i / |H p_i|$ of directions `p` (n, 3) mapped by `H`."""
    H, p = jnp.asarray(H), jnp.asarray(p)
    q = p @ H.T
    return q / jnp.linalg.norm(q, axis=-1, keepdims=True)


def homography_innovation(
    H_hat: Float[ArrayLike, "3 3"], p: Float[ArrayLike, "n 3"], p_ref: Float[ArrayLike, "n 3"]
) -> Float[Array, "3 3"]:
    """The innovation $\\Delta = \\sum_i (I - e_i e_i^T)\\, \\mathring p_i\\, e_i^T$ with
    $e_i = \\hat H p_i / |\\hat H p_i|$ (module docstring): trace-free, zero at
    $\\hat H = H$. `p` (n, 3) current directions, `p_ref` (n, 3) reference unit directions."""
    H_hat, p, p_ref = (jnp.asarray(a) for a in (H_hat, p, p_ref))
    e = homography_bearings(H_hat, p)
    proj = p_ref - e * jnp.sum(e * p_ref, axis=-1, keepdims=True)  # (I - e e^T) p_ref
    return jnp.einsum("ni,nj->ij", proj, e)


class HomographyEstimator(AbstractJumpEstimator):
    """The observer of Hamel et al. (module docstring): `k_P` the gain of the innovation
    (1/s), `p_ref` (n, 3) the reference unit directions (n >= 4), `H0` (3, 3) the initial
    estimate (default the identity; brought to SL(3)), `k_I` the gain of the integral term
    (1/s; default 0: the group velocity is measured whole).

    The stream's `A` is the measured part of the group velocity: all of it (`k_I = 0`), the
    camera's angular velocity $[\\Omega]_\\times$ only (the rest estimated by the integral
    term), or zero (all of it estimated)."""

    k_P: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    p_ref: Float[Array, "n 3"] = eqx.field(converter=jnp.asarray)
    H0: Float[Array, "3 3"] = eqx.field(
        converter=jnp.asarray, default=((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    )
    k_I: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.0)

    def __check_init__(self):
        if self.p_ref.ndim != 2 or self.p_ref.shape[-1] != 3 or self.p_ref.shape[0] < 4:
            raise ValueError(
                f"`p_ref` must be (n, 3) reference directions with n >= 4; got {self.p_ref.shape}."
            )

    def init(self, y0: HomographyMeasurement) -> HomographyState:
        H = sl3_normalize(self.H0).astype(y0.p.dtype)
        return HomographyState(H=H, Gamma=jnp.zeros_like(H))

    def vector_field(self, t, state: HomographyState, y: HomographyMeasurement):
        delta = homography_innovation(state.H, y.p, self.p_ref)
        # dH/dt = H (A + Gamma) + k_P Delta H; dGamma/dt = k_I Ad_{H^T} Delta = k_I H^T
        # Delta H^-T (module docstring: the integral term)
        H = state.H
        gamma_dot = self.k_I * H.T @ jnp.linalg.solve(H, delta.T).T
        return HomographyState(H=H @ (y.A + state.Gamma) + self.k_P * delta @ H, Gamma=gamma_dot)

    def jump(self, state: HomographyState, y: HomographyMeasurement) -> HomographyState:
        return HomographyState(H=sl3_normalize(state.H), Gamma=state.Gamma)

    def output(self, t, state: HomographyState, y: HomographyMeasurement) -> HomographyOutput:
        e = homography_bearings(state.H, y.p)
        cost = jnp.sum(1.0 - jnp.sum(e * self.p_ref, axis=-1))
        return HomographyOutput(H=state.H, A=y.A + state.Gamma, cost=cost)

    def valid(self, state: HomographyState, y: HomographyMeasurement) -> Bool[Array, ""]:
        # an invertible estimate (det 1 after each jump; far from 0 between them) that maps
        # every current direction to within 90 degrees of its reference direction: beyond,
        # a point would be sent behind the reference camera (RESULTS.diverged)
        e = homography_bearings(state.H, y.p)
        ahead = jnp.all(jnp.sum(e * self.p_ref, axis=-1) > 0)
        return (jnp.abs(jnp.linalg.det(state.H)) > 1e-6) & ahead

    def max_stable_dt(self, y: HomographyMeasurement):
        """Euler on the linearised error. Near $E = \\hat H H^{-1} = I + \\varepsilon$,
        $\\Delta \\approx -L\\varepsilon$ with $L\\varepsilon = \\sum_i \\Pi_i\\, \\varepsilon\\,
        \\mathring p_i \\mathring p_i^T$ ($\\Pi_i = I - \\mathring p_i \\mathring p_i^T$), a
        symmetric positive semi-definite map of eigenvalues $\\mu \\in [0, n]$; then
        $\\dot\\varepsilon = -k_P L\\varepsilon - \\tilde\\Gamma$,
        $\\dot{\\tilde\\Gamma} = k_I L \\varepsilon$: per mode
        $\\lambda^2 + k_P\\mu\\lambda + k_I\\mu = 0$. Euler is stable for real roots when
        $\\Delta t < 2/(k_P n)$ and for complex ones when $\\Delta t < k_P / k_I$ (from
        $|1 + \\lambda\\Delta t| < 1$, whatever $\\mu$): the smaller bound. A longer step is
        refused (`RESULTS.unstable_step`), never integrated into garbage."""
        bound = 2.0 / (self.k_P * self.p_ref.shape[0])
        return jnp.where(self.k_I > 0, jnp.minimum(bound, self.k_P / self.k_I), bound)

    def checks(self):
        d = jnp.linalg.det(self.H0)
        return (
            (self.k_P > 0, "`k_P` must be positive"),
            (self.k_I >= 0, "`k_I` must be non-negative"),
            (jnp.isfinite(d) & (d != 0), "`H0` must be invertible"),
        )


def unit_bearings(pixels: Float[ArrayLike, "... 2"], K: Float[ArrayLike, "3 3"]):
    """Unit bearing directions $m / |m|$, $m = K^{-1} [u, v, 1]^T$, of pixels."""
    m = pixel_to_normalized(pixels, K)
    m = jnp.concatenate([m, jnp.ones_like(m[..., :1])], axis=-1)
    return m / jnp.linalg.norm(m, axis=-1, keepdims=True)


def homography_stream(
    ts: Float[ArrayLike, " N"],
    pixels: Float[ArrayLike, "N n 2"],
    group_velocity: Float[ArrayLike, "N 3 3"],
    K: Float[ArrayLike, "3 3"],
    *,
    reject: Bool[ArrayLike, " N"] | None = None,
    truth=None,
    throw: bool = True,
) -> Stream:
    """The observer's stream from pixel tracks (N, n, 2) of a camera with intrinsics `K`
    and the group velocity (N, 3, 3) at each sample. `reject` (N,) bool: the samples an
    outlier test rejected, held over as dropped ones (`Stream.present`; the first must be
    kept). `throw`: a non-finite sample raises, naming it; with `throw=False` the run
    stops there."""
    ts, pixels, A = (jnp.asarray(a, float) for a in (ts, pixels, group_velocity))
    if pixels.ndim != 3 or pixels.shape[-1] != 2 or pixels.shape[0] != ts.shape[0]:
        raise ValueError(f"`pixels` must have shape (N, n, 2) with N = {ts.shape[0]}.")
    if A.shape != (ts.shape[0], 3, 3):
        raise ValueError(f"`group_velocity` must have shape ({ts.shape[0]}, 3, 3); got {A.shape}.")
    stream = Stream(ts=ts, ys=HomographyMeasurement(p=unit_bearings(pixels, K), A=A), truth=truth)
    stream = rejected_samples(stream, reject_mask(reject, ts.shape[0]))
    return checked_samples(stream, "homography_stream", throw)
