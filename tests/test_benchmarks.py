"""The benchmarks' own logic: `run_all.py --check` (each recorded ratio against the same
ratio measured again, 25% allowed) and the device and dtype every benchmark records
(issue 47). The scripts themselves run in the slow tier, at their smallest sizes."""

import json
import os
import pathlib
import subprocess
import sys

import jax
import pytest

BENCH = pathlib.Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.append(str(BENCH))  # after the installed packages: its names shadow none

import _device  # noqa: E402
import run_all  # noqa: E402

RECORD = {
    "one_trajectory": {"speedup_one_vs_numpy": 160.0, "visjax_one_s": 0.0086, "samples": 10000},
    "gain_sweep": {
        "duration_s": 1.0,
        "batches": [
            {"batch": 1, "ratio_to_bare_update": 23.0, "gtsam_iterations": 5},
            {"batch": 1024, "ratio_to_bare_update": 3.1, "ratio_to_hand_fused": 1.1},
        ],
        "target": {"ratio": 10.0},
    },
}


def test_checked_ratios_are_the_ratios_and_only_they():
    found = run_all.checked_ratios(RECORD)
    assert found == {
        "one_trajectory.speedup_one_vs_numpy": 160.0,
        "gain_sweep.batches[batch=1].ratio_to_bare_update": 23.0,
        "gain_sweep.batches[batch=1024].ratio_to_bare_update": 3.1,
        "gain_sweep.batches[batch=1024].ratio_to_hand_fused": 1.1,
    }  # no timing in seconds, no duration, no iteration count, nothing under `target`


def test_check_fails_a_ratio_more_than_25_percent_off_and_only_that():
    measured = json.loads(json.dumps(RECORD))
    measured["one_trajectory"]["speedup_one_vs_numpy"] = 130.0  # -18.75%: within
    measured["gain_sweep"]["batches"][1]["ratio_to_bare_update"] = 3.1 * 1.26  # +26%: out
    del measured["gain_sweep"]["batches"][1]["ratio_to_hand_fused"]  # missing: out
    rows = {r["ratio"]: r for r in run_all.check(RECORD, measured)}
    assert rows["one_trajectory.speedup_one_vs_numpy"]["ok"]
    assert rows["one_trajectory.speedup_one_vs_numpy"]["change"] == pytest.approx(-0.1875)
    assert rows["gain_sweep.batches[batch=1].ratio_to_bare_update"]["ok"]
    assert not rows["gain_sweep.batches[batch=1024].ratio_to_bare_update"]["ok"]
    assert not rows["gain_sweep.batches[batch=1024].ratio_to_hand_fused"]["ok"]
    failed = run_all.check(RECORD, {"one_trajectory": {"error": ["Traceback ..."]}})
    assert [r["ok"] for r in failed] == [False]


def test_results_file_keeps_each_devices_figures_with_its_ratios():
    results = json.loads((BENCH / "results.json").read_text())
    assert set(results) == {"devices"}
    for name, record in results["devices"].items():
        assert record["device"] == name and name.split(":")[0] in ("cpu", "gpu", "cuda", "tpu")
        assert run_all.checked_ratios(record["benchmarks"])  # something --check can compare
    page = (BENCH.parent / "docs" / "performance.md").read_text()
    assert run_all.tables(results) in page  # the page's tables are generated from the file
    gpu = (BENCH.parent / "docs" / "gpu.md").read_text()
    assert run_all.float32_tables(results) in gpu


def test_device_fields_name_the_device_and_the_dtype():
    fields = _device.device_fields("float32")
    assert set(fields) == {"device", "platform", "device_kind", "dtype"}
    assert fields["dtype"] == "float32" and fields["device"].startswith(fields["platform"])
    with pytest.raises(ValueError, match="dtype"):
        _device.use_dtype("float16")


@pytest.mark.slow
@pytest.mark.parametrize("dtype", ["float64", "float32"])
@pytest.mark.parametrize(
    "script, args",
    [
        ("monte_carlo.py", ["--batch", "8", "--duration", "0.05", "--repeats", "1"]),
        ("gain_sweep.py", ["--batches", "1", "8", "--duration", "0.05", "--repeats", "1"]),
        ("sweep.py", ["--batches", "4", "--duration", "0.05", "--repeats", "1", "--chunk", "4"]),
    ],
)
def test_benchmark_json_records_device_and_dtype(script, args, dtype):
    env = dict(os.environ, JAX_PLATFORMS=os.environ.get("JAX_PLATFORMS", "cpu"))
    out = subprocess.run(
        [sys.executable, str(BENCH / script), *args, "--dtype", dtype],
        capture_output=True, text=True, env=env, check=False, timeout=900,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-3000:]
    result = json.loads(out.stdout)
    assert result["dtype"] == dtype
    assert result["device"] == _device.device_name()  # the tests' own device, any backend
    assert result["platform"] == jax.devices()[0].platform
    for row in result.get("results", []):  # sweep.py: per batch, and its runner overhead
        assert row["dtype"] == dtype and row["sweep_over_raw"] > 0
