"""The uncertainty of a comparison over noise seeds: a percentile-bootstrap confidence
interval of a statistic (`bootstrap_interval`), and for two methods run on the same draws
the paired comparison (`paired_comparison`: the median difference, its interval, and the
Wilcoxon signed-rank test's p-value, `wilcoxon_signed_rank`). Pure JAX with static sizes:
NaN entries (a failed run) are left out through masks, so each works under `jit`, `vmap`
and (where a value is differentiable: the statistics, not a p-value) `grad`.

References: B. Efron and R. J. Tibshirani, *An Introduction to the Bootstrap* (1993), ch.
13 (the percentile interval); F. Wilcoxon, "Individual comparisons by ranking methods",
*Biometrics Bulletin* 1(6), 1945 (the signed-rank statistic); its exact null distribution
by counting the subsets of ranks with each sum, and the normal approximation with the
correction for tied ranks, as in M. Hollander, D. A. Wolfe and E. Chicken, *Nonparametric
Statistical Methods* (3rd ed., 2014), sec. 3.1.
"""

import functools
import math
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

EXACT_MAX = 50
"""The most nonzero differences for which `wilcoxon_signed_rank` counts the exact null
distribution (without tied ranks); above, or with ties, the normal approximation."""


class Interval(NamedTuple):
    """A statistic and its confidence interval: `value` (on the data), `low`, `high`
    (percentile bootstrap), `n` (the values used: the finite ones)."""

    value: Float[Array, ""]
    low: Float[Array, ""]
    high: Float[Array, ""]
    n: Array


class Paired(NamedTuple):
    """Two methods on the same draws (`paired_comparison`): `difference`, the median of
    `a - b` over the draws where both are finite, with its interval (`low`, `high`);
    `pvalue`, the two-sided Wilcoxon signed-rank test of a zero median difference; `n`,
    the pairs used."""

    difference: Float[Array, ""]
    low: Float[Array, ""]
    high: Float[Array, ""]
    pvalue: Float[Array, ""]
    n: Array


