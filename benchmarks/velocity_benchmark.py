"""The velocity estimator of Chitrakaran, Dawson, Dixon, Chen, *Identification of a moving
object's velocity with a fixed camera*: visjax against a per-step NumPy loop, and a batch of
gains.

Prints JSON. The paper's section-6 scenario, 10 s at 1 kHz (10,000 samples):

- `numpy_loop_s`: `tests.reference_velocity.numpy_velocity_estimator`, the estimator written
  per step from the paper (homography, decomposition, e, J, Euler step) in NumPy (best of
  `--numpy-repeats` runs, interleaved with the visjax rounds).
- `visjax_one_s`: the same with visjax after compilation, as a user runs one long
  trajectory: `velocity_stream(..., chunk=--chunk)` (the per-frame reconstruction, e,
  J^-1, fused with the loop in chunks of that many frames: the default 10,000 is the whole
  run, 7 MB of prepared frames) and `run(..., unroll=--unroll)` (8 steps per iteration of
  the compiled loop). `visjax_one_default_s`: with the defaults of both (chunks of 256
  frames, `unroll=1`), the settings for batches. `visjax_one_prepared_s`: with every
  frame's measurements prepared first (vmapped over all frames), then the loop.
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
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))  # the tests' helpers

import visjax  # noqa: E402
from tests.reference_velocity import numpy_velocity_estimator  # noqa: E402
from visjax.estimators import (  # noqa: E402
    FixedCamera,
    SaveAt,
    Stream,
    VelocityEstimator,
    WindowRMS,
    run,
    velocity_measurements,
    velocity_stream,
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
    visjax.apply_xla_cpu_workarounds()  # as the command line does (jaxlib 0.10's CPU options)
    parser = argparse.ArgumentParser()
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--chunk", type=int, default=10000, help="frames per fused chunk")
    parser.add_argument("--unroll", type=int, default=8, help="steps per loop iteration")
    parser.add_argument("--numpy-repeats", type=int, default=3)
    args = parser.parse_args()

    sc = section6_scenario(10.0, 1000.0)
    n = sc.ts.shape[0]
    K, rho = jnp.array(K_EQ63), jnp.array(RHO_EQ63)

    def numpy_run():
        return numpy_velocity_estimator(
            np.asarray(sc.pixels), np.asarray(sc.A), np.asarray(sc.R_star),
            np.asarray(sc.s[0]), float(sc.z1_star), np.asarray(sc.n_star), np.asarray(K),
            np.asarray(rho), 1e-3,
        )  # fmt: skip

    @jax.jit
    def one_prepared(pixels, K, rho):
        ys = jax.vmap(
            lambda pc: velocity_measurements(
                FixedCamera(pixels[0], sc.A, sc.R_star, sc.s[0], sc.n_star, sc.z1_star), pc
            )
        )(pixels)
        return run(VelocityEstimator(K=K, rho=rho), Stream(ts=sc.ts, ys=ys)).outputs.v_hat

    def one_with(chunk, unroll):
        @jax.jit
        def one(pixels, K, rho):
            # the users' path: the stream's preprocessing fused with the loop, in chunks
            camera = FixedCamera(pixels[0], sc.A, sc.R_star, sc.s[0], sc.n_star, sc.z1_star)
            stream = velocity_stream(sc.ts, pixels, camera, throw=False, **chunk)
            return run(VelocityEstimator(K=K, rho=rho), stream, **unroll).outputs.v_hat

        return one

    one = one_with({"chunk": args.chunk}, {"unroll": args.unroll})
    one_default = one_with({}, {})
    # rounds of (NumPy once, each visjax variant best of --repeats): the machine's speed
    # drifts, so the references are timed in the same stretch of time
    numpy_s, one_s, default_s, prepared_s = np.inf, np.inf, np.inf, np.inf
    compiles = []
    for _ in range(args.numpy_repeats):
        t0 = time.perf_counter()
        v_np = numpy_run()
        numpy_s = min(numpy_s, time.perf_counter() - t0)
        v_jax, c1, s1 = timed(one, sc.pixels, K, rho, repeats=args.repeats)
        _, c2, s2 = timed(one_default, sc.pixels, K, rho, repeats=args.repeats)
        _, c3, s3 = timed(one_prepared, sc.pixels, K, rho, repeats=args.repeats)
        one_s, default_s, prepared_s = min(one_s, s1), min(default_s, s2), min(prepared_s, s3)
        compiles = compiles or [c1, c2, c3]  # the first round's first calls compile
    one_compile, default_compile, prepared_compile = compiles

    ys = jax.vmap(
        lambda pc: velocity_measurements(
            FixedCamera(sc.pixels[0], sc.A, sc.R_star, sc.s[0], sc.n_star, sc.z1_star), pc
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
                "unroll": args.unroll,
                "visjax_one_default_s": round(default_s, 5),
                "visjax_one_default_compile_s": round(default_compile, 2),
                "speedup_one_default_vs_numpy": round(numpy_s / default_s, 1),
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
