"""Homography + decomposition per frame: visjax vmapped vs an OpenCV per-frame loop.

Prints JSON. For each of N frames (default 10,000): the normalized DLT homography from 4
point correspondences and its four-solution Euclidean decomposition. visjax runs one
`jit(vmap(...))` call over all frames (compile time reported apart); OpenCV runs
`cv2.findHomography(method=0)` and `cv2.decomposeHomographyMat` in a Python loop, in the
same process, on the same data, in interleaved rounds (`--repeats` of them: ten visjax
calls and one OpenCV loop each); the best time of each.

    python benchmarks/homography_decomposition.py [--frames 10000] [--repeats 5]
"""

import argparse
import json
import platform
import time

import cv2
import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import visjax  # noqa: E402
from visjax.geometry import decompose_homography, find_homography  # noqa: E402
from visjax.sim import random_planar_scenes  # noqa: E402


def per_frame(p_ref, p_cur, A):
    G = find_homography(p_ref, p_cur).G
    return G, decompose_homography(G, A)


def main():
    visjax.apply_xla_cpu_workarounds()  # as the command line does (jaxlib 0.10's CPU options)
    parser = argparse.ArgumentParser()
    parser.add_argument("--frames", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()

    sc = random_planar_scenes(args.frames, 4, seed=0)
    f = jax.jit(jax.vmap(per_frame))

    t0 = time.perf_counter()
    jax.block_until_ready(f(sc.p_ref, sc.p_cur, sc.A))
    compile_s = time.perf_counter() - t0
    # interleaved rounds (each: 10 visjax calls, one OpenCV loop), so that both see the
    # same machine; the best time of each
    visjax_s, opencv_s = [], []
    for _ in range(args.repeats):
        for _ in range(10):
            t0 = time.perf_counter()
            G, (R, t, n) = jax.block_until_ready(f(sc.p_ref, sc.p_cur, sc.A))
            visjax_s.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        for i in range(args.frames):
            Gc, _ = cv2.findHomography(sc.p_ref[i], sc.p_cur[i], 0)
            cv2.decomposeHomographyMat(Gc, sc.A[i])
        opencv_s.append(time.perf_counter() - t0)

    err = np.max(
        np.abs(np.asarray(G) - sc.G_n) / np.max(np.abs(sc.G_n), axis=(1, 2), keepdims=True)
    )
    best_v, best_c = min(visjax_s), min(opencv_s)
    print(
        json.dumps(
            {
                "benchmark": "homography_plus_decomposition_per_frame",
                "frames": args.frames,
                "points_per_frame": 4,
                "dtype": "float64",
                "machine": f"{platform.machine()}, {jax.devices()[0].platform}",
                "jax": jax.__version__,
                "opencv": cv2.__version__,
                "visjax_compile_s": round(compile_s, 3),
                "visjax_s": round(best_v, 5),
                "opencv_loop_s": round(best_c, 5),
                "visjax_us_per_frame": round(best_v / args.frames * 1e6, 3),
                "opencv_us_per_frame": round(best_c / args.frames * 1e6, 3),
                "speedup_opencv_over_visjax": round(best_c / best_v, 2),
                "visjax_max_rel_error_G": float(err),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
