"""visjax's bundle adjustment against GTSAM on the static-points problem of Nath et al. (the
uncalibrated camera: intrinsics, mounting and unknown features), time and accuracy side by
side (issue 30, item 1). Prints JSON.

The problem: a scene of the catalogue (`--scene`: `nath`, the project's scene of
`papers.nath.scenario`, 20 s at 2 Hz; `tilted`, `side`: `sim.tilted_platform_scene`,
`sim.side_looking_platform_scene`, 40 s at 1 Hz; 40 frames, 4 unknown and 6 known
features, as in `tests/baselines/test_vs_gtsam.py`) at `--noise-px` of pixel noise, each
problem its own noise seed. Both solvers start from the same initial values (the
estimator `StaticPointsEstimator.from_nominal` builds from the nominal camera and the first
noisy frame of seed 0, the same for every problem) and minimise the same cost,
$\\frac12\\sum\\|r\\|^2$ over the pixel residuals, by Levenberg-Marquardt:

- visjax: `bundle_adjustment` (its default tolerances), from the pixels to the solution in
  one compiled program; one problem alone, and `--problems` independent problems in one
  `jax.vmap`. Compile times are reported apart.
- GTSAM: the factor graph of `tests/baselines/test_vs_gtsam.py` (`gtsam_static_points`: a
  `Pose3` mounting, a `Point3` per unknown feature, a `Cal3_S2` calibration, one
  `CustomFactor` per seen pixel whose residual and Jacobians GTSAM's own `Pose3.compose`
  and `PinholeCameraCal3_S2.project` compute), its Levenberg-Marquardt run to a relative
  and absolute decrease of 1e-14; one problem alone, and a Python loop over the problems
  (the graph built and solved for each). GTSAM's Python wrapper has no projection factor
  with the calibration and the body-camera pose as variables, so each factor's error is a
  Python callback: a C++ factor would be faster, and the loop's time is GTSAM through its
  Python interface, as a Python user runs it. If the loop would exceed `--gtsam-budget-s`,
  it runs on the first problems only and its time is extrapolated (the JSON says so).

Reported: seconds per problem of each (and of visjax's one-problem program in a Python
loop over the first 200 problems: a vmapped batch runs as many Levenberg-Marquardt steps
as its slowest problem, hence the steps' median and largest), `batch_speedup_vs_gtsam_loop`
(the GTSAM loop's time over the vmapped batch's), `max_rel_diff_vs_gtsam` (over the
problems GTSAM solved: the largest difference of any solved quantity relative to the
largest entry of GTSAM's), the final costs' largest relative difference, and the accuracy
of each (the median and largest unknown-feature error against the truth, mm; the median
focal-length error, px).

    python benchmarks/vs_gtsam.py [--problems 1000] [--scene nath] [--noise-px 1.0]
"""

import argparse
import json
import pathlib
import platform
import statistics
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))  # the tests' helpers

import equinox as eqx  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import visjax  # noqa: E402
from visjax._results import RESULTS  # noqa: E402
from visjax.baselines import bundle_adjustment  # noqa: E402
from visjax.estimators import StaticPointsEstimator, static_points_stream  # noqa: E402

