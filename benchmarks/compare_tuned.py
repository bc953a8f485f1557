"""Every method of each problem at its defaults and tuned with the same budget
(`visjax.studies.compare_tuned`, as `visjax compare PROBLEM --tune`), at 0.5 px of pixel
noise: the same test seeds for both, the tuning on as many other seeds. Per method: the
median of the headline metric with its 95% bootstrap interval, the failure rate with the
failures' result codes, the median time per run, and the tuned parameters. The budget,
the seeds, the search ranges and each problem's settings are fixed in advance and
printed with the results. Prints JSON (docs/baselines.md, the problems' pages).

    python benchmarks/compare_tuned.py [--seeds 5] [--budget 16] [--noise 0.5]
        [--problems point_depth homography moving_point static_points velocity]
        [--partial FILE] [--methods a,b]

`--partial FILE`: the report so far, rewritten after each problem (a long run keeps what
it finished).
"""

import argparse
import json
import sys
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import visjax  # noqa: E402
from visjax import studies  # noqa: E402

PROBLEMS = ("point_depth", "homography", "moving_point", "static_points", "velocity")
# velocity over 1 s (scored over 0.5-1 s): its batch fits compile once per searched
# bandwidth (`bandwidth_scale` is structural)
OPTIONS = {"velocity": {"duration": 1.0}}


def table(problem, records, seed):
    stats = records.statistics(problem.metric, seed=seed)
    out = {}
    for m, s in stats["methods"].items():
        total = [r["total_s"] for r in records if r["method"] == m]
        failures = {k: v for k, v in s["results"].items() if k != "successful"}
        out[m] = {
            "median": s["median"], "low": s["low"], "high": s["high"],
            "failure_rate": s["failure_rate"], "failures": failures,
            "time_per_run_s": float(np.median(total)),
        }  # fmt: skip
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--budget", type=int, default=studies.BUDGET)
    parser.add_argument("--noise", type=float, default=0.5)
    parser.add_argument("--problems", nargs="*", default=list(PROBLEMS), choices=PROBLEMS)
    parser.add_argument("--partial", default=None)
    parser.add_argument("--methods", default=None, help="a,b: these methods only")
    args = parser.parse_args()
    visjax.apply_xla_cpu_workarounds()  # batched LAPACK calls can hang on jaxlib 0.10
    test, train = np.arange(args.seeds), np.arange(args.seeds, 2 * args.seeds)
    report = {"seeds": test.tolist(), "train_seeds": train.tolist(), "budget": args.budget}
    report |= {"noise_px": args.noise, "problems": {}}
    for name in args.problems:
        options = OPTIONS.get(name, {})
        problem = studies.problem(name, noise_px=args.noise, **options)
        started = time.perf_counter()
        methods = None if args.methods is None else args.methods.split(",")
        untuned = studies.compare(problem, test, methods=methods)
        records, tuning = studies.compare_tuned(problem, test, train, args.budget, methods=methods)
        report["problems"][name] = {
            "options": options, "methods": methods, "metric": problem.metric,
            "settings": problem.settings(),
            "untuned": table(problem, untuned, 0), "tuned": table(problem, records, 0),
            "tuning": tuning.as_json(), "wall_s": time.perf_counter() - started,
        }  # fmt: skip
        print(f"{name} done in {time.perf_counter() - started:.0f} s", file=sys.stderr)
        if args.partial is not None:
            with open(args.partial, "w") as f:
                json.dump(report, f, indent=1, default=float)
    json.dump(report, sys.stdout, indent=1, default=float)


if __name__ == "__main__":
    main()