def _masked_median(x: Array, mask: Array) -> Array:
    """The median of `x` where `mask` (NaN if none): sorted with the others last."""
    m = jnp.sum(mask)
    s = jnp.sort(jnp.where(mask, x, jnp.inf))
    lo = s[jnp.clip((m - 1) // 2, 0, x.shape[0] - 1)]
    hi = s[jnp.clip(m // 2, 0, x.shape[0] - 1)]
    return jnp.where(m > 0, 0.5 * (lo + hi), jnp.nan)


@functools.partial(jax.jit, static_argnames=("level", "resamples", "statistic"))
def bootstrap_interval(
    key: Array,
    values: Float[ArrayLike, " n"],
    *,
    level: float = 0.95,
    resamples: int = 2000,
    statistic: Callable[[Array], Array] | None = None,
) -> Interval:
    """The percentile-bootstrap confidence interval (Efron and Tibshirani, ch. 13) of a
    statistic of `values` (default the median): the statistic of `resamples` resamples
    with replacement of the finite values, its `(1 - level) / 2` and `(1 + level) / 2`
    quantiles. NaN values (failed runs) are left out; fewer than 2 finite values give a
    NaN interval.

    **Arguments:** `key` (a PRNG key); `values` (n,); `level`; `resamples`; `statistic`:
    a function of a 1-D array (of the finite values' length: under `jit`, pass the finite
    values alone) instead of the median.

    **Returns:** an `Interval`. Pure JAX (`jit`, `vmap`, `grad` with respect to `values`)."""
    if not 0 < level < 1:
        raise ValueError(f"`level` must be in (0, 1); got {level!r}.")
    if int(resamples) < 10:
        raise ValueError(f"`resamples` must be at least 10; got {resamples!r}.")
    x = jnp.asarray(values, float)
    if x.ndim != 1 or x.shape[0] < 1:
        raise ValueError(f"`values` must be a non-empty 1-D array; got shape {x.shape}.")
    n = x.shape[0]
    mask = jnp.isfinite(x)
    m = jnp.sum(mask)
    safe = jnp.where(mask, x, 0.0)
    if statistic is None:

        def stat(v, w):
            return _masked_median(v, w)
    else:

        def stat(v, w):
            return statistic(v)

    # a resample: n draws among the m finite values (their indices first in `order`)
    order = jnp.argsort(~mask, stable=True)
    u = jax.random.uniform(key, (int(resamples), n))
    picks = order[jnp.minimum((u * m.astype(u.dtype)).astype(int), jnp.maximum(m - 1, 0))]
    keep = jnp.arange(n) < m  # the first m draws of each resample are its m values
    stats = jax.vmap(lambda i: stat(safe[i], keep))(picks)
    q = jnp.array([(1 - level) / 2, (1 + level) / 2])
    low, high = jnp.quantile(stats, q)
    enough = m >= 2
    nan = jnp.nan
    return Interval(
        stat(safe, mask) if statistic is None else statistic(x),
        jnp.where(enough, low, nan),
        jnp.where(enough, high, nan),
        m,
    )


def _ranks(a: Array, mask: Array) -> Array:
    """The average ranks (1-based, ties the mean of their ranks) of `a` among the entries
    where `mask`; 0 elsewhere."""
    below = jnp.sum(mask[None, :] & (a[None, :] < a[:, None]), axis=1).astype(a.dtype)
    equal = jnp.sum(mask[None, :] & (a[None, :] == a[:, None]), axis=1).astype(a.dtype)
    return jnp.where(mask, below + (equal + 1) / 2, 0.0)


def _null_counts(m: Array, n: int, dtype) -> Array:
    """The number of subsets of the ranks 1..m with each sum 0..n(n+1)/2 (the exact null
    distribution of the signed-rank statistic times 2^m), for a traced m <= n."""
    size = n * (n + 1) // 2 + 1
    at = jnp.arange(size)

    def with_rank(k, counts):  # each subset with rank k added, or not
        return counts + jnp.where(at >= k, jnp.roll(counts, k), 0.0)

    return jax.lax.fori_loop(1, m + 1, with_rank, jnp.zeros(size, dtype).at[0].set(1.0))


@jax.jit
def wilcoxon_signed_rank(
    d: Float[ArrayLike, " n"], valid: Bool[ArrayLike, " n"] | None = None
) -> tuple[Array, Array]:
    """The two-sided Wilcoxon signed-rank test (Wilcoxon 1945) of a zero median of the
    paired differences `d`: zeros and NaN (or entries not `valid`) are left out (Wilcoxon's
    own treatment of zeros); the statistic is the sum of the positive differences' ranks,
    $W^+ = \\sum_{d_i > 0} R_i$ (ranks of $|d_i|$, ties averaged). The p-value is exact
    (the null distribution counted over the $2^m$ sign patterns) for at most `EXACT_MAX`
    differences without tied ranks; otherwise from the normal approximation, $z = (W^+ -
    m(m+1)/4)/\\sigma$, $\\sigma^2 = m(m+1)(2m+1)/24 - \\sum_t (t^3 - t)/48$ over groups of
    $t$ tied ranks, without a continuity correction (SciPy's `wilcoxon` defaults; with ties
    and at most 13 differences SciPy runs a permutation test instead).

    **Returns:** `(statistic, pvalue)`, NaN when no difference is left. Pure JAX (`jit`,
    `vmap`; a p-value has no useful gradient)."""
    d = jnp.asarray(d, float)
    if d.ndim != 1:
        raise ValueError(f"`d` must be a 1-D array; got shape {d.shape}.")
    n = d.shape[0]
    mask = jnp.isfinite(d) & (d != 0)
    if valid is not None:
        mask = mask & jnp.asarray(valid, bool)
    m = jnp.sum(mask)
    a = jnp.abs(jnp.where(mask, d, 0.0))
    r = _ranks(a, mask)
    w_plus = jnp.sum(jnp.where(mask & (d > 0), r, 0.0))
    equal = jnp.sum(mask[None, :] & (a[None, :] == a[:, None]), axis=1).astype(a.dtype)  # t
    ties = jnp.sum(jnp.where(mask, (equal**2 - 1.0), 0.0)) / 48.0  # sum_t (t^3 - t) / 48
    mf = m.astype(d.dtype)
    var = mf * (mf + 1) * (2 * mf + 1) / 24.0 - ties
    z = (w_plus - mf * (mf + 1) / 4.0) / jnp.sqrt(jnp.maximum(var, 1e-300))
    p_normal = jnp.minimum(1.0, jax.scipy.special.erfc(jnp.abs(z) / math.sqrt(2.0)))  # 2(1 - Phi)
    if n <= EXACT_MAX:
        counts = _null_counts(m, n, d.dtype)
        total = jnp.sum(counts)
        k = jnp.floor(w_plus + 1e-9).astype(int)
        at = jnp.arange(counts.shape[0])
        cdf = jnp.sum(jnp.where(at <= k, counts, 0.0)) / total
        sf = jnp.sum(jnp.where(at >= k, counts, 0.0)) / total
        p_exact = jnp.minimum(1.0, 2.0 * jnp.minimum(cdf, sf))
        exact = jnp.all(jnp.where(mask, equal == 1.0, True))
        p = jnp.where(exact, p_exact, p_normal)
    else:
        p = p_normal
    none = m == 0
    return jnp.where(none, jnp.nan, w_plus), jnp.where(none, jnp.nan, p)


def paired_comparison(
    key: Array,
    a: Float[ArrayLike, " n"],
    b: Float[ArrayLike, " n"],
    *,
    level: float = 0.95,
    resamples: int = 2000,
) -> Paired:
    """Two methods' metric on the same draws (`a[i]`, `b[i]` from draw i): the median of
    the differences `a - b` over the draws where both are finite, its percentile-bootstrap
    interval (the draws resampled as pairs: `bootstrap_interval` of the differences), and
    the Wilcoxon signed-rank p-value (`wilcoxon_signed_rank`). Pure JAX."""
    a, b = jnp.asarray(a, float), jnp.asarray(b, float)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"`a` and `b` must be 1-D of one shape; got {a.shape}, {b.shape}.")
    d = a - b  # NaN where either failed
    ci = bootstrap_interval(key, d, level=level, resamples=resamples)
    _, p = wilcoxon_signed_rank(d)
    return Paired(ci.value, ci.low, ci.high, p, ci.n)