QUANTITIES = ("A", "R_c", "x_c", "omega_s")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--problems", type=int, default=1000)
    parser.add_argument("--scene", choices=("nath", "tilted", "side"), default="nath")
    parser.add_argument("--noise-px", type=float, default=1.0)
    parser.add_argument("--repeats", type=int, default=5, help="timings: median of repeats")
    parser.add_argument(
        "--gtsam-budget-s",
        type=float,
        default=600.0,
        help="the GTSAM loop's time budget: beyond it, measured on a subset and extrapolated",
    )
    args = parser.parse_args()
    visjax.apply_xla_cpu_workarounds()
    jax.config.update("jax_enable_x64", True)
    # after float64 is on: the GTSAM transcription and the scenes of the tests
    from tests.baselines.test_vs_gtsam import gtsam_static_points, static_scenes

    s = next(sc for sc in static_scenes() if sc["name"] == args.scene)
    ts, R_b, x_b, omega_c = s["ts"], s["R_b"], s["x_b"], s["omega_c"]
    P = args.problems

    def noisy(seed):
        k1, k2 = jax.random.split(jax.random.key(seed))
        p_s = s["p_s"] + args.noise_px * jax.random.normal(k1, s["p_s"].shape)
        p_c = s["p_c"] + args.noise_px * jax.random.normal(k2, s["p_c"].shape)
        return p_s, p_c

    p_s, p_c = jax.jit(jax.vmap(noisy))(jnp.arange(P))
    first = static_points_stream(ts, R_b, x_b, p_s[0], p_c[0], omega_c)
    est = StaticPointsEstimator.from_nominal(first, *s["nominal"])

    def solve(p_s, p_c):
        """From the pixels of one problem to its solution (`throw=False`: a code each)."""
        stream = static_points_stream(ts, R_b, x_b, p_s, p_c, omega_c, throw=False)
        sol = bundle_adjustment(est, stream, omega_c, throw=False)
        out = jax.tree_util.tree_map(lambda x: x[-1], sol.outputs)
        seen = p_s.shape[0] * (p_s.shape[1] + p_c.shape[1])
        cost = sol.diagnostics.rms_px[0] ** 2 * seen  # 1/2 sum r^2 (rms over coordinates)
        return out, cost, sol.result._value, sol.diagnostics.steps[0]

    one = eqx.filter_jit(solve)
    batch = eqx.filter_jit(jax.vmap(solve))

    def timed(f, *a):
        t0 = time.perf_counter()
        jax.block_until_ready(f(*a))
        first_call = time.perf_counter() - t0
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            out = jax.block_until_ready(f(*a))
            times.append(time.perf_counter() - t0)
        run = statistics.median(times)
        return out, run, first_call - run

    (out1, cost1, _, _), t_one, compile_one = timed(one, p_s[0], p_c[0])
    (outs, costs, codes, steps), t_batch, compile_batch = timed(batch, p_s, p_c)
    # the single-problem program in a Python loop, for comparison with the vmapped batch
    looped = min(P, 200)
    t0 = time.perf_counter()
    for i in range(looped):
        jax.block_until_ready(one(p_s[i], p_c[i]))
    t_visjax_loop = (time.perf_counter() - t0) / looped

    # GTSAM from the same initial values: the estimator's initial estimate
    y0 = jax.tree_util.tree_map(lambda x: x[0], first.ys)
    init = est.output(jnp.zeros(()), est.init(y0), y0)
    start = [np.asarray(getattr(init, k)) for k in QUANTITIES]
    data = [np.asarray(x) for x in (R_b, x_b)]
    p_s_np, p_c_np, omega_c_np = np.asarray(p_s), np.asarray(p_c), np.asarray(omega_c)

    def gtsam_solve(i):
        return gtsam_static_points(
            *data, p_s_np[i], p_c_np[i], omega_c_np, *start, calibrated=False
        )  # fmt: skip

    single = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        ref1 = gtsam_solve(0)
        single.append(time.perf_counter() - t0)
    t_gtsam_one = statistics.median(single)

    refs, t0 = [], time.perf_counter()
    budget_problems = max(1, min(P, int(args.gtsam_budget_s / t_gtsam_one)))
    for i in range(budget_problems):
        refs.append(gtsam_solve(i))
    t_loop_measured = time.perf_counter() - t0
    t_gtsam_per_problem = t_loop_measured / len(refs)
    t_loop = t_gtsam_per_problem * P  # = the measurement when every problem ran

    # accuracy: visjax against GTSAM, each against the truth
    outs = {k: np.asarray(getattr(outs, k)) for k in QUANTITIES}
    costs, codes = np.asarray(costs), np.asarray(codes)

    def rel(a, b):
        return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))

    diffs = [max(rel(outs[k][i], r[k]) for k in QUANTITIES) for i, r in enumerate(refs)]
    cost_diffs = [abs(costs[i] - r["cost"]) / r["cost"] for i, r in enumerate(refs)]
    truth = np.asarray(s["omega_s"])
    err_visjax = np.linalg.norm(outs["omega_s"] - truth, axis=-1) * 1e3  # (P, n) mm
    err_gtsam = np.stack([np.linalg.norm(r["omega_s"] - truth, axis=-1) for r in refs]) * 1e3
    A_true = np.asarray(s["A"])
    focal_visjax = np.abs(outs["A"][:, 0, 0] - A_true[0, 0])
    focal_gtsam = np.array([abs(r["A"][0, 0] - A_true[0, 0]) for r in refs])
    single_diff = max(rel(np.asarray(getattr(out1, k)), ref1[k]) for k in QUANTITIES)
    n = len(refs)

    print(
        json.dumps(
            {
                "benchmark": "bundle_adjustment_vs_gtsam",
                "machine": platform.machine(),
                "jax": jax.__version__,
                "gtsam": getattr(sys.modules["gtsam"], "__version__", "4.3"),
                "dtype": "float64",
                "scene": args.scene,
                "frames": int(ts.shape[0]),
                "unknown_features": int(truth.shape[0]),
                "known_features": int(omega_c.shape[0]),
                "noise_px": args.noise_px,
                "problems": P,
                "one_problem": {
                    "visjax_s": t_one,
                    "visjax_compile_s": compile_one,
                    "gtsam_s": t_gtsam_one,
                    "speedup_vs_gtsam": t_gtsam_one / t_one,
                    "rel_diff_vs_gtsam": single_diff,
                    "cost_visjax": float(cost1),
                    "cost_gtsam": ref1["cost"],
                    "gtsam_iterations": ref1["iterations"],
                },
                "batch": {
                    "visjax_s": t_batch,
                    "visjax_compile_s": compile_batch,
                    "visjax_s_per_problem": t_batch / P,
                    "visjax_failed": int(np.sum(codes != RESULTS.successful._value)),
                    "visjax_steps_median": float(np.median(np.asarray(steps))),
                    "visjax_steps_max": int(np.max(np.asarray(steps))),
                    "visjax_loop_s_per_problem": t_visjax_loop,
                    "visjax_loop_problems": looped,
                    "gtsam_loop_s": t_loop,
                    "gtsam_s_per_problem": t_gtsam_per_problem,
                    "gtsam_problems_solved": n,
                    "gtsam_loop_extrapolated": n < P,
                },
                "batch_speedup_vs_gtsam_loop": t_loop / t_batch,
                "max_rel_diff_vs_gtsam": max(diffs),
                "max_cost_rel_diff_vs_gtsam": max(cost_diffs),
                "accuracy": {
                    "visjax_median_feature_error_mm": float(np.median(err_visjax)),
                    "gtsam_median_feature_error_mm": float(np.median(err_gtsam)),
                    "visjax_max_feature_error_mm": float(err_visjax[:n].max()),
                    "gtsam_max_feature_error_mm": float(err_gtsam.max()),
                    "visjax_median_focal_error_px": float(np.median(focal_visjax)),
                    "gtsam_median_focal_error_px": float(np.median(focal_gtsam)),
                    "over": "visjax: every problem; gtsam: the problems it solved "
                    "(the maxima over those for both)",
                },
                "settings": {
                    "visjax": "optimistix.LevenbergMarquardt(rtol=1e-9, atol=1e-9), the "
                    "bundle_adjustment defaults",
                    "gtsam": "LevenbergMarquardtParams: relative and absolute error "
                    "tolerance 1e-14, at most 200 iterations; CustomFactor (Python) per pixel",
                },
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
