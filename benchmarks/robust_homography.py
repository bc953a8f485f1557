"""The homography from correspondences with outliers: visjax's `find_homography_robust`
(one `jit(vmap(...))` call over all frames) against `cv2.findHomography` with RANSAC and
with USAC (`USAC_DEFAULT` and `USAC_MAGSAC`) in a Python loop, on the same data, in the
same process. Prints JSON.

The scenes: per frame a random homography (the corners of a 640 x 480 image moved by up to
100 px), `--points` points uniform in the image, 0.5 px of Gaussian noise on the inliers,
the outliers' `dst` uniform in the image, at each outlier fraction of `--fractions`. All
methods get the same threshold (`--threshold`, px, the forward transfer error); visjax
draws a fixed `--iterations` hypotheses, OpenCV stops adaptively (confidence 0.995, at most
2000 iterations, its defaults).

Reported per fraction and method: the inlier sets' precision and recall against the truth
(mean and worst frame), the homography error (the largest distance, px, between the images
of the image's corners under the true and the estimated homography: median, 95th
percentile, max), the frames that failed, and the time per frame: the best of `--repeats`
rounds, each one visjax call (after compilation, reported apart) and one loop of each
OpenCV method; `opencv_over_visjax` is OpenCV's time per frame over visjax's, measured in
the same run.

    python benchmarks/robust_homography.py [--frames 200] [--points 100] [--iterations 500]
"""

import argparse
import json
import platform
import time

import cv2
import jax
import numpy as np

import visjax

WIDTH, HEIGHT = 640.0, 480.0
CORNERS = np.array([[0.0, 0.0], [WIDTH, 0.0], [WIDTH, HEIGHT], [0.0, HEIGHT]])


def four_point_homography(a, b):
    rows, rhs = [], []
    for (u, v), (x, y) in zip(a, b):
        rows += [[u, v, 1, 0, 0, 0, -x * u, -x * v], [0, 0, 0, u, v, 1, -y * u, -y * v]]
        rhs += [x, y]
    return np.append(np.linalg.solve(np.array(rows), np.array(rhs)), 1.0).reshape(3, 3)


def apply(H, p):
    q = np.einsum("...ij,...nj->...ni", H, np.concatenate([p, np.ones_like(p[..., :1])], -1))
    return q[..., :2] / q[..., 2:]


def scenes(rng, frames, n, outlier_fraction, noise=0.5):
    Hs, srcs, dsts, truths = [], [], [], []
    for _ in range(frames):
        H = four_point_homography(CORNERS, CORNERS + rng.uniform(-100.0, 100.0, (4, 2)))
        src = rng.uniform([0.0, 0.0], [WIDTH, HEIGHT], (n, 2))
        dst = apply(H, src) + noise * rng.standard_normal((n, 2))
        k = int(round(outlier_fraction * n))
        out = rng.permutation(n)[:k]
        dst[out] = rng.uniform([0.0, 0.0], [WIDTH, HEIGHT], (k, 2))
        truth = np.ones(n, bool)
        truth[out] = False
        Hs.append(H), srcs.append(src), dsts.append(dst), truths.append(truth)
    return np.stack(Hs), np.stack(srcs), np.stack(dsts), np.stack(truths)


def quality(H_true, H, inliers, truth, ok):
    """Precision, recall and corner error over the frames that succeeded."""
    hits = np.sum(inliers & truth, 1)
    precision = hits / np.maximum(inliers.sum(1), 1)
    recall = hits / truth.sum(1)
    err = np.max(np.linalg.norm(apply(H_true, CORNERS) - apply(H, CORNERS), axis=-1), -1)
    p, r, e = precision[ok], recall[ok], err[ok]
    return {
        "failed_frames": int(np.sum(~ok)),
        "precision_mean": float(np.mean(p)),
        "precision_min": float(np.min(p)),
        "recall_mean": float(np.mean(r)),
        "recall_min": float(np.min(r)),
        "corner_error_px_median": float(np.median(e)),
        "corner_error_px_p95": float(np.percentile(e, 95)),
        "corner_error_px_max": float(np.max(e)),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--points", type=int, default=100)
    parser.add_argument("--iterations", type=int, default=500)
    parser.add_argument("--threshold", type=float, default=3.0)
    parser.add_argument("--fractions", type=float, nargs="+", default=[0.0, 0.1, 0.2, 0.4])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    visjax.apply_xla_cpu_workarounds()
    jax.config.update("jax_enable_x64", True)
    from visjax import RESULTS
    from visjax.geometry import find_homography_robust

    robust = jax.jit(
        jax.vmap(
            lambda k, s, d: find_homography_robust(
                k, s, d, iterations=args.iterations, threshold_px=args.threshold, throw=False
            )
        )
    )
    methods = {"opencv_ransac": cv2.RANSAC, "opencv_usac_default": cv2.USAC_DEFAULT}
    if hasattr(cv2, "USAC_MAGSAC"):
        methods["opencv_usac_magsac"] = cv2.USAC_MAGSAC

    def opencv(method, src, dst):
        return [cv2.findHomography(s, d, method, args.threshold) for s, d in zip(src, dst)]

    keys = jax.random.split(jax.random.key(0), args.frames)
    compile_s = None
    rows = []
    for i, fraction in enumerate(args.fractions):
        H_true, src, dst, truth = scenes(
            np.random.default_rng(100 + i), args.frames, args.points, fraction
        )
        if compile_s is None:
            t0 = time.perf_counter()
            robust = robust.lower(keys, src, dst).compile()
            compile_s = time.perf_counter() - t0
        times = {name: [] for name in ["visjax", *methods]}
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            est = jax.block_until_ready(robust(keys, src, dst))
            times["visjax"].append(time.perf_counter() - t0)
            cv_out = {}
            for name, method in methods.items():
                t0 = time.perf_counter()
                cv_out[name] = opencv(method, src, dst)
                times[name].append(time.perf_counter() - t0)
        us = {name: 1e6 * min(t) / args.frames for name, t in times.items()}

        ok = np.asarray(est.result._value) == int(RESULTS.successful._value)
        row = {
            "outlier_fraction": fraction,
            "visjax": {
                **quality(H_true, np.asarray(est.H), np.asarray(est.inliers), truth, ok),
                "us_per_frame": us["visjax"],
            },
        }
        for name, out in cv_out.items():
            ok_cv = np.array([H is not None for H, _ in out])
            H_cv = np.stack([H if H is not None else np.eye(3) for H, _ in out])
            m_cv = np.stack(
                [m.ravel().astype(bool) if m is not None else np.zeros(args.points, bool)
                 for _, m in out]
            )  # fmt: skip
            both = ok & ok_cv
            inl = np.asarray(est.inliers)
            jaccard = np.sum(inl & m_cv, 1)[both] / np.maximum(np.sum(inl | m_cv, 1)[both], 1)
            row[name] = {
                **quality(H_true, H_cv, m_cv, truth, ok_cv),
                "us_per_frame": us[name],
                "opencv_over_visjax": us[name] / us["visjax"],
                "inlier_jaccard_with_visjax_mean": float(np.mean(jaccard)),
                "inlier_jaccard_with_visjax_min": float(np.min(jaccard)),
            }
        rows.append(row)

    print(
        json.dumps(
            {
                "benchmark": "robust_homography",
                "machine": platform.machine(),
                "jax": jax.__version__,
                "opencv": cv2.__version__,
                "dtype": "float64",
                "frames": args.frames,
                "points": args.points,
                "visjax_iterations": args.iterations,
                "threshold_px": args.threshold,
                "visjax_compile_s": compile_s,
                "fractions": rows,
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
