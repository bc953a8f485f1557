"""Seed 004: how the adaptive LS estimator converges over a long noise-free run. Prints JSON.

The camera-parameter prediction error (max over known features, px) and the largest position
error of the unknown features (mm) at several times, plus wall time. Too long for the test
suite (which checks 20 s).

    python benchmarks/euclidean_convergence.py [--duration 90]
"""

import argparse
import json
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

from visjax.estimators import Stream, platform_measurements, run  # noqa: E402
from visjax.sim import uncalibrated_scenario  # noqa: E402
from visjax.studies import DEFAULT_GAINS, initial_estimator  # noqa: E402


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--duration", type=float, default=90.0)
    args = parser.parse_args()
    sc = uncalibrated_scenario(args.duration)
    ys = platform_measurements(sc.R_b, sc.x_b, sc.p_s, sc.p_c, sc.omega_c)
    t0 = time.perf_counter()
    sol = run(initial_estimator(sc), Stream(ts=sc.ts, ys=ys), save_every=1000)
    jax.block_until_ready(sol.outputs)
    wall = time.perf_counter() - t0
    pc = np.asarray(sol.outputs["p_tilde_c"]).max(1)
    err = np.linalg.norm(
        np.asarray(sol.outputs["omega_s"]) - np.asarray(sc.omega_s)[None], axis=-1
    ).max(1)
    times = [t for t in (0, 5, 10, 20, 30, 45, 60, 75, 89, 120, 179) if t < len(pc)]
    print(
        json.dumps(
            {
                "benchmark": "seed004_adaptive_ls_convergence",
                "duration_s": args.duration,
                "rate_hz": 1000,
                "gains": DEFAULT_GAINS,
                "camera_prediction_error_px": {str(t): round(float(pc[t]), 4) for t in times},
                "max_position_error_mm": {str(t): round(float(err[t]) * 1000, 3) for t in times},
                "covariance_resets": int(sol.outputs["resets"][-1]),
                "wall_s_including_compile": round(wall, 2),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
