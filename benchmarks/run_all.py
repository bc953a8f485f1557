"""Run the performance benchmarks and regenerate the performance table of the docs.

Each benchmark runs in its own process (its memory and compile times its own) and prints
one JSON document; this collects them under their names in `--out` (default
`benchmarks/results.json`), with the machine and versions, and then rewrites the table
between the markers `<!-- performance-table:start -->` and `<!-- performance-table:end -->`
in docs/performance.md from that file alone (`--table-only` redoes the table from an
existing file without running anything; `--no-table` leaves the page alone).

    python benchmarks/run_all.py [--quick] [--only NAME ...] [--table-only] [--no-table]

`--quick` runs every benchmark on small sizes (a smoke test of the scripts, minutes);
the documented numbers come from a full run.
"""

import argparse
import datetime
import json
import os
import pathlib
import platform
import subprocess
import sys

HERE = pathlib.Path(__file__).parent
PERFORMANCE_PAGE = HERE.parent / "docs" / "performance.md"
START, END = "<!-- performance-table:start -->", "<!-- performance-table:end -->"

# name: (script, full arguments, quick arguments)
BENCHMARKS = {
    "homography_decomposition": ("homography_decomposition.py", [], ["--frames", "2000"]),
    "one_trajectory": ("velocity_benchmark.py", [], ["--batch", "8", "--repeats", "2"]),
    "monte_carlo": (
        "monte_carlo.py",
        ["--batch", "1024"],
        ["--batch", "32", "--duration", "0.2", "--repeats", "1"],
    ),
    "long_run_memory": ("long_run_memory.py", [], ["--steps", "50000"]),
    "gradient_uncalibrated": (
        "gradient_uncalibrated.py",
        [],
        ["--duration", "1", "--batch", "8"],
    ),
    "compile_times": ("compile_times.py", [], []),
    "gain_sweep": ("gain_sweep.py", [], ["--batches", "1", "64", "--duration", "0.2"]),
    "sweep_scaling": (
        "sweep_scaling.py",
        [],
        ["--runs", "32", "--chunk", "8", "--duration", "0.1", "--repeats", "1"],
    ),
    "robust_homography": (
        "robust_homography.py",
        [],
        ["--frames", "20", "--iterations", "200", "--repeats", "1"],
    ),
    "vs_gtsam": ("vs_gtsam.py", [], ["--problems", "16", "--repeats", "1"]),
}


def run_one(name, quick):
    script, full, small = BENCHMARKS[name]
    cmd = [sys.executable, str(HERE / script), *(small if quick else full)]
    print(f"[run_all] {' '.join(cmd[1:])}", file=sys.stderr, flush=True)
    out = subprocess.run(cmd, capture_output=True, text=True, env=os.environ.copy())
    if out.returncode != 0:
        return {"error": out.stderr.strip().splitlines()[-20:], "command": cmd[1:]}
    result = json.loads(out.stdout)
    result["command"] = " ".join(["python", f"benchmarks/{script}", *cmd[2:]])
    return result


def _fmt(x, digits=3):
    if x is None:
        return "n/a"
    if abs(x) >= 100:
        return f"{x:,.0f}"
    return f"{x:.{digits}g}"


def _met(ok):
    return "yes" if ok else "**no**"


