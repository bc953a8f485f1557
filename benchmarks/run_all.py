"""Run the performance benchmarks and regenerate the performance table of the docs.

Each benchmark runs in its own process (its memory and compile times its own) and prints
one JSON document; this collects them under their names in `--out` (default
`benchmarks/results.json`), with the machine and versions, and then rewrites the table
between the markers `<!-- performance-table:start -->` and `<!-- performance-table:end -->`
in docs/performance.md from that file alone (`--table-only` redoes the table from an
existing file without running anything; `--no-table` leaves the page alone).

    python benchmarks/run_all.py [--quick] [--only NAME ...] [--table-only] [--no-table]
    python benchmarks/run_all.py --check [--only NAME ...]

`--quick` runs every benchmark on small sizes (a smoke test of the scripts, minutes);
the documented numbers come from a full run.

The file keeps each device's figures side by side under its name (`devices`: "cpu:
x86_64, 2 CPUs", "gpu: NVIDIA H200", `_device.device_name`); a run replaces the figures of
the device it runs on and keeps the others'. Timings are recorded as ratios against a
reference timed in the same run (`checked_ratios`: every number whose key names a
speedup, a ratio or an `_over_`), and `--check` re-measures them: it runs the benchmarks
again on this device, at the sizes recorded, and exits with 1 when a ratio is more than
`TOLERANCE` (25%) off the recorded one (or this device has none recorded), printing each
ratio then and now. A commit that changes a hot path updates the file from a run on the
same machine in the same session.
"""

import argparse
import datetime
import json
import os
import pathlib
import platform
import re
import subprocess
import sys

HERE = pathlib.Path(__file__).parent
PERFORMANCE_PAGE = HERE.parent / "docs" / "performance.md"
START, END = "<!-- performance-table:start -->", "<!-- performance-table:end -->"
GPU_PAGE = HERE.parent / "docs" / "gpu.md"
F32_START, F32_END = "<!-- float32-table:start -->", "<!-- float32-table:end -->"

