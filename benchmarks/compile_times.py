"""Compile time of each paper estimator's run, each in a fresh process. Prints JSON.

For the velocity estimator of Chitrakaran et al. (the section-6 stream, preprocessing fused
with the loop), the unknown input observer of Jang's thesis (set II.1, 50 Hz frames under a
1 ms step) and the adaptive estimator of Nath et al. (the project's scene at 1 kHz): the
time to trace, lower and compile `run` (`jax.jit(...).lower(...).compile()`), and the run's
own wall time after compiling, 2 s of data each. The reference, timed in the same process
first: the compile of a bare `jax.lax.scan` of the same number of steps carrying a (6,)
state (what any compiled loop costs), so that each estimator's compile is also a ratio.

    python benchmarks/compile_times.py
"""

import json
import subprocess
import sys

CHILD = r"""
import json, sys, time
import jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
which = sys.argv[1]

def bare(n):
    step = lambda c, _: (jnp.sin(c) * 0.5 + c, None)
    f = jax.jit(lambda x: jax.lax.scan(step, x, None, length=n)[0])
    t0 = time.perf_counter()
    f.lower(jnp.zeros(6)).compile()
    return time.perf_counter() - t0

from visjax.estimators import SaveAt, run
if which == "velocity":
    from visjax.estimators import VelocityEstimator, fixed_camera, velocity_stream
    from visjax.papers.chitrakaran import K_EQ63, RHO_EQ63, section6_scenario
    sc = section6_scenario(2.0, 1000.0)
    camera = fixed_camera(sc.pixels, sc.A, sc.R_star, sc.s[0])
    stream = velocity_stream(sc.ts, sc.pixels, camera)
    est, dt = VelocityEstimator(K=K_EQ63, rho=RHO_EQ63), None
elif which == "uio":
    from visjax.estimators import moving_point_stream
    from visjax.papers import jang
    sc = jang.scenario("II.1", 2.0)
    stream = moving_point_stream(sc.frame_ts, sc.frame_pixels, sc.frame_velocities, sc.Kc_observer)
    est, dt = jang.observer("II.1"), 1e-3
else:
    from visjax.papers import nath
    sc = nath.scenario(2.0)
    stream = nath.stream(sc)
    est, dt = nath.initial_estimator(sc), None

n = int(round((float(stream.ts[-1]) - float(stream.ts[0])) / (dt or 1e-3))) + 1
reference = bare(n)
# the times stay concrete (closed over: `run(..., dt=...)` fixes its grid from them); the
# estimator and the measurements are the compiled function's arguments
import equinox as eqx
def go(e, ys):
    s = eqx.tree_at(lambda s: s.ys, stream, ys)
    return run(e, s, dt=dt, saveat=SaveAt(every=10)).outputs
f = jax.jit(go)
t0 = time.perf_counter()
compiled = f.lower(est, stream.ys).compile()
compile_s = time.perf_counter() - t0
jax.block_until_ready(compiled(est, stream.ys))
t0 = time.perf_counter()
jax.block_until_ready(compiled(est, stream.ys))
run_s = time.perf_counter() - t0
print(json.dumps({"estimator": which, "steps": n, "compile_s": compile_s, "run_s": run_s,
                  "bare_scan_compile_s": reference,
                  "compile_over_bare_scan": compile_s / reference}))
"""

NAMES = {
    "velocity": "velocity estimator (Chitrakaran et al.)",
    "uio": "unknown input observer (Jang's thesis)",
    "adaptive": "adaptive least-squares estimator (Nath et al.)",
}


def main():
    rows = []
    for which in NAMES:
        out = subprocess.run(
            [sys.executable, "-c", CHILD, which], capture_output=True, text=True, check=True
        )
        row = json.loads(out.stdout.strip().splitlines()[-1])
        row["name"] = NAMES[which]
        rows.append(row)
    print(
        json.dumps(
            {
                "benchmark": "compile_times",
                "results": rows,
                "max_compile_s": max(r["compile_s"] for r in rows),
                "target": {"compile_s": "< 5 per estimator"},
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
