"""A causal output filter for noisy estimates.

Chitrakaran et al. (*Identification of a moving object's velocity with a fixed camera*,
section 6.1) note that pixel noise enters the velocity estimate through the high-gain
sign-based law and suggest filtering. `lowpass` is a causal second-order Butterworth
low-pass filter, applied after the estimator (it never feeds back), with its bandwidth and
its delay stated so that a comparison with other methods can be made at equal bandwidth.
"""

import math

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._util import as_float, check_shape


def lowpass_delay(cutoff_hz: float) -> float:
    """The delay (s) of `lowpass` at low frequencies: the group delay at DC of the
    second-order Butterworth filter, $2\\zeta/\\omega_c = \\sqrt 2/(2\\pi f_c)$."""
    if not cutoff_hz > 0:
        raise ValueError(f"`cutoff_hz` must be positive; got {cutoff_hz!r}.")
    return math.sqrt(2.0) / (2.0 * math.pi * cutoff_hz)


def lowpass(
    ts: Float[ArrayLike, " N"],
    signal: Float[ArrayLike, " N *d"],
    cutoff_hz: float | Float[ArrayLike, ""],
) -> Float[Array, " N *d"]:
    """Causal second-order Butterworth low-pass filter of a sampled signal, per channel.

    $H(s) = \\omega_c^2 / (s^2 + \\sqrt 2\\,\\omega_c s + \\omega_c^2)$, $\\omega_c = 2\\pi f_c$:
    gain $1/\\sqrt 2$ (-3 dB) at `cutoff_hz`, -40 dB per decade above, a delay of
    `lowpass_delay(cutoff_hz)` at low frequencies. Discretised exactly for a signal held
    between samples (zero-order hold, the matrix exponential in closed form per sample interval, so
    non-uniform times are fine); started at rest at the first sample (no start transient).
    The output at $t_k$ uses samples up to $t_k$ only.

    **Arguments:** `ts` (N,) increasing times; `signal` (N, ...) values; `cutoff_hz` the
    bandwidth (an array: gradients flow through it).

    **Returns:** the filtered signal, shape of `signal`. NaN in, NaN from there on.
    """
    ts, signal = as_float(ts), as_float(signal)
    check_shape(ts, (None,), "ts")
    if signal.ndim < 1 or signal.shape[0] != ts.shape[0]:
        raise ValueError(
            f"`signal` must have the {ts.shape[0]} samples of `ts` first; got {signal.shape}."
        )
    fc = as_float(cutoff_hz)
    check_shape(fc, (), "cutoff_hz")
    dtype = jnp.result_type(ts, signal, fc)
    w = 2.0 * jnp.pi * fc
    sigma = w / jnp.sqrt(2.0)  # the poles -sigma +- i omega_d, omega_d = sigma (zeta = 1/sqrt 2)
    F = jnp.stack(
        [jnp.stack([jnp.zeros_like(w), jnp.ones_like(w)]), jnp.stack([-(w**2), -2.0 * sigma])]
    )
    G = jnp.stack([jnp.zeros_like(w), w**2])
    eye = jnp.eye(2, dtype=dtype)

    def discretise(h):
        # Phi = exp(F h) in closed form for the complex pair: e^{-sigma h} [cos(omega_d h) I
        # + sin(omega_d h)/omega_d (F + sigma I)]; Gamma = F^{-1}(Phi - I) G (F invertible,
        # det F = omega_c^2): the zero-order-hold pair
        c, s_ = jnp.cos(sigma * h), jnp.sin(sigma * h)
        Phi = jnp.exp(-sigma * h) * (c * eye + (s_ / sigma) * (F + sigma * eye))
        return Phi, jnp.linalg.solve(F, (Phi - eye) @ G)

    Phi, Gam = jax.vmap(discretise)(jnp.diff(ts))
    flat = signal.reshape(signal.shape[0], -1)
    x0 = jnp.stack([flat[0], jnp.zeros_like(flat[0])])  # at rest at the first value

    def step(x, inputs):
        P, g, u = inputs
        x = P @ x + g[:, None] * u[None, :]
        return x, x[0]

    _, ys = jax.lax.scan(step, x0, (Phi, Gam, flat[:-1]))
    out = jnp.concatenate([flat[:1], ys], axis=0)
    return out.reshape(signal.shape)
