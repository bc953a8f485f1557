"""Float32 against float64: every method of every registered problem, on the same noise
keys, in a process of each (`jax_enable_x64` on for float64, off for float32: the whole
computation in float32, as a GPU without float64 throughput would run it). Prints JSON;
`--markdown` prints the tables of docs/gpu.md instead.

Per problem and method, at the problem's own noise level and without noise:

- the headline metric (the problem's `metric`) in each dtype: median over the keys;
- `rms_diff`: the RMS over the keys of (float32 - float64) (`rel_rms_diff`: over the
  float64 median; meaningless where that is at rounding level, as an exact method's
  noise-free error): without noise this is the arithmetic's difference alone; with
  noise it also holds the draws' (JAX draws a float32 normal from 32 random bits, so the
  float32 draw of a key is not the float64 draw rounded): compare the medians there;
- `failed`: the fraction of runs that failed (a result code other than `successful`, or
  a metric that is not finite), in each dtype.

    python benchmarks/float32_accuracy.py [--seeds 8] [--duration 2] [--problems velocity ...]
        [--markdown]
"""

import argparse
import json
import os
import pathlib
import subprocess
import sys

HERE = pathlib.Path(__file__).resolve().parent

CHILD = r"""
import json, sys
import numpy as np
import jax, jax.numpy as jnp
import visjax
visjax.apply_xla_cpu_workarounds()
jax.config.update("jax_enable_x64", sys.argv[1] == "float64")
from visjax import papers, studies  # noqa: F401  (registers the problems)

names, seeds = sys.argv[2].split(","), int(sys.argv[3])
duration = None if sys.argv[4] == "default" else float(sys.argv[4])
out = {}
for name in names:
    problem = studies.problem(name, duration=duration)
    keys = jnp.arange(seeds)
    for method in problem.methods:
        for noise in ("own", 0.0):
            params = {} if noise == "own" else {"noise_px": 0.0}
            spec = problem.parameters().get("noise_px")
            if noise != "own" and (spec is None or float(spec.value) == 0.0):
                continue  # no noise of its own: the first row is the noise-free one
            try:
                ev = studies.evaluate(problem, params, keys, method=method)
                values = np.asarray(ev.metrics[problem.metric], np.float64)
                values = values.reshape(values.shape[0], -1).max(axis=1)
                ok = np.asarray(ev.result._value) == 0
                level = float(spec.value) if (noise == "own" and spec is not None) else 0.0
                row = {"noise_px": level,
                       "values": [None if not np.isfinite(v) else float(v) for v in values],
                       "failed": float(np.mean(~ok | ~np.isfinite(values)))}
            except Exception as e:  # float32 cannot serve: recorded, never hidden
                row = {"error": f"{type(e).__name__}: {str(e).splitlines()[0][:200]}"}
            out[f"{name}|{method}|{noise}"] = row
            said = row.get("failed", row.get("error"))
            print(name, method, noise, said, file=sys.stderr, flush=True)
metric = {n: studies.problem(n).metric for n in names}
print(json.dumps({"dtype": sys.argv[1], "metric": metric, "runs": out}))
"""


def measure(dtype, names, seeds, duration):
    env = dict(os.environ, JAX_ENABLE_X64="1" if dtype == "float64" else "0")
    out = subprocess.run(
        [sys.executable, "-c", CHILD, dtype, ",".join(names), str(seeds), str(duration)],
        capture_output=True, text=True, env=env, check=False,
    )  # fmt: skip
    if out.returncode != 0:
        raise SystemExit(f"the {dtype} run failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def compare(r64, r32):
    import numpy as np

    rows = []
    for key, a in r64["runs"].items():
        b = r32["runs"].get(key, {"error": "not run"})
        name, method, noise = key.split("|")
        row = {"problem": name, "method": method, "noise": noise,
               "noise_px": a.get("noise_px", 0.0), "metric": r64["metric"][name]}  # fmt: skip
        if "error" in a or "error" in b:
            row.update(error64=a.get("error"), error32=b.get("error"))
            rows.append(row)
            continue
        x = np.array([np.nan if v is None else v for v in a["values"]])
        y = np.array([np.nan if v is None else v for v in b["values"]])
        both = np.isfinite(x) & np.isfinite(y)
        med = float(np.nanmedian(x)) if np.isfinite(x).any() else float("nan")
        rms = float(np.sqrt(np.mean((y[both] - x[both]) ** 2))) if both.any() else float("nan")
        row.update(
            median64=med,
            median32=float(np.nanmedian(y)) if np.isfinite(y).any() else float("nan"),
            rms_diff=rms,
            rel_rms_diff=rms / abs(med) if med else float("nan"),
            failed64=a["failed"],
            failed32=b["failed"],
        )
        rows.append(row)
    return rows


def markdown(rows):
    def f(x):
        return "n/a" if x is None or x != x else f"{x:.3g}"

    lines = []
    for name in dict.fromkeys(r["problem"] for r in rows):
        mine = [r for r in rows if r["problem"] == name]
        lines += [f"**{name}** (metric `{mine[0]['metric']}`, worst component)", "",
                  "| method | noise | float64 median | float32 median | RMS difference |"
                  " failed float64 | failed float32 |",
                  "|---|---|---|---|---|---|---|"]  # fmt: skip
        for r in mine:
            noise = f"{r['noise_px']:g} px" if r["noise"] == "own" else "none"
            if "error64" in r:
                err = r["error32"] or r["error64"]
                lines.append(f"| {r['method']} | {noise} | {err} | | | | |")
                continue
            lines.append(
                f"| {r['method']} | {noise} | {f(r['median64'])} | {f(r['median32'])} |"
                f" {f(r['rms_diff'])} | {r['failed64']:.0%} |"
                f" {r['failed32']:.0%} |"
            )
        lines.append("")
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument(
        "--duration", default="2", help="seconds of each problem's scene, or `default`"
    )
    parser.add_argument(
        "--problems",
        nargs="*",
        default=["velocity", "moving_point", "static_points", "point_depth", "homography"],
    )
    parser.add_argument("--markdown", action="store_true", help="the docs' tables")
    args = parser.parse_args()
    r64 = measure("float64", args.problems, args.seeds, args.duration)
    r32 = measure("float32", args.problems, args.seeds, args.duration)
    rows = compare(r64, r32)
    if args.markdown:
        print(markdown(rows))
    else:
        result = {"benchmark": "float32_accuracy", "seeds": args.seeds,
                  "duration_s": args.duration, "rows": rows}  # fmt: skip
        print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
