"""`find_homography_robust`: RANSAC and reweighted refinement against the truth and against
OpenCV's RANSAC and USAC on the same correspondences.

The scenes: a random homography (the image's corners moved by up to 100 px), 60 points
uniform in a 640 x 480 image, 0.5 px of Gaussian noise on the inliers, the outliers'
`dst` uniform in the image. Every test uses one size (60 points, 200 hypotheses), so
that each program is compiled once.
"""

import cv2
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax import RESULTS, result_names
from visjax.geometry import RobustHomography, find_homography_robust
from visjax.geometry._robust import _samples

N, ITERATIONS, THRESHOLD = 60, 200, 3.0
FRACTIONS = (0.0, 0.1, 0.2, 0.4)
FRAMES = 8  # per outlier fraction
WIDTH, HEIGHT = 640.0, 480.0
CORNERS = np.array([[0.0, 0.0], [WIDTH, 0.0], [WIDTH, HEIGHT], [0.0, HEIGHT]])
USAC = getattr(cv2, "USAC_MAGSAC", cv2.USAC_DEFAULT)


def _robust(key, src, dst):
    return find_homography_robust(
        key, src, dst, iterations=ITERATIONS, threshold_px=THRESHOLD, throw=False
    )


robust_one = jax.jit(_robust)
robust_batch = jax.jit(jax.vmap(_robust))


def _four_point_homography(a, b):
    """The homography mapping the four points `a` to `b` (NumPy, exact 8 x 8 solve)."""
    rows, rhs = [], []
    for (u, v), (x, y) in zip(a, b):
        rows += [[u, v, 1, 0, 0, 0, -x * u, -x * v], [0, 0, 0, u, v, 1, -y * u, -y * v]]
        rhs += [x, y]
    return np.append(np.linalg.solve(np.array(rows), np.array(rhs)), 1.0).reshape(3, 3)


def _apply(H, p):
    q = np.einsum("...ij,...nj->...ni", H, np.concatenate([p, np.ones_like(p[..., :1])], -1))
    return q[..., :2] / q[..., 2:]


def _scene(rng, outlier_fraction, noise=0.5):
    """`(H, src, dst, is_inlier)`: `dst ~ H src` plus noise for the inliers."""
    H = _four_point_homography(CORNERS, CORNERS + rng.uniform(-100.0, 100.0, (4, 2)))
    src = rng.uniform([0.0, 0.0], [WIDTH, HEIGHT], (N, 2))
    dst = _apply(H, src) + noise * rng.standard_normal((N, 2))
    k = int(round(outlier_fraction * N))
    out = rng.permutation(N)[:k]
    dst[out] = rng.uniform([0.0, 0.0], [WIDTH, HEIGHT], (k, 2))
    is_inlier = np.ones(N, bool)
    is_inlier[out] = False
    return H, src, dst, is_inlier


def corner_error(H_true, H):
    """The homography error: the largest distance, in px, between the images of the four
    image corners under the true and the estimated homography."""
    return np.max(np.linalg.norm(_apply(H_true, CORNERS) - _apply(H, CORNERS), axis=-1), -1)


def _ok(result):
    return np.asarray(result._value) == int(RESULTS.successful._value)


@pytest.fixture(scope="module")
def scenes():
    """Every scene of every fraction in one batch, and visjax's estimates of all of them
    (one call)."""
    rng = np.random.default_rng(2024)
    parts = [_scene(rng, f) for f in FRACTIONS for _ in range(FRAMES)]
    H, src, dst, truth = (np.stack(x) for x in zip(*parts))
    keys = jax.random.split(jax.random.key(7), len(parts))
    est = robust_batch(keys, src, dst)
    return H, src, dst, truth, keys, est


def _fraction(i):
    return slice(i * FRAMES, (i + 1) * FRAMES)


def _opencv(src, dst, method):
    H, mask = cv2.findHomography(src, dst, method, THRESHOLD)
    return H, mask.ravel().astype(bool)