def table(results: dict) -> str:
    """The performance table (Markdown) of docs/performance.md from the collected results."""
    r = results["benchmarks"]
    rows = []
    h = r.get("homography_decomposition", {})
    if "speedup_opencv_over_visjax" in h:
        ratio = h["speedup_opencv_over_visjax"]
        rows.append(
            (
                f"homography + four-solution decomposition, {h['frames']:,} frames (`jit(vmap)`)",
                f"{_fmt(h['visjax_us_per_frame'])} µs/frame",
                f"OpenCV per-frame loop {_fmt(h['opencv_us_per_frame'])} µs/frame",
                f"{_fmt(ratio)}x faster",
                ">= 20x",
                _met(ratio >= 20),
            )
        )
    m = r.get("monte_carlo", {})
    if "ns_per_trajectory_step" in m:
        ns = m["ns_per_trajectory_step"]
        rows.append(
            (
                f"Monte-Carlo noise study, per-trajectory reconstruction, batch {m['batch']:,}"
                f" x {m['steps_per_trajectory']:,} steps",
                f"{_fmt(ns)} ns per trajectory-step",
                f"NumPy per-step loop {_fmt(m['numpy_loop_ns_per_step'])} ns/step; "
                f"the estimator's loop alone {_fmt(m['loop_only_ns_per_trajectory_step'])} ns",
                f"{_fmt(m['speedup_vs_numpy_loop'])}x the NumPy loop",
                "<= 300 ns at batch 1,024",
                _met(ns <= 300 and m["batch"] >= 1024),
            )
        )
    if "ns_per_trajectory_step_rbg" in m:
        ns = m["ns_per_trajectory_step_rbg"]
        rows.append(
            (
                'the same study with `jax.random.key(seed, impl="rbg")` keys (XLA\'s generator)',
                f"{_fmt(ns)} ns per trajectory-step",
                f"drawing the noise alone: threefry {_fmt(m['noise_only_ns_per_trajectory_step'])}"
                f" ns, rbg {_fmt(m['noise_only_rbg_ns_per_trajectory_step'])} ns",
                f"{_fmt(m['numpy_loop_ns_per_step'] / ns)}x the NumPy loop",
                "<= 300 ns at batch 1,024",
                _met(ns <= 300 and m["batch"] >= 1024),
            )
        )
    if "parts_ns_per_trajectory_step" in m:
        rows.append(
            (
                "the study's parts, each timed alone: noise + per-frame measurement + the"
                " estimator's loop (a lower bound for the fused study)",
                f"{_fmt(m['parts_ns_per_trajectory_step'])} ns per trajectory-step",
                f"the measurement alone {_fmt(m['measure_only_ns_per_frame'])} ns/frame over"
                f" {m['measure_frames']:,} frames ({m['measure_kernels']} kernels,"
                f" {_fmt(m['measure_bytes_per_frame'])} bytes moved per frame)",
                f"{_fmt(m['numpy_loop_ns_per_step'] / m['parts_ns_per_trajectory_step'])}x"
                " the NumPy loop",
                "<= 300 ns at batch 1,024",
                _met(m["parts_ns_per_trajectory_step"] <= 300 and m["batch"] >= 1024),
            )
        )
    o = r.get("one_trajectory", {})
    if "speedup_one_vs_numpy" in o:
        rows.append(
            (
                f"one trajectory, {o['samples']:,} steps, preprocessing + estimator"
                f" (`chunk={o.get('chunk')}`, `run(..., unroll={o.get('unroll', 1)})`)",
                f"{_fmt(o['visjax_one_s'] * 1e3)} ms",
                f"NumPy per-step loop {_fmt(o['numpy_loop_s'])} s",
                f"{_fmt(o['speedup_one_vs_numpy'])}x",
                ">= 150x",
                _met(o["speedup_one_vs_numpy"] >= 150),
            )
        )
    if "speedup_one_default_vs_numpy" in o:
        rows.append(
            (
                "the same with the defaults for batches (`chunk=256`, `unroll=1`)",
                f"{_fmt(o['visjax_one_default_s'] * 1e3)} ms",
                f"NumPy per-step loop {_fmt(o['numpy_loop_s'])} s",
                f"{_fmt(o['speedup_one_default_vs_numpy'])}x",
                ">= 150x",
                _met(o["speedup_one_default_vs_numpy"] >= 150),
            )
        )
    lr = r.get("long_run_memory", {})
    if "peak_rss_mb" in lr:
        rows.append(
            (
                f"{lr['long']['steps']:,}-step velocity run, peak resident memory",
                f"{_fmt(lr['peak_rss_mb'])} MB",
                f"the same process on {lr['reference']['steps']:,} steps "
                f"{_fmt(lr['reference']['peak_rss_mb'])} MB",
                f"+{_fmt(lr['extra_bytes_per_step'])} bytes/step",
                "< 500 MB at 10^6 steps",
                _met(lr["peak_rss_mb"] < 500 and lr["long"]["steps"] >= 1_000_000),
            )
        )
    g = r.get("gradient_uncalibrated", {})
    if "rss_peak_mb" in g:
        rows.append(
            (
                f"reverse-mode gradient, uncalibrated estimator, {g['duration_s']:g} s at 1 kHz"
                f" x {g['batch']} gain settings (`CheckpointAdjoint`)",
                f"{_fmt(g['rss_peak_mb'])} MB peak resident",
                f"the forward run alone {_fmt(g['rss_after_forward_mb'])} MB; "
                f"`DirectAdjoint` would need {_fmt(g['direct_xla']['temp_size_in_bytes'] / 2**20)}"
                " MB of buffers",
                f"{_fmt(g['rss_peak_over_forward'])}x the forward run",
                "< 4 GB at 30 s x 256",
                _met(g["rss_peak_mb"] < 4096 and g["duration_s"] >= 30 and g["batch"] >= 256),
            )
        )
    gs = r.get("gain_sweep", {})
    for row in gs.get("batches", []):
        if row["batch"] == 1 or "bare_update_ns_per_trajectory_step" not in row:
            continue
        rows.append(
            (
                f"shared-stream gain sweep, velocity estimator, batch {row['batch']:,} x"
                f" {gs['steps_per_trajectory']:,} steps (`run` with checks and a windowed RMS)",
                f"{_fmt(row['ns_per_trajectory_step'])} ns per trajectory-step,"
                f" {row['kernels_per_step']} kernels per step",
                f"the bare Euler update alone {_fmt(row['bare_update_ns_per_trajectory_step'])}"
                f" ns, {row['bare_update_kernels_per_step']} kernels"
                + (
                    "; the same output, RMS, bound test and freeze written by hand"
                    f" {_fmt(row['hand_fused_ns_per_trajectory_step'])} ns (batch last:"
                    f" {_fmt(row['hand_fused_batch_last_ns_per_trajectory_step'])} ns)"
                    if "hand_fused_ns_per_trajectory_step" in row
                    else ""
                ),
                f"{_fmt(row['ratio_to_bare_update'])}x the bare update"
                + (
                    f", {_fmt(row['ratio_to_hand_fused'])}x the loop written by hand"
                    if "ratio_to_hand_fused" in row
                    else ""
                ),
                "<= 10 ns at batch 1,024" if row["batch"] == 1024 else "(reported)",
                _met(row["ns_per_trajectory_step"] <= 10) if row["batch"] == 1024 else "-",
            )
        )
    vg = r.get("vs_gtsam", {})
    if "batch_speedup_vs_gtsam_loop" in vg:
        b = vg["batch"]
        rows.append(
            (
                f"bundle adjustment (Nath et al.'s scene), {b['gtsam_problems_solved']:,} noisy"
                " problems, `vmap`",
                f"{_fmt(1e3 * b['visjax_s_per_problem'])} ms/problem",
                f"GTSAM's Levenberg-Marquardt, a loop {_fmt(1e3 * b['gtsam_s_per_problem'])}"
                f" ms/problem; solutions equal to {vg['max_rel_diff_vs_gtsam']:.1e}",
                f"{_fmt(vg['batch_speedup_vs_gtsam_loop'])}x faster",
                "(reported)",
                "-",
            )
        )
    rh = r.get("robust_homography", {})
    for f in rh.get("fractions", []):
        if f["outlier_fraction"] not in (0.0, 0.4):
            continue
        v, cv = f["visjax"], f["opencv_ransac"]
        rows.append(
            (
                f"RANSAC homography, {rh['points']} points, {f['outlier_fraction']:.0%} outliers"
                f" (`find_homography_robust`, {rh['visjax_iterations']} hypotheses)",
                f"{_fmt(v['us_per_frame'])} µs/frame, corner error "
                f"{_fmt(v['corner_error_px_median'])} px",
                f"OpenCV RANSAC {_fmt(cv['us_per_frame'])} µs/frame, "
                f"{_fmt(cv['corner_error_px_median'])} px",
                f"{_fmt(cv['opencv_over_visjax'])}x",
                "(reported)",
                "-",
            )
        )
    c = r.get("compile_times", {})
    for row in c.get("results", []):
        rows.append(
            (
                f"compile time, {row['name']}",
                f"{_fmt(row['compile_s'])} s",
                f"a bare `lax.scan` of {row['steps']:,} steps {_fmt(row['bare_scan_compile_s'])} s",
                f"{_fmt(row['compile_over_bare_scan'])}x",
                "< 5 s",
                _met(row["compile_s"] < 5),
            )
        )
    lines = [
        f"Generated by `python benchmarks/run_all.py` from `benchmarks/results.json` "
        f"({results['machine']}, jax {results['jax']}, {results['date']}"
        f"{', QUICK sizes' if results.get('quick') else ''}).",
        "",
        "| figure | visjax | reference, same run | ratio | target | met |",
        "|---|---|---|---|---|---|",
    ]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    failed = [name for name, v in r.items() if "error" in v]
    if failed:
        lines += ["", f"Failed to run: {', '.join(failed)}."]
    return "\n".join(lines)


