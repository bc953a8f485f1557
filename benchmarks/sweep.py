"""Throughput of `visjax.studies.sweep` on the users' main workload: a Monte-Carlo noise
study of the velocity estimator of Chitrakaran et al. with per-trajectory pixel noise (the
homography, its decomposition and J recomputed from each trajectory's noisy pixels), at
batch 1, 64, 1,024 and 16,384 trajectories, each batch in its own process so that its peak
resident memory is its own.

Reported per batch: trajectory-steps per second after compilation (median of `--repeats`
timed sweeps), the compile-inclusive first sweep, the peak resident memory of the process
(`VmHWM`, see `_memory.py`), and the throughput as a ratio against batch 1 measured in the same run.
Prints JSON.

    python benchmarks/sweep.py [--duration 1.0] [--batches 1 64 1024 16384] [--chunk 1024]
"""

import argparse
import json
import pathlib
import subprocess
import sys

CHILD = r"""
import json, statistics, sys, time
sys.path.insert(0, sys.argv[5])
from _memory import peak_rss_mb
import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
import visjax
visjax.apply_xla_cpu_workarounds()
from visjax import papers, studies

batch, duration = int(sys.argv[1]), float(sys.argv[2])
chunk, repeats = int(sys.argv[3]), int(sys.argv[4])
setup = papers.velocity_problem(noise_px=0.1, duration=duration)
params = {"K_scale": np.array([0.01]), "rho_scale": np.array([0.1])}
keys = jnp.arange(batch)
t0 = time.perf_counter()
table = studies.sweep(setup, params, keys, study=studies.Study(chunk=chunk))
first = time.perf_counter() - t0
times = []
for _ in range(repeats):
    t0 = time.perf_counter()
    studies.sweep(setup, params, keys, study=studies.Study(chunk=chunk))
    times.append(time.perf_counter() - t0)
steps = int(round(duration * 1000)) + 1
wall = statistics.median(times)
print(json.dumps({
    "batch": batch,
    "steps_per_trajectory": steps,
    "chunk": min(chunk, batch),
    "wall_s": wall,
    "first_call_s": first,
    "trajectory_steps_per_s": batch * steps / wall,
    "ns_per_trajectory_step": 1e9 * wall / (batch * steps),
    "peak_rss_mb": peak_rss_mb(),
    "failed": int((table["result"] != "successful").sum()),
}))
"""


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=1.0, help="seconds at 1 kHz")
    parser.add_argument("--batches", type=int, nargs="*", default=[1, 64, 1024, 16384])
    parser.add_argument("--chunk", type=int, default=1024, help="runs per vmap call")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    rows = []
    for batch in args.batches:
        repeats = args.repeats if batch <= 1024 else 1
        out = subprocess.run(
            [
                sys.executable,
                "-c",
                CHILD,
                str(batch),
                str(args.duration),
                str(args.chunk),
                str(repeats),
                str(pathlib.Path(__file__).resolve().parent),
            ],
            capture_output=True,
            text=True,
            check=True,
        )
        rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
        print(json.dumps(rows[-1]), file=sys.stderr)
    base = next((r for r in rows if r["batch"] == 1), rows[0])
    for r in rows:
        r["throughput_vs_batch_1"] = r["trajectory_steps_per_s"] / base["trajectory_steps_per_s"]
    print(
        json.dumps(
            {
                "workload": "velocity estimator, section-6 simulation, 0.1 px noise per "
                "trajectory, reconstruction per trajectory, K x 0.01, rho x 0.1, float64",
                "duration_s": args.duration,
                "devices": "CPU (this machine)",
                "results": rows,
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
