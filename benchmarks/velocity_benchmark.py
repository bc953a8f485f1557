"""The velocity estimator of Chitrakaran, Dawson, Dixon, Chen, *Identification of a moving
object's velocity with a fixed camera*: visjax against a per-step NumPy loop, and a batch of
gains.

Prints JSON. The paper's section-6 scenario, 10 s at 1 kHz (10,000 samples):

- `numpy_loop_s`: `velocity_numpy_reference.numpy_velocity_estimator`, the estimator written
  per step from the paper (homography, decomposition, e, J, Euler step) in NumPy.
- `visjax_one_s`: the same with visjax after compilation, as a user runs it:
  `fixed_camera_stream` (the per-frame reconstruction, e, J^-1, fused with the loop in
  chunks of `--chunk` frames) and `run`. `visjax_one_prepared_s`: with every frame's
  measurements prepared first (vmapped over all frames), then the loop.
- `batch_*`: 256 gain settings vmapped over one shared measurement stream, the windowed RMS
  reduced in the loop (no per-sample saving): seconds and nanoseconds per trajectory-step.
Compile times are reported separately.

    python benchmarks/velocity_benchmark.py [--batch 256] [--repeats 5]
"""

import argparse
import json
import pathlib
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)
sys.path.insert(0, str(pathlib.Path(__file__).parent))

from velocity_numpy_reference import numpy_velocity_estimator  # noqa: E402

from visjax.estimators import (  # noqa: E402
    SaveAt,
    Stream,
    VelocityEstimator,
    WindowRMS,
    fixed_camera_stream,
    run,
    velocity_measurements,
)
from visjax.papers.chitrakaran import K_EQ63, RHO_EQ63, section6_scenario  # noqa: E402


def timed(f, *args, repeats):
    t0 = time.perf_counter()
    out = jax.block_until_ready(f(*args))
    first = time.perf_counter() - t0
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = jax.block_until_ready(f(*args))
        best = min(best, time.perf_counter() - t0)
    return out, first - best, best


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--chunk", type=int, default=1000, help="frames per fused chunk")
    args = parser.parse_args()

    sc = section6_scenario(10.0, 1000.0)
    n = sc.ts.shape[0]
    K, rho = jnp.array(K_EQ63), jnp.array(RHO_EQ63)

    t0 = time.perf_counter()
    v_np = numpy_velocity_estimator(
        np.asarray(sc.pixels),
        np.asarray(sc.A),
        np.asarray(sc.R_star),
        np.asarray(sc.s[0]),
        float(sc.z1_star),
        np.asarray(sc.n_star),
        np.asarray(K),
        np.asarray(rho),
        1e-3,
    )
    numpy_s = time.perf_counter() - t0

    @jax.jit
    def one_prepared(pixels, K, rho):
        ys = jax.vmap(
            lambda pc: velocity_measurements(
                pixels[0], pc, sc.A, sc.R_star, sc.s[0], sc.z1_star, sc.n_star
            )
        )(pixels)
        return run(VelocityEstimator(K=K, rho=rho), Stream(ts=sc.ts, ys=ys)).outputs.v_hat

    @jax.jit
    def one(pixels, K, rho):
        # the users' path: the stream's preprocessing fused with the loop, in chunks
        stream, _, _ = fixed_camera_stream(
            sc.ts, pixels, sc.A, sc.R_star, sc.s[0], n_star=sc.n_star, z1_star=sc.z1_star,
            throw=False, chunk=args.chunk,
        )  # fmt: skip
        return run(VelocityEstimator(K=K, rho=rho), stream).outputs.v_hat

    v_jax, one_compile, one_s = timed(one, sc.pixels, K, rho, repeats=args.repeats)
    _, prepared_compile, prepared_s = timed(one_prepared, sc.pixels, K, rho, repeats=args.repeats)

    ys = jax.vmap(
        lambda pc: velocity_measurements(
            sc.pixels[0], pc, sc.A, sc.R_star, sc.s[0], sc.z1_star, sc.n_star
        )
    )(sc.pixels)
    stream = Stream(ts=sc.ts, ys=ys, truth=sc.velocity)
    reducer = WindowRMS(5.0, 10.0, field="v_hat")
    Ks = K * jnp.exp(0.3 * jax.random.normal(jax.random.key(0), (args.batch, 6)))

    @jax.jit
    def batch(Ks):
        def rms(K):
            sol = run(
                VelocityEstimator(K=K, rho=rho),
                stream,
                saveat=SaveAt(outputs=False),
                reducer=reducer,
            )
            return sol.summary.rms

        return jax.vmap(rms)(Ks)

    _, batch_compile, batch_s = timed(batch, Ks, repeats=args.repeats)

    print(
        json.dumps(
            {
                "benchmark": "seed000_velocity_estimator",
                "samples": n,
                "rate_hz": 1000,
                "dtype": "float64",
                "jax": jax.__version__,
                "numpy_loop_s": round(numpy_s, 4),
                "visjax_one_s": round(one_s, 5),
                "visjax_one_compile_s": round(one_compile, 2),
                "speedup_one_vs_numpy": round(numpy_s / one_s, 1),
                "chunk": args.chunk,
                "visjax_one_prepared_s": round(prepared_s, 5),
                "speedup_one_prepared_vs_numpy": round(numpy_s / prepared_s, 1),
                "max_abs_diff_vs_numpy_first_0.5s": float(
                    np.max(np.abs(np.asarray(v_jax)[:500] - v_np[:500]))
                ),
                "batch": args.batch,
                "batch_s": round(batch_s, 4),
                "batch_compile_s": round(batch_compile, 2),
                "batch_ns_per_trajectory_step": round(batch_s / (args.batch * n) * 1e9, 1),
                "targets": {
                    "speedup_one_vs_numpy": ">= 150",
                    "batch_ns_per_trajectory_step": "<= 200",
                },
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