def write_table(results: dict, page: pathlib.Path = PERFORMANCE_PAGE) -> None:
    """Replace the table between the markers of `page` with `table(results)`."""
    text = page.read_text()
    if START not in text or END not in text:
        raise SystemExit(f"{page} has no {START} ... {END} markers.")
    head, rest = text.split(START, 1)
    _, tail = rest.split(END, 1)
    page.write_text(f"{head}{START}\n{table(results)}\n{END}{tail}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out",
        type=pathlib.Path,
        default=HERE / "results.json",
        help="the collected JSON (default benchmarks/results.json)",
    )
    parser.add_argument("--quick", action="store_true", help="small sizes: a smoke test")
    parser.add_argument(
        "--only", nargs="*", choices=list(BENCHMARKS), help="run these only, keep the others'"
    )
    parser.add_argument(
        "--table-only",
        action="store_true",
        help="run nothing: regenerate the table of docs/performance.md from --out",
    )
    parser.add_argument(
        "--no-table",
        "--no-readme",
        dest="no_table",
        action="store_true",
        help="leave docs/performance.md alone (--no-readme: the former name)",
    )
    args = parser.parse_args()
    if args.table_only:
        results = json.loads(args.out.read_text())
    else:
        import jax

        previous = json.loads(args.out.read_text()) if args.only and args.out.exists() else {}
        results = {
            "machine": f"{platform.machine()}, {os.cpu_count()} CPUs, {jax.devices()[0].platform}",
            "jax": jax.__version__,
            "date": datetime.date.today().isoformat(),
            "quick": args.quick,
            "benchmarks": previous.get("benchmarks", {}),
        }
        for name in args.only or BENCHMARKS:
            results["benchmarks"][name] = run_one(name, args.quick)
            args.out.write_text(json.dumps(results, indent=2) + "\n")
    print(json.dumps(results, indent=2))
    if not args.no_table:
        write_table(results)


if __name__ == "__main__":
    main()
