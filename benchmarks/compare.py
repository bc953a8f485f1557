"""Each paper's estimator against its batch least-squares baselines and its EKF
(`visjax.studies.compare`, the same problems as `visjax compare`): for each problem at 0,
0.1 and 0.5 px of pixel noise, over a few noise seeds, the accuracy (the estimator's own
summary keys) and the latency per new sample (median over timed runs, after compilation)
of every method. The settings of every method are fixed in advance and printed with the
results (no value chosen to match anything). Prints JSON (docs/baselines.md).

    python benchmarks/compare.py [--seeds 3] [--problems velocity moving_point static_points]
"""

import argparse
import json
import sys

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import visjax  # noqa: E402
from visjax import studies  # noqa: E402

NOISE = (0.0, 0.1, 0.5)
PROBLEMS = ("velocity", "moving_point", "static_points")


def summarise(setup, records):
    out = {}
    for method in setup.methods:
        rows = [r for r in records if r["method"] == method]
        good = [r[setup.metric] for r in rows if r["result"] == "successful"]
        out[method] = {
            "failed": sum(r["result"] != "successful" for r in rows),
            setup.label: float(np.median(good)) if good else None,
            "latency_s_per_sample": float(np.median([r["latency_s_per_sample"] for r in rows])),
            "total_s": float(np.median([r["total_s"] for r in rows])),
        }
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--problems", nargs="*", default=list(PROBLEMS), choices=PROBLEMS)
    args = parser.parse_args()
    visjax.apply_xla_cpu_workarounds()  # batched LAPACK calls can hang on jaxlib 0.10
    report = {"seeds": args.seeds, "problems": {}}
    for name in args.problems:
        per_noise = {}
        for noise in NOISE:
            setup = studies.problem(name, noise_px=noise)
            records = studies.compare(setup, range(args.seeds))
            per_noise[str(noise)] = {"summary": summarise(setup, records), "records": records}
            print(f"{name} at {noise} px done", file=sys.stderr)
        report["problems"][name] = {"settings": setup.settings(), "noise_px": per_noise}
    json.dump(report, sys.stdout, indent=1)


if __name__ == "__main__":
    main()
