"""The command line's output folders: a user's file inside `--out` survives a run, two
concurrent runs into one `--out` (the second refused in one line), SIGINT and SIGTERM
(one line, no traceback, no staging folder left)."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from visjax.cli import main
from visjax.io._staging import MANIFEST, staged_output

ROOT = Path(__file__).resolve().parents[1]


def test_a_users_file_inside_out_survives_runs(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    argv = ["geometry", "--scenes", "3", "--quiet", "--out", str(out)]
    assert main(argv) == 0
    assert main(argv) == 0  # the same command again: its own files replaced
    assert (out / "notes.txt").read_text() == "mine"
    assert (out / "summary.json").exists() and (out / MANIFEST).exists()
    assert not [p for p in out.iterdir() if p.name.startswith(".visjax-stage")]
    # another command's results: refused in one line (exit 2) unless --force
    capsys.readouterr()
    assert main(["reproduce", "--quick", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "results of `visjax geometry`" in err and "--force" in err


def test_a_second_run_into_the_same_out_is_refused(tmp_path, capsys):
    out = tmp_path / "out"
    with staged_output(out, command="geometry"):  # a run in progress (this process)
        assert main(["geometry", "--scenes", "3", "--quiet", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("visjax: error: --out") and "another visjax run" in err
    assert err.count("\n") == 1


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_prints_one_line_and_leaves_no_staging_folder(tmp_path, sig):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    argv = [sys.executable, "-m", "visjax.cli", "geometry", "--scenes", "100000"]
    argv += ["--quiet", "--out", str(out)]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(argv, cwd=ROOT, env=env, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not list(out.glob(".visjax-stage-*")):
        time.sleep(0.05)
    time.sleep(0.5)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    name = signal.Signals(sig).name
    assert proc.returncode == 128 + sig, err
    assert err == f"visjax: interrupted by {name}; nothing was written to --out\n", err
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]