@pytest.mark.parametrize("i", range(len(FRACTIONS)), ids=[f"{f:.0%}" for f in FRACTIONS])
def test_finds_the_outliers_and_the_homography(scenes, i):
    H_true, _, _, truth, _, est = scenes
    part = _fraction(i)
    assert np.all(_ok(est.result)[part])
    inl, truth = np.asarray(est.inliers[part]), truth[part]
    hits = np.sum(inl & truth, 1)
    # recall and precision of the inlier set against the truth, every frame
    assert np.all(hits / truth.sum(1) >= 0.98)
    assert np.all(hits / inl.sum(1) >= 0.98)
    H = np.asarray(est.H[part])
    np.testing.assert_array_equal(H[:, 2, 2], 1.0)
    # 0.5 px of noise on 36-60 points: the corners move by ~0.5 px (median; at most 1.2 px
    # over these 32 scenes)
    err = corner_error(H_true[part], H)
    assert np.max(err) < 2.0
    assert np.median(err) < 0.8


@pytest.mark.parametrize("method", [cv2.RANSAC, USAC], ids=["RANSAC", "USAC"])
@pytest.mark.parametrize("i", range(len(FRACTIONS)), ids=[f"{f:.0%}" for f in FRACTIONS])
def test_agrees_with_opencv(scenes, i, method):
    """The same inlier sets as `cv2.findHomography` (Jaccard overlap >= 0.95 per frame) and
    homography errors of the same order (within 1.5x plus 0.1 px of OpenCV's per frame)."""
    H_true, src, dst, _, _, est = scenes
    part = np.arange(len(src))[_fraction(i)]
    for j in part:
        H_cv, mask_cv = _opencv(src[j], dst[j], method)
        inl = np.asarray(est.inliers[j])
        assert np.sum(inl & mask_cv) / np.sum(inl | mask_cv) >= 0.95
        e_cv = corner_error(H_true[j], H_cv)
        e = corner_error(H_true[j], np.asarray(est.H[j]))
        assert e <= 1.5 * e_cv + 0.1


def test_samples_are_four_distinct_uniform_indices():
    """Each sample holds 4 distinct indices, each position uniform over the points."""
    n, count = 7, 20000
    idx = np.asarray(jax.jit(_samples, static_argnums=(1, 2))(jax.random.key(3), n, count))
    assert idx.shape == (count, 4)
    assert np.all((idx >= 0) & (idx < n))
    assert np.all(np.sort(idx, 1)[:, 1:] != np.sort(idx, 1)[:, :-1])
    for k in range(4):
        freq = np.bincount(idx[:, k], minlength=n) / count
        np.testing.assert_allclose(freq, 1.0 / n, atol=0.01)  # 4 standard deviations


def test_exact_correspondences_with_outliers():
    """No noise, 30% outliers: the homography to rounding, the inliers exactly, the
    convention of `cv2.findHomography` (`dst ~ H src`, `H[2, 2] = 1`)."""
    rng = np.random.default_rng(5)
    H_true, src, dst, truth = _scene(rng, 0.3, noise=0.0)
    est = robust_one(jax.random.key(0), src, dst)
    assert est.result == RESULTS.successful
    np.testing.assert_array_equal(np.asarray(est.inliers), truth)
    np.testing.assert_allclose(est.H, H_true, rtol=1e-9, atol=1e-12)
    # OpenCV's least squares on the true inliers (in float32 inside: to 1e-3 px)
    H_cv, _ = _opencv(src[truth], dst[truth], 0)
    assert corner_error(H_cv, np.asarray(est.H)) < 1e-3


def test_deterministic(scenes):
    _, src, dst, _, keys, _ = scenes
    j = 3 * FRAMES  # 40% outliers
    a = robust_one(keys[j], src[j], dst[j])
    b = robust_one(keys[j], src[j], dst[j])
    np.testing.assert_array_equal(a.H, b.H)
    np.testing.assert_array_equal(a.inliers, b.inliers)
    # another key draws other samples, but finds the same inliers and homography
    c = robust_one(jax.random.key(123), src[j], dst[j])
    np.testing.assert_array_equal(a.inliers, c.inliers)
    np.testing.assert_allclose(a.H, c.H, rtol=1e-9, atol=1e-12)


