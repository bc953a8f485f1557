"""The homography observer on SL(3) from direct point correspondences.

T. Hamel, R. Mahony, J. Trumpf, P. Morin, M.-D. Hua, *Homography estimation on the Special
Linear group based on direct point correspondence*, IEEE CDC-ECC 2011.

Built on visjax's public contract only (`visjax.estimators.AbstractJumpEstimator`,
`Stream`, `checked_samples`; `visjax.geometry`'s SL(3) functions), as a user's estimator
would be (`docs/extending.md`).

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

The runner integrates $\\hat H$ in the ambient $\\mathbb{R}^{3\\times 3}$; at each new sample
the estimate is brought back to its unit-determinant representative (`jump`,
`visjax.geometry.sl3_normalize`), so the saved estimates have det 1 to round-off.

Equation numbers: the paper's text was not available to this transcription; the observer
is cited by name and its properties derived above and tested.
"""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from ..estimators import AbstractJumpEstimator, Stream, checked_samples
from ..geometry import pixel_to_normalized, sl3_normalize


class HomographyMeasurement(eqx.Module):
    """One sample: `p` (n, 3) the unit bearing directions of the points in the current
    image; `A` (3, 3) the group velocity ($\\dot H = H A$, trace-free)."""

    p: Float[Array, "*batch n 3"]
    A: Float[Array, "*batch 3 3"]


class HomographyState(eqx.Module):
    """`H` (3, 3): the estimate of the homography (current to reference)."""

    H: Float[Array, "*batch 3 3"]


class HomographyOutput(eqx.Module):
    """`H` (3, 3) the estimate in SL(3); `cost` the correspondence misfit
    $\\sum_i (1 - e_i^T \\mathring p_i)$ (0 at the truth)."""

    H: Float[Array, "*batch 3 3"]
    cost: Float[Array, "*batch"]


def _bearings(H, p):
    q = p @ H.T
    return q / jnp.linalg.norm(q, axis=-1, keepdims=True)


def homography_innovation(
    H_hat: Float[ArrayLike, "3 3"], p: Float[ArrayLike, "n 3"], p_ref: Float[ArrayLike, "n 3"]
) -> Float[Array, "3 3"]:
    """The innovation $\\Delta = \\sum_i (I - e_i e_i^T)\\, \\mathring p_i\\, e_i^T$ with
    $e_i = \\hat H p_i / |\\hat H p_i|$ (module docstring): trace-free, zero at
    $\\hat H = H$. `p` (n, 3) current directions, `p_ref` (n, 3) reference unit directions."""
    H_hat, p, p_ref = (jnp.asarray(a) for a in (H_hat, p, p_ref))
    e = _bearings(H_hat, p)
    proj = p_ref - e * jnp.sum(e * p_ref, axis=-1, keepdims=True)  # (I - e e^T) p_ref
    return jnp.einsum("ni,nj->ij", proj, e)


class HomographyObserver(AbstractJumpEstimator):
    """The observer of Hamel et al. with a known group velocity (module docstring): `k_P`
    the gain (1/s), `p_ref` (n, 3) the reference unit directions (n >= 4), `H0` (3, 3)
    the initial estimate (default the identity; brought to SL(3))."""

    k_P: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    p_ref: Float[Array, "n 3"] = eqx.field(converter=jnp.asarray)
    H0: Float[Array, "3 3"] = eqx.field(
        converter=jnp.asarray, default=((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    )

    def __check_init__(self):
        if self.p_ref.ndim != 2 or self.p_ref.shape[-1] != 3 or self.p_ref.shape[0] < 4:
            raise ValueError(
                f"`p_ref` must be (n, 3) reference directions with n >= 4; got {self.p_ref.shape}."
            )

    def init(self, y0: HomographyMeasurement) -> HomographyState:
        return HomographyState(H=sl3_normalize(self.H0).astype(y0.p.dtype))

    def vector_field(self, t, state: HomographyState, y: HomographyMeasurement):
        delta = homography_innovation(state.H, y.p, self.p_ref)
        return HomographyState(H=state.H @ y.A + self.k_P * delta @ state.H)

    def jump(self, state: HomographyState, y: HomographyMeasurement) -> HomographyState:
        return HomographyState(H=sl3_normalize(state.H))

    def output(self, t, state: HomographyState, y: HomographyMeasurement) -> HomographyOutput:
        e = _bearings(state.H, y.p)
        return HomographyOutput(H=state.H, cost=jnp.sum(1.0 - jnp.sum(e * self.p_ref, axis=-1)))

    def valid(self, state: HomographyState, y: HomographyMeasurement) -> Bool[Array, ""]:
        # an invertible estimate (det 1 after each jump; far from 0 between them)
        return jnp.abs(jnp.linalg.det(state.H)) > 1e-6

    def checks(self):
        d = jnp.linalg.det(self.H0)
        return (
            (self.k_P > 0, "`k_P` must be positive"),
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
    truth=None,
    throw: bool = True,
) -> Stream:
    """The observer's stream from pixel tracks (N, n, 2) of a camera with intrinsics `K`
    and the group velocity (N, 3, 3) at each sample. `throw`: a non-finite sample raises,
    naming it; with `throw=False` the run stops there."""
    ts, pixels, A = (jnp.asarray(a, float) for a in (ts, pixels, group_velocity))
    if pixels.ndim != 3 or pixels.shape[-1] != 2 or pixels.shape[0] != ts.shape[0]:
        raise ValueError(f"`pixels` must have shape (N, n, 2) with N = {ts.shape[0]}.")
    if A.shape != (ts.shape[0], 3, 3):
        raise ValueError(f"`group_velocity` must have shape ({ts.shape[0]}, 3, 3); got {A.shape}.")
    stream = Stream(ts=ts, ys=HomographyMeasurement(p=unit_bearings(pixels, K), A=A), truth=truth)
    return checked_samples(stream, "homography_stream", throw)
