"""Where a sweep's time goes when it is spread out: the velocity problem of Chitrakaran et
al. (a Monte-Carlo noise study, `papers.velocity_problem`, per-trajectory reconstruction)
swept over `--runs` runs in chunks of `--chunk`, timed in one process against the same
sweep's chunks as Ray tasks on one and on two workers of a local Ray instance, and the
per-chunk cost of writing each chunk's rows as a Parquet part (`parts=`). Prints JSON.

Reported: runs per second after compilation (the median of `--repeats` sweeps) for each;
their ratio against the single-process sweep measured in the same run; the first sweep
(compile-inclusive: each Ray worker compiles once); and the time one part takes to write
(the sweep with parts minus without, per chunk), beside a chunk's own time (a part costs
milliseconds: negligible against chunks of seconds, not against chunks of milliseconds).

    python benchmarks/sweep_scaling.py [--runs 512] [--chunk 64] [--duration 0.5]
"""

import argparse
import json
import os
import platform
import statistics
import tempfile
import time

import jax
import jax.numpy as jnp
import numpy as np

import visjax
from visjax import papers, studies


def timed(f, repeats):
    t0 = time.perf_counter()
    f()
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return first, statistics.median(times)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=512, help="noise seeds (one point)")
    parser.add_argument("--chunk", type=int, default=64, help="runs per chunk")
    parser.add_argument("--duration", type=float, default=0.5, help="seconds at 1 kHz")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    visjax.apply_xla_cpu_workarounds()
    jax.config.update("jax_enable_x64", True)

    problem = papers.velocity_problem(noise_px=0.1, duration=args.duration)
    params = {"K_scale": np.array([1.0])}
    keys = jnp.arange(args.runs)
    chunks = -(-args.runs // args.chunk)

    def sweep(**kw):
        study = studies.Study(chunk=args.chunk, **kw)
        return studies.sweep(problem, params, keys, study=study).to_pandas()

    reference = sweep()
    local_first, local_s = timed(sweep, args.repeats)

    def with_parts():
        with tempfile.TemporaryDirectory() as folder:
            sweep(parts=folder)

    _, parts_s = timed(with_parts, args.repeats)

    ray = {}
    import ray as ray_module

    for workers in (1, 2):
        executor = studies.RayExecutor(num_cpus=workers)
        try:
            first, wall = timed(lambda ex=executor: sweep(executor=ex), args.repeats)
            same = sweep(executor=executor).equals(reference)
        finally:
            executor.shutdown()
        ray[workers] = {
            "runs_per_s": args.runs / wall,
            "ratio_to_one_process": local_s / wall,
            "first_sweep_s": first,
            "table_equals_one_process": bool(same),
        }
    steps = int(round(args.duration * 1000)) + 1
    print(
        json.dumps(
            {
                "benchmark": "sweep_scaling_velocity",
                "machine": platform.machine(),
                "cpus": os.cpu_count(),
                "jax": jax.__version__,
                "ray": ray_module.__version__,
                "runs": args.runs,
                "chunk": args.chunk,
                "chunks": chunks,
                "steps_per_run": steps,
                "one_process": {
                    "runs_per_s": args.runs / local_s,
                    "first_sweep_s": local_first,
                    "ns_per_trajectory_step": 1e9 * local_s / (args.runs * steps),
                },
                "ray_1_worker": ray[1],
                "ray_2_workers": ray[2],
                "parts": {
                    "s_per_part": max(parts_s - local_s, 0.0) / chunks,
                    "chunk_s": local_s / chunks,
                    "overhead_fraction": max(parts_s - local_s, 0.0) / local_s,
                },
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