def test_vmap_over_frames_equals_a_loop(scenes):
    _, src, dst, _, keys, est = scenes
    for j in (0, FRAMES + 1, 3 * FRAMES + 2):
        one = robust_one(keys[j], src[j], dst[j])
        np.testing.assert_allclose(est.H[j], one.H, rtol=1e-10, atol=1e-12)
        np.testing.assert_array_equal(est.inliers[j], one.inliers)
        assert result_names(est.result)[j] == result_names(one.result)


def test_throw_and_result_codes(scenes):
    _, src, dst, _, keys, est = scenes
    j = 2 * FRAMES
    # throw=True (the default) succeeds with the same answer, and is a RobustHomography
    out = find_homography_robust(keys[j], src[j], dst[j], iterations=ITERATIONS)
    assert isinstance(out, RobustHomography)
    assert out.result == RESULTS.successful
    np.testing.assert_allclose(out.H, est.H[j], rtol=1e-10, atol=1e-12)

    # all points on one line: no hypothesis that is not degenerate
    t = np.linspace(0.0, 1.0, N)
    line = np.stack([100.0 + 400.0 * t, 50.0 + 300.0 * t], 1)
    bad_nan = dst[j].copy()
    bad_nan[5, 1] = np.nan
    cases = [
        (line, dst[j], "degenerate_points", "collinear"),
        (src[j], bad_nan, "nonfinite_pixels", "not finite"),
    ]
    for s, d, name, message in cases:
        r = robust_one(keys[j], s, d)
        assert result_names(r.result) == name
        assert np.all(np.isnan(np.asarray(r.H)))
        assert not np.any(np.asarray(r.inliers))
        with pytest.raises(eqx.EquinoxRuntimeError, match=message):
            find_homography_robust(keys[j], s, d, iterations=ITERATIONS)

    # under vmap, each frame its own code
    batch = robust_batch(
        keys[:3], np.stack([src[j], line, src[j]]), np.stack([dst[j], dst[j], bad_nan])
    )
    assert result_names(batch.result) == ["successful", "degenerate_points", "nonfinite_pixels"]
    np.testing.assert_allclose(batch.H[0], est.H[j], rtol=1e-10, atol=1e-12)

    # a traced threshold, vmapped: one that is not positive leaves no consensus
    def with_threshold(t):
        r = find_homography_robust(
            keys[j], src[j], dst[j], iterations=ITERATIONS, threshold_px=t, throw=False
        )
        return r.result, jnp.sum(r.inliers)

    codes, counts = jax.jit(jax.vmap(with_threshold))(jnp.array([THRESHOLD, 0.0]))
    assert result_names(codes) == ["successful", "too_few_inliers"]
    assert int(counts[0]) > N // 2 and int(counts[1]) == 0


@pytest.mark.slow  # the unit tier's time: 9 s of compiles
def test_gradient_against_finite_differences(scenes):
    """`jax.grad` through the refinement (the inlier set fixed: it does not change over
    the finite-difference steps) against a central difference along a random direction."""
    _, src, dst, _, keys, _ = scenes
    j = FRAMES + 2  # 10% outliers
    key = keys[j]
    C = np.random.default_rng(1).standard_normal((3, 3))

    def loss(s, d):
        return jnp.sum(C * _robust(key, s, d).H)

    g_src, g_dst = jax.jit(jax.grad(loss, argnums=(0, 1)))(src[j], dst[j])
    rng = np.random.default_rng(2)
    h = 1e-3  # px
    for which, g in ((0, g_src), (1, g_dst)):
        v = rng.standard_normal((N, 2))
        args_p, args_m = [src[j], dst[j]], [src[j], dst[j]]
        args_p[which] = args_p[which] + h * v
        args_m[which] = args_m[which] - h * v
        plus, minus = robust_one(key, *args_p), robust_one(key, *args_m)
        np.testing.assert_array_equal(plus.inliers, minus.inliers)
        fd = (np.sum(C * np.asarray(plus.H)) - np.sum(C * np.asarray(minus.H))) / (2 * h)
        np.testing.assert_allclose(np.sum(np.asarray(g) * v), fd, rtol=1e-6)
        assert np.all(np.isfinite(np.asarray(g)))


