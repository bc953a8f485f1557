"""Nath, Dawson, Tatlicioglu, *Euclidean position estimation of static features using a
moving uncalibrated camera*: how the adaptive LS estimator converges over a long noise-free
run. Prints JSON.

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

from visjax.estimators import SaveAt, run  # noqa: E402
from visjax.papers import nath  # noqa: E402


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--duration", type=float, default=90.0)
    args = parser.parse_args()
    sc = nath.scenario(args.duration)
    stream = nath.stream(sc)
    t0 = time.perf_counter()
    sol = run(nath.initial_estimator(sc), stream, saveat=SaveAt(every=1000, diagnostics=True))
    jax.block_until_ready((sol.outputs, sol.diagnostics))
    wall = time.perf_counter() - t0
    pc = np.asarray(sol.diagnostics.p_tilde_c).max(1)
    err = np.linalg.norm(
        np.asarray(sol.outputs.omega_s) - np.asarray(sc.omega_s)[None], axis=-1
    ).max(1)
    times = [t for t in (0, 5, 10, 20, 30, 45, 60, 75, 89, 120, 179) if t < len(pc)]
    print(
        json.dumps(
            {
                "benchmark": "seed004_adaptive_ls_convergence",
                "duration_s": args.duration,
                "rate_hz": 1000,
                "gains": nath.DEFAULT_GAINS,
                "camera_prediction_error_px": {str(t): round(float(pc[t]), 4) for t in times},
                "max_position_error_mm": {str(t): round(float(err[t]) * 1000, 3) for t in times},
                "covariance_resets": int(sol.diagnostics.resets[-1]),
                "wall_s_including_compile": round(wall, 2),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
