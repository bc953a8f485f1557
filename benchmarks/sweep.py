"""Throughput of `visjax.studies.sweep` on the users' main workload: a Monte-Carlo noise
study of the velocity estimator of Chitrakaran et al. with per-trajectory pixel noise (the
homography, its decomposition and J recomputed from each trajectory's noisy pixels), at
batch 1, 64, 1,024 and 16,384 trajectories, each batch in its own process so that its peak
resident memory is its own.

Reported per batch: trajectory-steps per second after compilation (median of `--repeats`
timed sweeps), the compile-inclusive first sweep, the peak resident memory of the process
(`VmHWM`, see `_memory.py`), and the throughput as a ratio against batch 1 measured in the same run.
Each batch's sweep is also timed against the same study written directly on the estimator
and stream builders, in the same process (`monte_carlo.raw_study`, `jit(vmap)` over the
batch at once): `sweep_over_raw`, the runner's overhead (target: <= 1.3 at batch 131,072).
The JSON records the device and the dtype (`_device.device_fields`). Prints JSON.

    python benchmarks/sweep.py [--duration 1.0] [--batches 1 64 1024 16384] [--chunk 1024]
        [--dtype float64|float32]
"""

import argparse
import json
import pathlib
import subprocess
import sys

from _device import add_dtype_option, device_fields

CHILD = r"""
import json, statistics, sys, time
sys.path.insert(0, sys.argv[5])
from _memory import peak_rss_mb
from _device import device_fields, use_dtype
import jax, jax.numpy as jnp, numpy as np
use_dtype(sys.argv[6])
import visjax
visjax.apply_xla_cpu_workarounds()
from visjax import papers, studies
from monte_carlo import raw_study

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
# the raw study at the same batch (one jit(vmap) call, no runner): the runner's overhead
raw = raw_study(duration, 16)[0]
raw_keys = jax.random.split(jax.random.key(0), batch)
jax.block_until_ready(raw(raw_keys))
raw_times = []
for _ in range(repeats):
    t0 = time.perf_counter()
    jax.block_until_ready(raw(raw_keys))
    raw_times.append(time.perf_counter() - t0)
raw_wall = statistics.median(raw_times)
print(json.dumps({
    **device_fields(sys.argv[6]),
    "batch": batch,
    "steps_per_trajectory": steps,
    "chunk": min(chunk, batch),
    "wall_s": wall,
    "first_call_s": first,
    "trajectory_steps_per_s": batch * steps / wall,
    "ns_per_trajectory_step": 1e9 * wall / (batch * steps),
    "raw_ns_per_trajectory_step": 1e9 * raw_wall / (batch * steps),
    "sweep_over_raw": wall / raw_wall,
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
    add_dtype_option(parser)
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
                args.dtype,
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
                f"trajectory, reconstruction per trajectory, K x 0.01, rho x 0.1, {args.dtype}",
                "duration_s": args.duration,
                **device_fields(args.dtype),
                "results": rows,
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
