"""Peak memory of a long run of the velocity estimator of Chitrakaran, Dawson, Dixon, Chen,
*Identification of a moving object's velocity with a fixed camera*: 10^6 steps (1,000 s
at 1 kHz) of the section-6 simulation. Prints JSON.

The pixels are simulated first and written to a temporary `.npy` file; a fresh process
then loads them, builds the stream (`fixed_camera`, `velocity_stream`, $n^*$ and $z_1^*$ given, the
result-code pass over every frame included) and runs the estimator, saving one output in
1,000, and reports its peak resident memory (`VmHWM`, see `_memory.py`). The reference, in the same
run, is the same process on the first 10^4 steps: the difference is what the length costs
(the pixels themselves are 64 bytes per sample, 64 MB for 10^6).

    python benchmarks/long_run_memory.py [--steps 1000000] [--chunk 256]
"""

import argparse
import json
import pathlib
import subprocess
import sys
import tempfile

HERE = str(pathlib.Path(__file__).resolve().parent)

CHILD = r"""
import json, sys, time
sys.path.insert(0, sys.argv[4])
from _memory import peak_rss_mb
import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
from visjax.estimators import SaveAt, VelocityEstimator, FixedCamera, run, velocity_stream
from visjax.papers.chitrakaran import K_EQ63, RHO_EQ63
from visjax import RESULTS

folder, steps, chunk = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
c = np.load(folder + "/constants.npz")
pixels = np.load(folder + "/pixels.npy", mmap_mode="r")[:steps]
ts = np.arange(steps) * 1e-3
t0 = time.perf_counter()
camera = FixedCamera(pixels[0], c["A"], c["R_star"], c["s1"], c["n_star"], c["z1_star"])
stream = velocity_stream(ts, pixels, camera, chunk=chunk)
sol = run(VelocityEstimator(K=K_EQ63, rho=RHO_EQ63), stream, saveat=SaveAt(every=1000))
v = np.asarray(sol.outputs.v_hat)
print(json.dumps({
    "steps": steps,
    "wall_s": time.perf_counter() - t0,
    "saved": int(v.shape[0]),
    "finite": bool(np.all(np.isfinite(v))),
    "successful": bool(sol.result == RESULTS.successful),
    "peak_rss_mb": peak_rss_mb(),
}))
"""


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--chunk", type=int, default=256)
    args = parser.parse_args()

    import jax
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    from visjax.papers.chitrakaran import section6_scenario

    with tempfile.TemporaryDirectory() as folder:
        sc = section6_scenario(args.steps / 1000.0, 1000.0)
        np.save(pathlib.Path(folder) / "pixels.npy", np.asarray(sc.pixels))
        np.savez(
            pathlib.Path(folder) / "constants.npz",
            A=np.asarray(sc.A),
            R_star=np.asarray(sc.R_star),
            s1=np.asarray(sc.s[0]),
            n_star=np.asarray(sc.n_star),
            z1_star=np.asarray(sc.z1_star),
        )
        n = int(sc.ts.shape[0])
        del sc
        rows = []
        for steps in (min(10_000, n), n):
            out = subprocess.run(
                [sys.executable, "-c", CHILD, folder, str(steps), str(args.chunk), HERE],
                capture_output=True,
                text=True,
                check=True,
            )
            rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
    short, long = rows
    print(
        json.dumps(
            {
                "benchmark": "long_run_peak_memory_velocity_estimator",
                "chunk": args.chunk,
                "reference": short,
                "long": long,
                "peak_rss_mb": long["peak_rss_mb"],
                "extra_mb_vs_reference": long["peak_rss_mb"] - short["peak_rss_mb"],
                "extra_bytes_per_step": 2**20
                * (long["peak_rss_mb"] - short["peak_rss_mb"])
                / (long["steps"] - short["steps"]),
                "target": {"peak_rss_mb": "< 500 for 10^6 steps"},
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