def test_bad_input_names_the_argument(no_jaxtyping, scenes):
    _, src, dst, _, keys, _ = scenes
    key = keys[0]
    s, d = src[0], dst[0]
    cases = [
        ((key, s[:3], d[:3]), {}, "`src` has 3 points"),
        ((key, s[:, :1], d), {}, "`src` must be"),
        ((key, s, d[:, :1]), {}, "`dst` must be"),
        ((key, s, d[:-1]), {}, "`src` and `dst`"),
        ((keys[:2], s, d), {}, "`key`"),
        ((key, s, d), {"iterations": 0}, "`iterations`"),
        ((key, s, d), {"iterations": 10.0}, "`iterations`"),
        ((key, s, d), {"threshold_px": -1.0}, "`threshold_px` must be positive"),
        ((key, s, d), {"threshold_px": np.ones(2)}, "`threshold_px` must be a scalar"),
    ]
    for args, kwargs, match in cases:
        with pytest.raises(ValueError, match=match):
            find_homography_robust(*args, **kwargs)


@pytest.mark.slow  # a 200-seed Monte Carlo (4 s): the unit tier's budget
def test_covariance_predicts_the_spread_over_noise_seeds():
    """`cov` (the inliers' transfer errors, $\\hat\\sigma^2 (J^TJ)^{-1}$) against the spread
    of the eight entries of `H` over 200 noise seeds at 0.5 px, with 10% outliers: each
    predicted standard deviation within 20% of the Monte-Carlo one."""
    rng = np.random.default_rng(11)
    H, src, dst0, truth = _scene(rng, 0.1, noise=0.0)
    seeds = 200
    dst = np.repeat(dst0[None], seeds, 0)
    dst[:, truth] += 0.5 * rng.standard_normal((seeds, int(truth.sum()), 2))
    keys = jax.random.split(jax.random.key(3), seeds)
    est = robust_batch(keys, np.repeat(src[None], seeds, 0), dst)
    assert np.all(_ok(est.result))
    h = np.asarray(est.H).reshape(seeds, 9)[:, :8]
    mc = np.std(h, axis=0, ddof=1)
    predicted = np.sqrt(np.median(np.diagonal(np.asarray(est.cov), axis1=1, axis2=2), 0))
    np.testing.assert_allclose(predicted / mc, 1.0, atol=0.2)
    assert np.all(np.isfinite(est.cov))


def test_opencv_ransac_under_vmap_takes_each_threshold(scenes):
    """`baselines.ransac_homographies` (OpenCV's RANSAC through a callback) under `vmap`
    over noise draws with an unbatched threshold, and over thresholds: each batch member's
    homographies are OpenCV's at its own threshold (an unbatched threshold once reached
    the callback as an array and failed)."""
    from visjax.baselines import ransac_homographies

    H, src, dst, *_ = scenes
    ref, frames = src[0], np.stack([_apply(H[i], src[0]) for i in range(3)])
    draws = np.stack([frames, frames + 0.3])
    G = jax.vmap(lambda p: ransac_homographies(ref, p, threshold_px=3.0))(draws)
    for d in range(2):
        for k in range(3):
            expect, _ = cv2.findHomography(ref, draws[d, k], cv2.RANSAC, 3.0)
            np.testing.assert_allclose(G[d, k], expect / expect[2, 2], rtol=1e-6, atol=1e-9)
    thresholds = jnp.array([1.0, 5.0])
    G = jax.vmap(lambda t: ransac_homographies(ref, frames, threshold_px=t))(thresholds)
    for i, t in enumerate((1.0, 5.0)):
        expect, _ = cv2.findHomography(ref, frames[0], cv2.RANSAC, t)
        np.testing.assert_allclose(G[i, 0], expect / expect[2, 2], rtol=1e-6, atol=1e-9)
