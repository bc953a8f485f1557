"""Robust losses and the covariance of a least-squares estimate, shared by the batch
baselines (not from the papers: the textbook M-estimators and the Gauss-Newton covariance).

A loss $\\rho$ acts on the norm $s = \\|r_i\\|$ of each residual block $r_i$ (a feature's pixel
pair): the fit minimises $\\sum_i \\rho(\\|r_i\\|)$. With $\\rho(s) = s^2/2$ that is least
squares; Huber's $\\rho(s) = s^2/2$ for $s \\le k$, $k(s - k/2)$ beyond, grows linearly for
outliers; Cauchy's $\\rho(s) = \\tfrac{k^2}{2}\\log(1 + s^2/k^2)$ grows only logarithmically
(Huber, "Robust Statistics"; Hartley and Zisserman, "Multiple View Geometry", app. A6.8).
Every least-squares solver minimises $\\tfrac12\\sum\\|\\tilde r_i\\|^2$: the blocks are passed
to it rescaled, $\\tilde r_i = w(s)\\, r_i$ with $w(s) = \\sqrt{2\\rho(s)}/s$ (so that
$\\tfrac12\\|\\tilde r_i\\|^2 = \\rho(s)$ exactly; $w \\to 1$ as $s \\to 0$), and its solution is
the M-estimate itself, not an approximation of it.

The covariance of an estimate $\\hat y$ from $m$ residuals and $p$ unknowns:
$\\hat\\sigma^2 (J^T J)^{-1}$ with $J$ the Jacobian of the residuals at $\\hat y$ and
$\\hat\\sigma^2 = \\|r\\|^2 / (m - p)$ the residual variance (the Gauss-Newton approximation of
the inverse Hessian; exact for a linear model with independent equal-variance noise).
"""

from typing import Literal, final

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._util import covariance as covariance


@final
class Loss(eqx.Module):
    """A loss on the norm of each residual block (module docstring): `kind` `"squared"`
    (least squares, the default everywhere), `"huber"` or `"cauchy"`; `scale` $k$, in the
    residuals' units (pixels for pixel residuals: e.g. 2-3 times the noise level)."""

    kind: Literal["squared", "huber", "cauchy"] = eqx.field(default="squared", static=True)
    scale: Float[Array, ""] = eqx.field(default=1.0, converter=jnp.asarray)

    def __check_init__(self):
        if self.kind not in ("squared", "huber", "cauchy"):
            raise ValueError(f'`kind` must be "squared", "huber" or "cauchy"; got {self.kind!r}.')
        if jnp.shape(self.scale) != ():
            raise ValueError(f"`scale` must be a scalar; got shape {jnp.shape(self.scale)}.")

    def checks(self):
        """The scale must be positive and finite (concrete values are refused by the
        baselines before they run)."""
        return jnp.isfinite(self.scale) & (self.scale > 0)

    def rho(self, s):
        """$\\rho(s)$ for block norms `s`."""
        k = self.scale.astype(jnp.result_type(s))
        if self.kind == "squared":
            return 0.5 * s**2
        if self.kind == "huber":
            return jnp.where(s <= k, 0.5 * s**2, k * (s - 0.5 * k))
        return 0.5 * k**2 * jnp.log1p((s / k) ** 2)

    def weight(self, s):
        """$w(s) = \\sqrt{2\\rho(s)}/s$, 1 at $s = 0$, smooth (differentiable) there."""
        if self.kind == "squared":
            return jnp.ones_like(s)
        k = self.scale.astype(jnp.result_type(s))
        small = s < 1e-8 * k
        t = jnp.where(small, k, s)  # a safe argument where the limit is taken
        if self.kind == "huber":
            w = jnp.where(t <= k, 1.0, jnp.sqrt(jnp.maximum(2.0 * k * t - k**2, 0.0)) / t)
        else:
            w = k * jnp.sqrt(jnp.log1p((t / k) ** 2)) / t
        return jnp.where(small, 1.0, w)

    def irls_weight(self, s):
        """The M-estimator's weight $\\psi(s)/s = \\rho'(s)/s$ at block norms `s` (Huber,
        *Robust Statistics*; Hartley and Zisserman app. A6.8): iteratively reweighted least
        squares minimises $\\sum_i \\rho(\\|r_i\\|)$ by weighting each block's squared
        norm with it at the current residuals (a fixed point of the reweighting is a
        stationary point of the loss). Squared: 1; Huber: 1 for $s \\le k$, $k/s$ beyond;
        Cauchy: $1/(1 + s^2/k^2)$. In $(0, 1]$, 1 at $s = 0$; continuous, and differentiable
        but at Huber's threshold."""
        if self.kind == "squared":
            return jnp.ones_like(s)
        k = self.scale.astype(jnp.result_type(s))
        if self.kind == "huber":
            return jnp.where(s <= k, 1.0, k / jnp.maximum(s, k))
        return 1.0 / (1.0 + (s / k) ** 2)

    def __call__(self, r: Float[Array, "... d"]) -> Float[Array, "... d"]:
        """The rescaled residual blocks $\\tilde r_i = w(\\|r_i\\|) r_i$ (the last axis is a
        block), whose half squared norm is $\\rho(\\|r_i\\|)$."""
        if self.kind == "squared":
            return r
        s2 = jnp.sum(r * r, axis=-1, keepdims=True)
        safe = jnp.where(s2 > 0, s2, 1.0)
        s = jnp.where(s2 > 0, jnp.sqrt(safe), 0.0)
        return self.weight(s) * r


def as_loss(loss) -> Loss:
    """`None` (least squares), a `Loss`, or one of "squared", "huber", "cauchy" (scale 1)."""
    if loss is None:
        return Loss()
    if isinstance(loss, str):
        return Loss(kind=loss)
    if not isinstance(loss, Loss):
        raise ValueError(f"`loss` must be a visjax.baselines.Loss, a name or None; got {loss!r}.")
    try:
        ok = bool(loss.checks())
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerBoolConversionError):
        ok = True  # traced: the baseline's result code says so
    if not ok:
        raise ValueError(f"the loss' `scale` must be positive and finite; got {loss.scale}.")
    return loss


def huber(scale) -> Loss:
    """Huber's loss with threshold `scale` (module docstring)."""
    return Loss(kind="huber", scale=scale)


def cauchy(scale) -> Loss:
    """The Cauchy (Lorentzian) loss with scale `scale` (module docstring)."""
    return Loss(kind="cauchy", scale=scale)