# name: (script, full arguments, quick arguments)
BENCHMARKS = {
    "homography_decomposition": ("homography_decomposition.py", [], ["--frames", "2000"]),
    "one_trajectory": ("velocity_benchmark.py", [], ["--batch", "8", "--repeats", "2"]),
    "monte_carlo": (
        "monte_carlo.py",
        ["--batch", "1024"],
        ["--batch", "32", "--duration", "0.2", "--repeats", "1"],
    ),
    "monte_carlo_float32": (
        "monte_carlo.py",
        ["--batch", "1024", "--dtype", "float32"],
        ["--batch", "32", "--duration", "0.2", "--repeats", "1", "--dtype", "float32"],
    ),
    "long_run_memory": ("long_run_memory.py", [], ["--steps", "50000"]),
    "gradient_uncalibrated": (
        "gradient_uncalibrated.py",
        [],
        ["--duration", "1", "--batch", "8"],
    ),
    "compile_times": ("compile_times.py", [], []),
    "float32_accuracy": ("float32_accuracy.py", [], ["--seeds", "2", "--duration", "0.2"]),
    "sweep": (
        "sweep.py",
        ["--batches", "1", "1024", "16384", "--chunk", "16384", "--repeats", "2"],
        ["--batches", "1", "8", "--duration", "0.1", "--repeats", "1", "--chunk", "8"],
    ),
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


TOLERANCE = 0.25  # --check: the largest relative change of a recorded ratio
_RATIO = re.compile(r"(^|_)(speedup|ratio)(_|$)|_over_")
_ROW_ID = ("batch", "estimator", "outlier_fraction", "name")


def checked_ratios(result, prefix="") -> dict[str, float]:
    """The ratios `--check` compares, by a path label (`gain_sweep.batches[batch=1024].
    ratio_to_bare_update`): every number whose key names a speedup, a ratio or an
    `_over_` (a timing against a reference of the same run, or a memory figure against
    its reference), found anywhere in a benchmark's JSON."""
    out = {}
    if isinstance(result, dict):
        for k, v in result.items():
            if k in ("target", "targets", "command"):
                continue
            path = f"{prefix}.{k}" if prefix else k
            if isinstance(v, (int, float)) and not isinstance(v, bool) and _RATIO.search(k):
                out[path] = float(v)
            elif isinstance(v, (dict, list)):
                out.update(checked_ratios(v, path))
    elif isinstance(result, list):
        for i, v in enumerate(result):
            ident = next((f for f in _ROW_ID if isinstance(v, dict) and f in v), None)
            label = f"{prefix}[{ident}={v[ident]}]" if ident else f"{prefix}[{i}]"
            out.update(checked_ratios(v, label))
    return out


def check(recorded: dict, measured: dict, tolerance: float = TOLERANCE) -> list[dict]:
    """Each recorded ratio against the same ratio measured again: one row per ratio with
    `recorded`, `measured`, `change` (relative) and `ok` (within `tolerance`); a ratio
    missing from the new run, or a benchmark that failed, is a row that is not ok."""
    rows = []
    for name, old in recorded.items():
        new = measured.get(name)
        if new is None:
            continue  # not re-run (--only)
        if "error" in new:
            rows.append({"ratio": name, "recorded": None, "measured": None, "change": None,
                         "ok": False, "error": new["error"]})  # fmt: skip
            continue
        now = checked_ratios(new, name)
        for label, value in checked_ratios(old, name).items():
            got = now.get(label)
            change = None if got is None or value == 0 else (got - value) / abs(value)
            ok = change is not None and abs(change) <= tolerance
            rows.append({"ratio": label, "recorded": value, "measured": got,
                         "change": change, "ok": ok})  # fmt: skip
    return rows


def run_one(name, quick):
    script, full, small = BENCHMARKS[name]
    cmd = [sys.executable, str(HERE / script), *(small if quick else full)]
    print(f"[run_all] {' '.join(cmd[1:])}", file=sys.stderr, flush=True)
    out = subprocess.run(cmd, capture_output=True, text=True, env=os.environ.copy())
    if out.returncode != 0:
        return {"error": out.stderr.strip().splitlines()[-20:], "command": cmd[1:]}
    result = json.loads(out.stdout)
    result["command"] = " ".join(["python", f"benchmarks/{script}", *cmd[2:]])
    result["date"] = datetime.date.today().isoformat()  # each figure's own
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
    m32 = r.get("monte_carlo_float32", {})
    if "ns_per_trajectory_step" in m32:
        ns = m32["ns_per_trajectory_step"]
        rows.append(
            (
                f"the same study in float32 (`--dtype float32`), batch {m32['batch']:,}",
                f"{_fmt(ns)} ns per trajectory-step",
                f"the measurement alone {_fmt(m32['measure_only_ns_per_frame'])} ns/frame"
                f" ({m32['measure_kernels']} kernels, {_fmt(m32['measure_bytes_per_frame'])}"
                " bytes per frame)",
                f"{_fmt(m32['speedup_vs_numpy_loop'])}x the NumPy loop",
                "(reported)",
                "-",
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
                ">= 75x",
                _met(o["speedup_one_default_vs_numpy"] >= 75),
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
    sw = r.get("sweep", {})
    for row in sw.get("results", []):
        if "sweep_over_raw" not in row or row["batch"] < 1024:
            continue
        rows.append(
            (
                f"`studies.sweep` of the velocity problem, batch {row['batch']:,} x"
                f" {row['steps_per_trajectory']:,} steps ({row['dtype']}, noise and"
                " reconstruction per trajectory)",
                f"{_fmt(row['ns_per_trajectory_step'])} ns per trajectory-step",
                f"the same study written on the builders (`monte_carlo.raw_study`)"
                f" {_fmt(row['raw_ns_per_trajectory_step'])} ns",
                f"{_fmt(row['sweep_over_raw'])}x the raw study",
                "<= 1.3x at batch 131,072",
                _met(row["sweep_over_raw"] <= 1.3) if row["batch"] >= 131072 else "-",
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


def tables(results: dict) -> str:
    """One performance table per device of a results file (the CPU's first)."""
    if "devices" not in results:
        return table(results)
    names = sorted(results["devices"], key=lambda n: (not n.startswith("cpu"), n))
    parts = []
    for name in names:
        parts += [f"**{name}**", "", table(results["devices"][name]), ""]
    return "\n".join(parts).rstrip()


def float32_tables(results: dict) -> str:
    """docs/gpu.md's float32 tables: `float32_accuracy.py`'s, each device's that has one."""
    from float32_accuracy import markdown

    parts = []
    for name, record in (results.get("devices") or {}).items():
        f = record.get("benchmarks", {}).get("float32_accuracy", {})
        if "rows" in f:
            parts += [f"Measured on {name} ({f['seeds']} keys, {f['duration_s']} s scenes,"
                      f" {record['date']}):", "", markdown(f["rows"])]  # fmt: skip
    return "\n".join(parts).rstrip() or "(not measured)"


def _replace_between(page: pathlib.Path, start: str, end: str, body: str) -> None:
    text = page.read_text()
    if start not in text or end not in text:
        raise SystemExit(f"{page} has no {start} ... {end} markers.")
    head, rest = text.split(start, 1)
    _, tail = rest.split(end, 1)
    page.write_text(f"{head}{start}\n{body}\n{end}{tail}")


def write_table(results: dict, page: pathlib.Path = PERFORMANCE_PAGE) -> None:
    """Replace the tables between the markers of `page` with `tables(results)`, and those
    of docs/gpu.md with `float32_tables(results)`."""
    _replace_between(page, START, END, tables(results))
    _replace_between(GPU_PAGE, F32_START, F32_END, float32_tables(results))


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
    parser.add_argument(
        "--check",
        action="store_true",
        help=f"re-measure the recorded ratios of this device; exit 1 if one is more than "
        f"{TOLERANCE:.0%} off (nothing is written)",
    )
    args = parser.parse_args()
    if args.table_only:
        results = json.loads(args.out.read_text())
        print(json.dumps(results, indent=2))
        if not args.no_table:
            write_table(results)
        return 0
    import jax

    sys.path.insert(0, str(HERE))
    from _device import device_name

    device = device_name()
    stored = json.loads(args.out.read_text()) if args.out.exists() else {}
    devices = dict(stored.get("devices", {}))
    if "benchmarks" in stored:  # the one-device layout of earlier files: its CPU record
        devices.setdefault(_legacy_device(stored), dict(stored))
    mine = devices.get(device)
    if args.check:
        if mine is None:
            print(f"[run_all] no figures recorded for {device!r} in {args.out}: run without "
                  "--check first", file=sys.stderr)  # fmt: skip
            return 1
        names = [n for n in (args.only or mine["benchmarks"]) if n in BENCHMARKS]
        measured = {n: run_one(n, mine.get("quick", False)) for n in names}
        rows = check({n: mine["benchmarks"][n] for n in names if n in mine["benchmarks"]},
                     measured)  # fmt: skip
        print(json.dumps({"device": device, "tolerance": TOLERANCE, "ratios": rows}, indent=2))
        bad = [r for r in rows if not r["ok"]]
        for r in bad:
            print(f"[run_all] {r['ratio']}: recorded {r['recorded']}, now {r['measured']}",
                  file=sys.stderr)  # fmt: skip
        return 1 if bad or not rows else 0
    previous = mine if (args.only and mine) else {}
    record = {
        "machine": f"{platform.machine()}, {os.cpu_count()} CPUs, {jax.devices()[0].platform}",
        "device": device,
        "jax": jax.__version__,
        "date": datetime.date.today().isoformat(),
        "quick": args.quick,
        "benchmarks": dict(previous.get("benchmarks", {})),
    }
    devices[device] = record
    results = {"devices": devices}
    for name in args.only or BENCHMARKS:
        record["benchmarks"][name] = run_one(name, args.quick)
        args.out.write_text(json.dumps(results, indent=2) + "\n")
    print(json.dumps(results, indent=2))
    if not args.no_table:
        write_table(results)
    return 0


def _legacy_device(stored: dict) -> str:
    """The device name of a file of the one-device layout ("x86_64, 2 CPUs, cpu")."""
    machine = stored.get("machine", "")
    parts = [p.strip() for p in machine.split(",")]
    if len(parts) == 3 and parts[2] == "cpu":
        return f"cpu: {parts[0]}, {parts[1]}"
    return machine or "unknown"


if __name__ == "__main__":
    sys.exit(main())
