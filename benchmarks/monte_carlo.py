"""The users' main workload: a Monte-Carlo noise study of the velocity estimator of
Chitrakaran, Dawson, Dixon, Chen, *Identification of a moving object's velocity with a
fixed camera*, with noise per trajectory, so that the homography, its decomposition, e,
J and J^-1 are recomputed from each trajectory's noisy pixels. Prints JSON.

The run of one trajectory is `papers.velocity_problem(noise_px=0.1)`'s estimator (the section-6
simulation at 1 kHz, the published gains of eq. (63), the windowed RMS reduced in the loop,
nothing saved per step): Gaussian noise drawn for the trajectory's pixels, the stream
(`fixed_camera`, `velocity_stream`: its preprocessing fused with the time loop, `chunk` frames at a
time), the estimator's loop. `jit(vmap)` over `--batch` noise keys.

References timed in the same run, on the same trajectories:

- `numpy_loop`: the per-step NumPy transcription of the paper
  (`tests/reference_velocity.py`, no noise), one trajectory: ns per step.
- `loop_only`: the estimator's loop alone on a prepared, shared measurement stream,
  vmapped over `--batch` gain settings: ns per trajectory-step (what the loop itself
  costs, without the per-trajectory reconstruction).
- `noise_only`: drawing the noise for the batch.
- `measure_only`: the per-frame reconstruction, e, J, J^-1 alone (`stream.measure`),
  `jit(vmap)` over `--batch` x `--chunk` noisy frames at once (what one fused chunk
  prepares), in ns per frame, with XLA's count of the kernels it compiles to and of the
  bytes they move per frame (`cost_analysis`).
- `parts_ns_per_trajectory_step`: noise + measurement + loop, each timed alone at its
  best: what the study would cost if the runner added nothing (a lower bound for this
  code on this machine).

The study is timed twice: with JAX's default random-number generator (threefry, counter
based, the same noise on every backend) and with `impl="rbg"` keys (XLA's own generator,
cheaper on a CPU; the noise differs, its distribution does not). A study's noise
generator is the user's choice: `jax.random.key(seed, impl="rbg")`.

    python benchmarks/monte_carlo.py [--batch 1024] [--duration 1.0] [--chunk 16]
        [--dtype float64|float32]

The JSON records the device and the dtype (`_device.device_fields`).
"""

import argparse
import json
import pathlib
import platform
import re
import statistics
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))  # the tests' helpers

from _device import add_dtype_option, device_fields, use_dtype  # noqa: E402

import visjax  # noqa: E402
from tests.reference_velocity import numpy_velocity_estimator  # noqa: E402
from visjax import papers  # noqa: E402
from visjax.estimators import (  # noqa: E402
    FixedCamera,
    SaveAt,
    VelocityEstimator,
    WindowRMS,
    fixed_camera,
    run,
    velocity_stream,
)
from visjax.papers.chitrakaran import K_EQ63, RHO_EQ63, section6_scenario  # noqa: E402

# the operations of a compiled program that run as kernels of their own on a CPU
KERNEL_OPS = {"fusion", "copy", "concatenate", "custom-call", "dynamic-slice", "reduce",
              "dynamic-update-slice", "transpose", "select", "add", "multiply", "divide",
              "subtract", "sqrt", "conditional", "while", "sort", "gather", "scatter"}  # fmt: skip


def timed(f, *args, repeats):
    t0 = time.perf_counter()
    jax.block_until_ready(f(*args))
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(f(*args))
        times.append(time.perf_counter() - t0)
    return first, statistics.median(times)


def raw_study(duration, chunk):
    """The study written directly on the estimator and stream builders (no problem, no
    runner around it): `jit(vmap(one))` over noise keys, and what the references reuse."""
    sc = section6_scenario(duration, 1000.0)
    camera = fixed_camera(sc.pixels, sc.A, sc.R_star, sc.s[0])
    stream0 = velocity_stream(sc.ts, sc.pixels, camera)
    n_star, z1_star = camera.n_star, camera.z1_star
    reducer = WindowRMS(0.5 * duration, duration + 1e-9, field="v_hat")
    est = VelocityEstimator(K=K_EQ63, rho=RHO_EQ63)

    def one(key):
        noise = 0.1 * jax.random.normal(key, sc.pixels.shape, dtype=sc.pixels.dtype)
        pixels = sc.pixels + noise
        camera = FixedCamera(pixels[0], sc.A, sc.R_star, sc.s[0], n_star, z1_star)
        stream = velocity_stream(sc.ts, pixels, camera, truth=sc.velocity, throw=False, chunk=chunk)
        sol = run(est, stream, saveat=SaveAt(outputs=False), reducer=reducer, throw=False)
        return sol.summary.rms, sol.result._value

    return jax.jit(jax.vmap(one)), stream0, n_star, z1_star, reducer


