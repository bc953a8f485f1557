"""The comparison's uncertainty (`studies.bootstrap_interval`, `wilcoxon_signed_rank`,
`paired_comparison`, `Comparison.statistics`): the signed-rank test against SciPy's
`wilcoxon` (exact and normal approximation, ties and zeros), the bootstrap interval's
coverage on a statistic with a known answer, failed runs left out, `jit`/`vmap`/`grad`."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.stats

from visjax import studies


@pytest.mark.parametrize("n", [5, 12, 30, 50])
def test_wilcoxon_exact_against_scipy(n):
    d = np.random.default_rng(n).normal(0.3, 1.0, n)
    w, p = jax.jit(studies.wilcoxon_signed_rank)(d)
    ref = scipy.stats.wilcoxon(d, method="exact")
    total = n * (n + 1) / 2  # SciPy's two-sided statistic: min(W+, W-)
    assert min(float(w), total - float(w)) == ref.statistic
    np.testing.assert_allclose(p, ref.pvalue, rtol=1e-12)


def test_wilcoxon_normal_approximation_ties_zeros_and_nan_against_scipy():
    rng = np.random.default_rng(3)
    for d in (rng.normal(0.2, 1.0, 60), rng.normal(-0.1, 1.0, 200)):
        _, p = studies.wilcoxon_signed_rank(d)
        np.testing.assert_allclose(p, scipy.stats.wilcoxon(d, method="asymptotic").pvalue, 1e-12)
    d = np.round(rng.normal(0.3, 1.0, 40), 1)  # tied ranks, and three zeros (left out)
    d[:3] = 0.0
    _, p = studies.wilcoxon_signed_rank(d)
    np.testing.assert_allclose(p, scipy.stats.wilcoxon(d, method="asymptotic").pvalue, 1e-12)
    # a NaN (a failed run) is left out, as if the pair were not there
    _, p_nan = studies.wilcoxon_signed_rank(np.r_[d, np.nan])
    np.testing.assert_allclose(p_nan, p, rtol=1e-12)
    # a batch of tests is one vmap
    batch = jax.vmap(studies.wilcoxon_signed_rank)(np.stack([d, -d]))[1]
    np.testing.assert_allclose(batch, [p, p], rtol=1e-12)
    assert np.isnan(studies.wilcoxon_signed_rank(np.zeros(4))[1])  # nothing left


def test_bootstrap_interval_covers_the_mean_of_gaussian_draws():
    """The 95% percentile interval of the mean of 30 standard normal draws contains the
    true mean 0 in 95% of 400 independent trials, within 3 points (measured 94.5%)."""

    def covered(key):
        k1, k2 = jax.random.split(key)
        x = jax.random.normal(k1, (30,))
        ci = studies.bootstrap_interval(k2, x, resamples=1000, statistic=jnp.mean)
        return (ci.low <= 0.0) & (0.0 <= ci.high)

    keys = jax.random.split(jax.random.key(7), 400)
    coverage = float(jax.jit(jax.vmap(covered))(keys).mean())
    assert abs(coverage - 0.95) < 0.03, coverage


def test_bootstrap_interval_leaves_failures_out_and_differentiates():
    x = np.array([1.0, 3.0, np.nan, 2.0, 5.0, np.nan, 4.0])
    key = jax.random.key(0)
    ci = jax.jit(studies.bootstrap_interval)(key, x)
    assert float(ci.value) == 3.0 and int(ci.n) == 5 and 1.0 <= ci.low <= 3.0 <= ci.high <= 5.0
    assert np.isnan(studies.bootstrap_interval(key, np.array([1.0, np.nan])).low)
    # the median's derivative: 1/2 on each of the two middle values of an even count
    g = jax.grad(lambda v: studies.bootstrap_interval(key, v).value)(np.array([4.0, 1.0, 3.0, 2.0]))
    np.testing.assert_allclose(g, [0.0, 0.0, 0.5, 0.5])
    with pytest.raises(ValueError, match="level"):
        studies.bootstrap_interval(key, x, level=95.0)


def test_paired_comparison_of_a_shift():
    """b = a + 0.5 + 0.01 i on draw i: the median difference is -0.55 (draw 3 failed, the
    others' middle is i = 5), inside [-0.59, -0.5]; every sign negative (exact p = 2 /
    2^9, SciPy's); a failed draw of either drops the pair."""
    a = np.random.default_rng(1).normal(size=10)
    b = a + 0.5 + 0.01 * np.arange(10)
    b[3] = np.nan
    c = studies.paired_comparison(jax.random.key(1), a, b)
    np.testing.assert_allclose(c.difference, -0.55, rtol=1e-12)
    assert -0.59 - 1e-12 <= c.low <= c.difference <= c.high <= -0.5 + 1e-12 and int(c.n) == 9
    np.testing.assert_allclose(c.pvalue, 2 / 2**9, rtol=1e-12)
    ok = np.isfinite(b)
    np.testing.assert_allclose(c.pvalue, scipy.stats.wilcoxon(a[ok], b[ok]).pvalue, rtol=1e-12)


def test_statistics_of_a_comparison_and_its_tables():
    rows = []
    for seed in range(6):  # "b" worse by 0.1 + 0.01 seed on each seed, "c" fails on seed 2
        rows.append({"method": "a", "seed": seed, "result": "successful", "err": 1.0 + seed})
        rows.append({"method": "b", "seed": seed, "result": "successful", "err": 1.1 + 1.01 * seed})
        bad = seed == 2
        code = "nonfinite_measurement" if bad else "successful"
        rows.append({"method": "c", "seed": seed, "result": code, "err": None if bad else seed / 2})
    stats = studies.Comparison(rows).statistics("err")
    a, c = stats["methods"]["a"], stats["methods"]["c"]
    assert a["median"] == 3.5 and a["n"] == 6 and a["failure_rate"] == 0.0
    assert c["n"] == 5 and c["failure_rate"] == pytest.approx(1 / 6)
    assert c["results"] == {"successful": 5, "nonfinite_measurement": 1}
    ab = stats["pairs"][0]
    # a - b = -(0.1 + 0.01 seed): the median of 0.1, ..., 0.15 is 0.125
    assert (ab["a"], ab["b"]) == ("a", "b") and ab["median_difference"] == pytest.approx(-0.125)
    assert ab["pvalue"] == pytest.approx(2 / 2**6) and ab["n"] == 6
    assert [p["n"] for p in stats["pairs"]] == [6, 5, 5]
    per, pairs = studies.statistics_tables(stats)
    md = studies.table_text(per, "md")
    assert md.splitlines()[0].startswith("| method | err median | 95% CI low")
    assert "nonfinite_measurement 1" in md
    tex = studies.table_text(pairs, "tex")
    assert tex.startswith(r"\begin{tabular}{lrrrrr}") and r"a - b & -0.125 &" in tex
