"""Users' plausible mistakes on the command line, one probe of each kind
(`benchmarks/user_probes.py --quick`: data files with transposed intrinsics, times in ms,
features never seen, most frames missing, huge gains, damaged or foreign files, complex
and object arrays, misspelt keys, a zip bomb; bad grids, seeds and chunks of the study
commands; videos that are not; a user's files in `--out`, another command's results there,
two runs into one folder, a signal mid-run): each ends in one clear error line or a named
result code, never a traceback nor silent garbage, and the user's files are never deleted
or mixed with a command's."""

import json
import pathlib
import subprocess
import sys

import pytest

SCRIPT = pathlib.Path(__file__).parents[1] / "benchmarks" / "user_probes.py"
# the script's outcomes that are bugs (`unclear_error`: a failure without its one line;
# `timeout`: a mistake that ran on past the probe's limit)
BAD = ("silent_garbage", "traceback", "failed_check", "unclear_error", "timeout")


@pytest.mark.slow
def test_quick_user_probes_end_clearly():
    done = subprocess.run(
        [sys.executable, str(SCRIPT), "--quick"],
        capture_output=True,
        text=True,
        timeout=1200,
    )
    assert done.returncode == 0, done.stderr[-4000:]
    report = json.loads(done.stdout)
    kinds = {p["kind"] for p in report["probes"]}
    assert len(report["probes"]) == len(kinds) >= 20  # one probe of each kind
    bad = {
        p["name"]: (p["outcome"], p["exit"], p.get("problems"), p["stderr_tail"])
        for p in report["probes"]
        if p["outcome"] in BAD
    }
    for outcome in BAD:
        assert report["counts"][outcome] == 0, bad