def main():
    visjax.apply_xla_cpu_workarounds()  # as the command line does (jaxlib 0.10's CPU options)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=1024)
    parser.add_argument("--duration", type=float, default=1.0, help="seconds at 1 kHz")
    parser.add_argument(
        "--chunk", type=int, default=16, help="frames per fused chunk (16: fastest at batch 1,024)"
    )
    parser.add_argument("--repeats", type=int, default=3)
    add_dtype_option(parser)
    args = parser.parse_args()

    use_dtype(args.dtype)
    sc = section6_scenario(args.duration, 1000.0)
    steps = sc.ts.shape[0]
    setup = papers.velocity_problem(noise_px=0.1, duration=args.duration, chunk=args.chunk)
    keys = jax.random.split(jax.random.key(0), args.batch)
    study, stream0, n_star, z1_star, reducer = raw_study(args.duration, args.chunk)
    study_first, study_s = timed(study, keys, repeats=args.repeats)
    rms, codes = study(keys)
    failed = int(np.sum(np.asarray(codes) != 0))
    keys_rbg = jax.random.split(jax.random.key(0, impl="rbg"), args.batch)
    _, study_rbg_s = timed(study, keys_rbg, repeats=args.repeats)
    rms_rbg, codes_rbg = study(keys_rbg)
    failed += int(np.sum(np.asarray(codes_rbg) != 0))

    # the same through the library's problem (papers.velocity_problem), for reference
    params = setup.resolve()
    factory = jax.jit(
        jax.vmap(lambda k: setup.solve("estimator", params, setup.inputs(k)).summary.rms)
    )
    _, factory_s = timed(factory, keys, repeats=args.repeats)

    noise = jax.jit(
        jax.vmap(lambda k: 0.1 * jax.random.normal(k, sc.pixels.shape, dtype=sc.pixels.dtype))
    )
    _, noise_s = timed(noise, keys, repeats=args.repeats)
    _, noise_rbg_s = timed(noise, keys_rbg, repeats=args.repeats)

    frames = args.batch * min(args.chunk, steps)
    noisy = jnp.resize(sc.pixels, (frames,) + sc.pixels.shape[1:])
    noisy = noisy + 0.1 * jax.random.normal(jax.random.key(2), noisy.shape, noisy.dtype)
    measure = jax.jit(jax.vmap(stream0.measure))
    _, measure_s = timed(measure, noisy, repeats=args.repeats)
    compiled = measure.lower(noisy).compile()
    cost = compiled.cost_analysis()
    cost = cost[0] if isinstance(cost, list) else cost
    entry = compiled.as_text().split("\nENTRY", 1)[1]
    ops = re.findall(r"^\s*\S+ = (?:\([^)]*\)|\S+) ([\w-]+)\(", entry, re.MULTILINE)
    kernels = sum(op in KERNEL_OPS for op in ops)

    prepared = stream0.measured()
    prepared = type(prepared)(ts=prepared.ts, ys=prepared.ys, truth=sc.velocity)
    Ks = jnp.asarray(K_EQ63) * jnp.exp(0.1 * jax.random.normal(jax.random.key(1), (args.batch, 6)))

    def loop(K):
        sol = run(
            VelocityEstimator(K=K, rho=RHO_EQ63), prepared, saveat=SaveAt(outputs=False),
            reducer=reducer, throw=False,
        )  # fmt: skip
        return sol.summary.rms

    _, loop_s = timed(jax.jit(jax.vmap(loop)), Ks, repeats=args.repeats)

    t0 = time.perf_counter()
    numpy_velocity_estimator(
        np.asarray(sc.pixels), np.asarray(sc.A), np.asarray(sc.R_star), np.asarray(sc.s[0]),
        float(z1_star), np.asarray(n_star), np.asarray(K_EQ63), np.asarray(RHO_EQ63), 1e-3,
    )  # fmt: skip
    numpy_s = time.perf_counter() - t0

    per = 1e9 / (args.batch * steps)
    ns = study_s * per
    measure_ns = 1e9 * measure_s / frames
    print(
        json.dumps(
            {
                "benchmark": "monte_carlo_velocity_noise_study",
                "machine": platform.processor() or platform.machine(),
                "jax": jax.__version__,
                **device_fields(args.dtype),
                "batch": args.batch,
                "steps_per_trajectory": steps,
                "chunk": args.chunk,
                "failed_runs": failed,
                "median_rms_worst": float(np.median(np.max(np.asarray(rms), axis=-1))),
                "study_s": study_s,
                "study_compile_s": study_first - study_s,
                "ns_per_trajectory_step": ns,
                "ns_per_trajectory_step_rbg": study_rbg_s * per,
                "median_rms_worst_rbg": float(np.median(np.max(np.asarray(rms_rbg), axis=-1))),
                "factory_ns_per_trajectory_step": factory_s * per,
                "noise_only_ns_per_trajectory_step": noise_s * per,
                "noise_only_rbg_ns_per_trajectory_step": noise_rbg_s * per,
                "loop_only_ns_per_trajectory_step": loop_s * per,
                "measure_only_ns_per_frame": measure_ns,
                "measure_frames": frames,
                "measure_kernels": kernels,
                "measure_bytes_per_frame": float(cost.get("bytes accessed", np.nan)) / frames,
                "measure_flops_per_frame": float(cost.get("flops", np.nan)) / frames,
                "parts_ns_per_trajectory_step": noise_s * per + measure_ns + loop_s * per,
                "numpy_loop_ns_per_step": 1e9 * numpy_s / steps,
                "speedup_vs_numpy_loop": 1e9 * numpy_s / steps / ns,
                "target": {"ns_per_trajectory_step": "<= 300 at batch 1024"},
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
