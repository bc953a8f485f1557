"""`docs/your-own-data.md` as a user follows it: every code block of the page runs as
written, in order, in a fresh folder (the example files made by its first command, a
rendered video standing in for `plate.mp4`), and says what the page says it does. A block
that cannot run as written (a placeholder name) is listed in `ILLUSTRATIVE` with why; a
block in neither is a failure, so that a new recipe is run too."""

import json
import pathlib
import re
import shlex
import shutil
import subprocess
import sys

import numpy as np
import pytest

from visjax.frontend import Plane, render_planes, textured_table, write_video

pytestmark = pytest.mark.slow  # the three example files, four commands, two compiles

ROOT = pathlib.Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "your-own-data.md"
ILLUSTRATIVE = {  # the first line of a block -> why it is not run
    'np.savez("tracks.npz", pixels=int_pixels, missing_value=0, **other_keys)': "placeholders",
    'np.savez("log.npz", t=stamps_ns, time_unit="ns", **other_keys)': "placeholders",
    "visjax track VIDEO --out tracks.npz      # or --out tracks.csv": "VIDEO: the user's file",
}


def _blocks():
    text = PAGE.read_text()
    return re.findall(r"```(\w+)\n(.*?)```", text, flags=re.S)


def _plate_video(path):
    """30 Hz, 2 s of a textured plate moving before a fixed camera (the user's recording)."""
    K = np.array([[300.0, 0.0, 159.5], [0.0, 300.0, 119.5], [0.0, 0.0, 1.0]])
    texture = textured_table((160, 200), seed=3)
    frames = []
    for k in range(61):
        t = k / 30.0
        T = np.eye(4)
        T[:3, 3] = [-0.2 + 0.05 * t, -0.15, 0.9 + 0.05 * t]
        frames.append(render_planes([Plane(texture, 0.002, T)], K, np.eye(3), np.zeros(3),
                                    (240, 320)))  # fmt: skip
    write_video(path, np.stack(frames), 30.0)


def _shell(line, cwd):
    argv = shlex.split(line, comments=True)
    if argv[0] == "python":
        argv[0] = sys.executable
    return subprocess.run(argv, cwd=cwd, capture_output=True, text=True, timeout=900)


def test_the_page_runs_as_written(tmp_path):
    (tmp_path / "examples").mkdir()
    shutil.copy(ROOT / "examples" / "make_example_data.py", tmp_path / "examples")
    _plate_video(tmp_path / "plate.mp4")
    ran = []
    for language, body in _blocks():
        first = body.strip().splitlines()[0]
        if first in ILLUSTRATIVE:
            continue
        if language == "yaml":  # the camera file the next command reads
            name = re.match(r"#\s*(\S+)", first)[1]
            (tmp_path / name).write_text(body)
        elif language == "bash":
            for line in [ln for ln in body.splitlines() if ln.strip()]:
                done = _shell(line, tmp_path)
                # the page: the velocity example's estimate is worse than zero velocity,
                # reported with exit status 1 and its files kept
                words = " ".join(shlex.split(line, comments=True))
                expected = 1 if words.startswith("visjax run velocity --data examples") else 0
                assert done.returncode == expected, (line, done.stdout[-2000:], done.stderr)
                ran.append(line)
        elif language == "python":
            done = subprocess.run([sys.executable, "-c", body], cwd=tmp_path,
                                  capture_output=True, text=True, timeout=900)  # fmt: skip
            assert done.returncode == 0, (first, done.stderr[-3000:])
            ran.append(first)
            if "Z RMS over the second half" in body:  # the recipe equals the command
                printed = float(re.search(r"second half: ([\d.]+) mm", done.stdout)[1])
                summary = json.loads((tmp_path / "results/moving_point/summary.json").read_text())
                assert printed == pytest.approx(1e3 * summary["metrics"]["rms"][2], rel=0.1)
        else:
            pytest.fail(f"a {language} block the test does not know how to run: {first!r}")
    velocity = json.loads((tmp_path / "results/velocity/summary.json").read_text())
    assert velocity["result"] == "worse_than_trivial"  # as the page says
    assert (tmp_path / "results/plate/estimates.parquet").is_file()
    assert len(ran) >= 10, ran
