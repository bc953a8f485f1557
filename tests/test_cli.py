import json
import shlex
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

import visjax
from tests.helpers import (
    check_outputs,
    check_testbed_tracking,
    figure_faults,
    twin_kinematics_residual,
)
from visjax import _options, studies
from visjax.cli import build_parser, main
from visjax.io import read_summary
from visjax.papers.chitrakaran import AXES, K_EQ63


def _summary(folder) -> dict:
    """A command's summary.json, loaded with pandas and checked against its schema."""
    return read_summary(Path(folder) / "summary.json").to_dict()


@pytest.fixture
def saved_figures(monkeypatch):
    """Every figure a command saves, checked as it is saved (`figure_faults`: nothing off
    the canvas, units on the axes): path -> what is wrong (empty when nothing)."""
    import matplotlib.figure

    checked = {}
    savefig = matplotlib.figure.Figure.savefig

    def checked_savefig(fig, fname, *args, **kwargs):
        if str(fname) not in checked:
            checked[str(fname)] = figure_faults(fig)
        return savefig(fig, fname, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", checked_savefig)
    return checked


# The commands' end-to-end tests share the small settings of `reproduce`'s smoke test (its
# jobs are the commands), and stay in this module: `pytest --dist loadfile` runs a module
# in one worker, so each job is traced and compiled once for all of them.
TESTBED_S = 4.0


def test_reproduce_smoke_every_output_loads_with_its_schema(
    tmp_path, monkeypatch, capsys, saved_figures
):
    """`visjax reproduce` on the small settings of the commands' tests below (the full
    `--quick` run is a slow test of `tests/test_outputs.py`): every job runs, every output
    follows its schema, and the table has one number per row. Its figures as SVG (a quarter
    of the time of 300-dpi PNGs; the commands' own tests below write PNGs), every one with
    its labels on the canvas and units on its axes."""
    import dataclasses
    import functools

    from visjax.studies import _reproductions, registered_reproduction

    small = {
        "velocity": dict(duration=1.0),
        "geometry": dict(scenes=5),
        "moving_point": dict(duration=2.0, sets=["I.1", "II.2"]),
        "static_points": dict(duration=2.0),
        "testbed": dict(sets=["I.1"], duration=TESTBED_S, studies=False),
        "point_depth": dict(duration=2.0),  # the settings of tests/papers/test_spica.py
        "homography": dict(seeds=1, duration=0.2),
    }
    for name, options in small.items():
        entry = registered_reproduction(name)
        run = functools.partial(entry.run, **options)
        monkeypatch.setitem(
            _reproductions._REPRODUCTIONS, name, dataclasses.replace(entry, run=run)
        )
    out = tmp_path / "results"
    assert main(["reproduce", "--quick", "--quiet", "--format", "svg", "--out", str(out)]) == 0
    kinds = check_outputs(out)
    assert sorted(kinds.values()) == sorted(
        ["reproduce", "velocity", "geometry", "moving_point", "static_points", "testbed"]
        + ["point_depth", "homography"]
    )
    # the settings name the folder the user asked for, not the staging folder written first
    assert read_summary(out / "summary.json")["settings"]["out"] == str(out)
    table = pd.read_parquet(out / "summary.parquet")
    assert table["value"].dtype == np.float64 and len(table) >= 6
    # the reference is a number, its kind in its own column
    assert table["reference"].dtype == np.float64 and table["reference"].notna().all()
    assert list(table.columns) == ["name", "value", "reference", "reference_kind", "unit"]
    assert set(table["reference_kind"]) == {"published", "truth", "bound", "OpenCV", "ideal"} | {
        "trivial"
    }
    assert table.loc[table["name"].str.contains("z1"), "reference_kind"].tolist() == ["truth"]
    assert "summary" in capsys.readouterr().out
    figures = sorted(p.relative_to(out).as_posix() for p in out.rglob("*.svg"))
    assert len(figures) == 10 and not list(out.rglob("*.png")), figures
    assert len(saved_figures) == 10 and not any(saved_figures.values()), saved_figures


RUN_FIGURES = {  # every registered problem, on short settings
    "velocity": ["--duration", "1"],
    "moving_point": ["--set", "II.3", "--duration", "2"],
    "static_points": ["--duration", "2"],
    "point_depth": ["--duration", "2"],
    "homography": ["--duration", "0.2"],
}


def test_the_run_figures_checked_are_every_registered_problems():
    assert sorted(RUN_FIGURES) == studies.problem_names()


@pytest.mark.slow  # five problems built and compiled (the unit tier's time)
@pytest.mark.parametrize("problem", sorted(RUN_FIGURES))
def test_every_problems_run_figure_keeps_its_labels_on_the_canvas(problem, tmp_path, saved_figures):
    """`visjax run PROBLEM` for every registered problem: its figure (`run.svg`, the
    problem's own `figure`) has nothing off the canvas and a unit on every axis."""
    out = tmp_path / problem
    argv = ["run", problem, *RUN_FIGURES[problem], "--noise", "0.1", "--format", "svg", "--quiet"]
    assert main([*argv, "--out", str(out)]) in (0, 1)  # 1: a run whose verdict failed
    [(path, faults)] = saved_figures.items()  # written in a staging folder, then moved
    assert path.endswith("run.svg") and faults == [], (path, faults)
    assert len(list(out.rglob("run.svg"))) == 1


@pytest.mark.slow  # two baselines compiled
@pytest.mark.parametrize(
    "problem, method, columns",
    [
        ("point_depth", "least_squares", ["depth_0", "depth_0_true", "depth_std_0"]),
        ("homography", "dlt", ["H_11", "H_33"]),
    ],
)
def test_a_baseline_whose_solution_is_its_own_module_writes_its_table(
    problem, method, columns, tmp_path
):
    """`visjax run PROBLEM --method M` for a per-frame baseline (its solution a Module of
    its own, without `outputs`): its fields are the table's columns, with the truth beside
    them where the problem knows it (this crashed before: no `outputs`)."""
    out = tmp_path / method
    argv = ["run", problem, "--duration", "0.3", "--method", method, "--quiet"]
    assert main([*argv, "--out", str(out)]) in (0, 1)
    table = pd.read_parquet(out / "estimates.parquet")
    assert set(columns) <= set(table.columns) and len(table) > 1, table.columns


@pytest.mark.slow  # every method of a problem once more, for the recording
def test_compare_writes_a_rerun_recording_of_each_method(tmp_path):
    """`visjax compare --rerun`: read back with Rerun's own reader, each method's run of
    the first seed is there, its estimate and the truth of every saved output column."""
    pytest.importorskip("rerun")
    from rerun.chunk import RrdReader

    rrd = tmp_path / "cmp.rrd"
    argv = ["compare", "point_depth", "--duration", "0.5", "--seeds", "1", "--noise", "0.5"]
    assert main([*argv, "--quiet", "--rerun", str(rrd)]) in (0, 1)
    rows = {}
    for chunk in RrdReader(rrd).stream():
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    problem = studies.problem("point_depth", duration=0.5)
    for method in problem.methods:
        mine = [e for e in rows if e.startswith(f"/point_depth/{method}/estimate/")]
        assert mine and all(rows[e] > 1 for e in mine), (method, sorted(rows))
    assert any(e.startswith("/point_depth/estimator/truth/") for e in rows)


def test_geometry_command_writes_summary_and_figure(tmp_path, capsys):
    assert main(["geometry", "--scenes", "5", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "visjax median" in printed and "OpenCV median" in printed
    summary = _summary(tmp_path)
    err = summary["errors"]
    # noise-free: visjax recovers ground truth to float64 precision, OpenCV to its float32
    # point conversion
    assert err["visjax"]["R_bar_deg"]["max"] < 1e-9
    assert err["visjax"]["alpha_rel"]["max"] < 1e-12
    assert err["opencv"]["alpha_rel"]["max"] < 1e-4
    assert (tmp_path / "geometry.png").stat().st_size > 10_000


BAD_OPTIONS = [
    ["geometry", "--points", "3"],
    ["geometry", "--scenes", "0"],
    ["geometry", "--noise", "-1"],
    ["geometry", "--scenes", "many"],
    ["velocity", "--duration", "-1"],
    ["velocity", "--duration", "0"],
    ["velocity", "--duration", "nan"],
    ["velocity", "--duration", "inf"],
    ["velocity", "--rate", "0"],
    ["velocity", "--rate", "-5"],
    ["velocity", "--noise", "-1"],
    ["velocity", "--noise", "nan"],
    ["velocity", "--duration", "0.001"],
    ["velocity", "--K", "1 2 3"],
    ["velocity", "--rho", "1 1 1 1 1 nan"],
    ["velocity", "--seed", "-3"],
    ["sweep", "velocity", "--grid", "K=1:2"],
    ["sweep", "velocity", "--grid", "K=0:1:3"],
    ["sweep", "velocity", "--set", "I.1"],
    ["sweep", "structure", "--set", "III.9"],
    ["tune", "structure", "--rate", "30"],
    ["tune", "velocity", "--steps", "0"],
    ["compare", "moving_point", "--robust"],
    ["structure", "--set", "III.9"],
    ["structure", "--duration", "0"],
    ["structure", "--noise", "-0.1"],
    ["euclidean", "--noise-px", "-1"],
    ["euclidean", "--duration", "-2"],
    ["reproduce", "--bogus"],
]


@pytest.mark.parametrize("argv", BAD_OPTIONS, ids=" ".join)
def test_bad_options_give_one_line_and_exit_2(argv, capsys, tmp_path):
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as e:
        main(argv + ["--out", str(out)])
    assert e.value.code == 2
    err = capsys.readouterr().err
    if argv[1:2] == ["structure"]:  # the old name is one warning line first
        note, err = err.split("\n", 1)
        assert (
            note == "warning: the problem name 'structure' is deprecated: it is now 'moving_point'"
        )
    assert err.startswith("visjax: error:") and err.count("\n") == 1, err
    assert "Traceback" not in err
    assert not out.exists()


def test_out_that_is_a_file_is_refused_before_any_work(capsys, tmp_path):
    target = tmp_path / "a_file"
    target.write_text("keep me")
    with pytest.raises(SystemExit) as e:
        main(["velocity", "--out", str(target)])
    assert e.value.code == 2 and "not a folder" in capsys.readouterr().err
    assert target.read_text() == "keep me"


def test_a_failing_command_leaves_nothing_behind(tmp_path, monkeypatch, capsys):
    import dataclasses

    from visjax.studies import _reproductions, registered_reproduction

    def half_written(out=None, **kwargs):
        (Path(out) / "summary.json").write_text("{}")
        raise RuntimeError("the simulation failed")

    entry = dataclasses.replace(registered_reproduction("static_points"), run=half_written)
    monkeypatch.setitem(_reproductions._REPRODUCTIONS, "static_points", entry)
    out = tmp_path / "out"
    assert main(["euclidean", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err == "visjax: error: the simulation failed\n"  # one line, no traceback
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []  # no staging folder either


def test_velocity_command(tmp_path, capsys):
    assert main(["velocity", "--duration", "1", "--quiet", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "RMS" in printed and "vz" in printed
    summary = _summary(tmp_path)
    for key in ("rms_window", "max_window"):
        assert len(summary[key]) == 6
    assert summary["window_s"] == [0.5, 1.0]  # the paper's 5-10 s, shrunk into 1 s
    assert max(summary["rms_window"]) < 0.1  # noise-free: already in the chattering band
    assert abs(summary["z1_star_recovered"] - 1.99) < 1e-8
    assert (tmp_path / "velocity.png").stat().st_size > 20_000
    # what was run is recorded: version, every option, the seed (none: noise-free), time
    assert summary["kind"] == "velocity" and summary["visjax_version"] == visjax.__version__
    assert summary["settings"]["duration"] == 1.0 and summary["settings"]["K"][0] == 300.0
    assert summary["seed"] is None and summary["wall_time_s"] > 0
    estimate = np.load(tmp_path / "estimate.npz")
    assert estimate["v_hat"].shape == estimate["velocity"].shape == (1000, 6)


def test_velocity_rejects_bad_gains(capsys):
    with pytest.raises(SystemExit):
        main(["velocity", "--K", "1 2 3"])
    assert "six positive numbers" in capsys.readouterr().err


def test_structure_command(tmp_path, capsys):
    assert (
        main(
            [
                "structure",
                "--set",
                "I.1",
                "--set",
                "II.2",
                "--duration",
                "2",
                "--quiet",
                "--out",
                str(tmp_path),
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert "Table 5-3" in printed and "Table 5-4" in printed
    summary = _summary(tmp_path)
    assert set(summary["sets"]) == {"I.1", "II.2"} and summary["seed"] == 0
    assert len(summary["sets"]["II.2"]["rms"]) == 3
    assert max(summary["sets"]["I.1"]["rms"]) < 0.05  # metres, static point, 0.1 px
    assert (tmp_path / "structure_I.1.png").stat().st_size > 20_000
    # the thesis' camera-velocity figures (Figs. 5-5/5-6 and their like), m/s and rad/s
    assert (tmp_path / "camera_velocity_II.2.png").stat().st_size > 10_000


def test_euclidean_command(tmp_path, capsys):
    """Two noise seeds, vector figures only: the final errors are the seeds' medians (of two:
    their mean), each seed's beside them, and the estimates over time have a seed axis."""
    argv = ["euclidean", "--duration", "2", "--noise", "0.3", "--seeds", "2"]
    assert main([*argv, "--quiet", "--format", "svg,pdf", "--out", str(tmp_path)]) == 0
    assert "final position error" in capsys.readouterr().out
    summary = _summary(tmp_path)
    assert len(summary["final_position_error_m"]) == 4 and summary["seeds"] == 2
    assert max(summary["final_position_error_m"]) < 0.2  # from 10-16 cm, 2 s in
    per_seed = np.array(summary["final_position_error_m_seeds"])
    np.testing.assert_allclose(summary["final_position_error_m"], per_seed.mean(0), rtol=1e-12)
    # vector figures only, as asked; the estimates over time beside the truth
    assert (tmp_path / "euclidean.svg").read_bytes()[:5] == b"<?xml"
    assert (tmp_path / "euclidean.pdf").read_bytes()[:4] == b"%PDF"
    assert not (tmp_path / "euclidean.png").exists()
    estimate = np.load(tmp_path / "estimate.npz")
    assert estimate["features"].shape[0] == 2
    assert estimate["features"].shape[2:] == estimate["truth"].shape == (4, 3)
    final = np.linalg.norm(estimate["features"][:, -1] - estimate["truth"], axis=-1)
    np.testing.assert_allclose(final, per_seed, rtol=1e-12)


def test_one_option_vocabulary_and_version(capsys):
    parser = build_parser()
    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert (
        done.value.code == 0 and capsys.readouterr().out.strip() == f"visjax {visjax.__version__}"
    )
    # the same options with the same meaning wherever they apply
    for argv in (
        ["velocity"], ["structure"], ["euclidean"], ["geometry"],
        ["compare", "velocity"], ["sweep", "velocity"], ["tune", "velocity"],
    ):  # fmt: skip
        a = parser.parse_args([*argv, "--noise", "0.3", "--seed", "7", "--format", "pdf"])
        assert (a.noise, a.seed, a.format, a.quiet, a.out) == (0.3, 7, ["pdf"], False, None)
    for argv in (["velocity"], ["structure"], ["euclidean"], ["compare", "velocity"]):
        assert parser.parse_args([*argv, "--data", "x.npz"]).data == "x.npz"
    # the old name of euclidean's noise option still works
    assert parser.parse_args(["euclidean", "--noise-px", "0.2"]).noise == 0.2
    # the commands' names before version 0.3 are aliases of the problems' names
    assert parser.parse_args(["euclidean"]).command == "static_points"
    assert parser.parse_args(["structure"]).command == "moving_point"
    # the testbed's switches, and track's positional video, keep their own meanings
    tb = parser.parse_args(["testbed", "--no-video"])
    assert (tb.video, tb.studies) == (False, True)
    assert parser.parse_args(["track", "v.mp4", "--out", "t.npz"]).video == "v.mp4"
    with pytest.raises(SystemExit):
        main(["velocity", "--format", "png,jpeg"])
    assert "png, pdf, svg" in capsys.readouterr().err
    # --quick says what it changes
    quick = next(
        a for a in parser._subparsers._group_actions[0].choices["reproduce"]._actions
        if a.dest == "quick"
    )  # fmt: skip
    assert "geometry: 20 scenes, not 100" in quick.help and "velocity: in full" in quick.help
    assert "point_depth: 1.5 s" in quick.help and "homography: 2 seeds" in quick.help
    assert "seed 0" not in parser.format_help()


def test_every_help_ends_with_examples_that_parse():
    """Each command's `--help` ends with two or three examples (`visjax --help` with
    three), and each example parses with the command line's own parser and checks."""
    parser = build_parser()
    commands = parser._subparsers._group_actions[0]
    names = {name for name, p in commands.choices.items() if commands.choices[name] is p}
    aliases = {"structure", "euclidean"}
    assert set(_options.EXAMPLES) == {None} | (names - aliases)
    for name, lines in _options.EXAMPLES.items():
        assert 2 <= len(lines) <= 3, name
        sub = parser if name is None else commands.choices[name]
        assert sub.format_help().rstrip().endswith(lines[-1]), name
        for line in lines:
            argv = shlex.split(line)
            assert argv[0] == "visjax" and (name is None or argv[1] == name), line
            args = parser.parse_args(argv[1:])
            assert args.command == argv[1], line


def test_read_only_out_is_refused_before_any_work(capsys, tmp_path, monkeypatch):
    """A folder without write permission. As root every folder is writable, so the
    permission check is made to read the mode bits, as it would for any other user."""
    import os
    import stat

    from visjax.io import _staging

    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    real_access = os.access

    def access_as_a_user(path, mode):
        if Path(path) == locked:
            return bool(locked.stat().st_mode & stat.S_IWUSR) and real_access(path, mode)
        return real_access(path, mode)

    monkeypatch.setattr(_staging.os, "access", access_as_a_user)
    for out in (locked, locked / "new"):
        with pytest.raises(SystemExit) as e:
            main(["velocity", "--out", str(out)])
        assert e.value.code == 2
        err = capsys.readouterr().err
        assert err.startswith("visjax: error:") and "is not writable" in err, err
    assert list(locked.iterdir()) == []
    locked.chmod(0o755)


def _estimates(folder, columns):
    """The named columns of a `run`'s `estimates.parquet` (one column per number)."""
    table = pd.read_parquet(Path(folder) / "estimates.parquet")
    return table["t"].to_numpy(), table[list(columns)].to_numpy()


@pytest.mark.slow
def test_a_slow_file_gives_one_estimate_by_every_route(tmp_path, capsys):
    """A velocity file sampled at 50 Hz, slower than eq. (63)'s Euler bound: `visjax
    velocity --data` and `visjax run velocity --data` are one route (the problem, its step
    chosen by `run`'s `dt="auto"` rule at its default gains) and give the same estimate;
    neither reports `unstable_step`. With `--filter-hz` the estimate is the unfiltered one
    through `estimators.lowpass` (an independent call on the saved outputs)."""
    import dataclasses

    from tests.example_data import velocity_example
    from visjax import io
    from visjax.estimators import lowpass, lowpass_delay

    data = velocity_example(duration=1.0, noise_px=0.0, dropout=0.0)
    fields = {f.name: getattr(data, f.name) for f in dataclasses.fields(data)}
    for name in ("t", "pixels", "velocity"):
        fields[name] = np.asarray(fields[name])[::20]  # 50 Hz
    path = io.VelocityData(**fields).save(tmp_path / "slow.npz")
    old, new, low = tmp_path / "velocity", tmp_path / "run", tmp_path / "low"
    codes = [
        main(["velocity", "--data", str(path), "--quiet", "--out", str(old)]),
        main(["run", "velocity", "--data", str(path), "--quiet", "--out", str(new)]),
        main(["velocity", "--data", str(path), "--quiet", "--out", str(low), "--filter-hz", "2"]),
    ]
    capsys.readouterr()
    for folder in (old, new):
        assert _summary(folder)["result"] in ("successful", "worse_than_trivial"), codes
    step = _summary(old)["problem_settings"]["integration_step_s"]
    assert 0 < step < 0.02 / 2  # a held step, half the bound at most
    assert _summary(new)["problem_settings"]["integration_step_s"] == step
    t, v_hat = _estimates(old, AXES)
    t_new, v_new = _estimates(new, AXES)
    np.testing.assert_array_equal(t_new, t)
    np.testing.assert_array_equal(v_new, v_hat)
    t_low, v_low = _estimates(low, AXES)
    np.testing.assert_array_equal(t_low, t)
    np.testing.assert_allclose(v_low, np.asarray(lowpass(t, v_hat, 2.0)), rtol=0, atol=1e-12)
    settings = _summary(low)["problem_settings"]
    assert settings["filter_hz"] == 2.0 and settings["filter_delay_s"] == lowpass_delay(2.0)


@pytest.mark.slow
def test_velocity_on_a_data_file(tmp_path, capsys):
    """`visjax velocity --data FILE` (`visjax run velocity --data FILE`) on the example
    scene (not the paper's): the recovered z1* and, since the file has the truth, the RMS
    over the second half; a bad file is one line."""
    from tests.example_data import velocity_example

    data = velocity_example(duration=1.0, noise_px=0.0)  # 2% of the features missing
    path = data.save(tmp_path / "v.npz")
    out = tmp_path / "out"
    assert main(["velocity", "--data", str(path), "--quiet", "--out", str(out)]) == 0
    summary = _summary(out)
    z1_true = 1.5 + (data.R_star @ data.s1)[2]  # the plate starts at x0 = [0.05, -0.03, 1.5]
    assert abs(summary["problem_settings"]["z1_star"] - z1_true) < 1e-9
    window = summary["problem_settings"]["window_s"]  # the second half (a float32 file)
    np.testing.assert_allclose(window, [0.4995, 0.999], rtol=1e-6)
    rms = summary["metrics"]["rms"]
    assert len(rms) == 6 and max(rms) < 0.05  # noise-free, 0.5-1 s: converging
    t, v_hat = _estimates(out, AXES)
    assert v_hat.shape == (1000, 6) and t[0] == 0.0
    quality = summary["quality"]  # against zero velocity over the same window
    assert quality["flag"] == "ok" and quality["ratio_to_trivial"] < 0.5, quality
    # the same frames with 0.1 px of noise: the sign-based law amplifies it past what
    # answering zero would give: the result says so (exit 1, its files kept)
    noisy = velocity_example(duration=1.0, noise_px=0.1).save(tmp_path / "noisy.npz")
    capsys.readouterr()
    out = tmp_path / "noisy"
    assert main(["velocity", "--data", str(noisy), "--quiet", "--out", str(out)]) == 1
    summary = _summary(out)
    assert summary["result"] == "worse_than_trivial" and summary["quality"]["ratio_to_trivial"] >= 1
    assert "the result is worse_than_trivial" in capsys.readouterr().err
    # without the truth: no errors reported
    data.velocity = None
    data.save(tmp_path / "v2.npz")
    capsys.readouterr()
    assert main(["velocity", "--data", str(tmp_path / "v2.npz"), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "rms" not in out and out.endswith(
        "nothing written (no --out DIR: the summary, tables and figures were not kept)\n"
    )
    bad = dict(np.load(path))
    del bad["A"]
    np.savez(tmp_path / "bad.npz", **bad)
    assert main(["velocity", "--data", str(tmp_path / "bad.npz"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("visjax: error:") and "'A'" in err and err.count("\n") == 1
    with pytest.raises(SystemExit):
        main(["velocity", "--data", str(tmp_path / "missing.npz")])


@pytest.mark.slow
def test_moving_and_static_points_on_data_files(tmp_path, capsys):
    """`visjax moving_point|static_points --data FILE` (`visjax run PROBLEM --data`) on the
    example scenes (not the papers'): gains designed / derived from the file alone, errors
    reported against its truth; `euclidean`, the old name, still works."""
    from tests.example_data import euclidean_example, structure_example

    path = structure_example(duration=6.0, noise_px=0.0).save(tmp_path / "s.npz")
    out = tmp_path / "s"
    assert main(["moving_point", "--data", str(path), "--quiet", "--out", str(out)]) == 0
    summary = _summary(out)
    assert summary["result"] == "successful" and len(summary["metrics"]["rms"]) == 3
    # depth guess 4 m for a target 2.5 m away; 3-6 s: within 1 cm (2.5 mm measured)
    assert summary["metrics"]["rms_worst"] < 0.01
    assert (out / "estimates.parquet").exists() and (out / "run.png").exists()

    path = euclidean_example(duration=10.0, noise_px=0.0).save(tmp_path / "e.npz")
    out = tmp_path / "e"
    assert main(["euclidean", "--data", str(path), "--quiet", "--out", str(out)]) == 0
    summary = _summary(out)
    assert summary["dropped_fraction"] > 0  # 2% of the features drop out
    errors = np.asarray(summary["metrics"]["error"])
    # 10 s of a 40 s convergence: from 0.1-0.5 m to a few cm, each at least halved
    table = pd.read_parquet(out / "estimates.parquet")
    start = np.array([[table[f"{c}_{i}"][0] for c in "XYZ"] for i in range(5)])
    initial = np.linalg.norm(start - np.load(path)["features"], axis=-1)
    assert len(errors) == 5 and errors.max() < 0.1 and np.all(errors < 0.5 * initial)
    assert "error_worst" in capsys.readouterr().out


@pytest.mark.slow
def test_compare_command_writes_records_that_load(tmp_path, capsys):
    import pandas as pd

    out = tmp_path / "cmp"
    argv = ["compare", "structure", "--duration", "4", "--seeds", "2", "--noise", "0.5"]
    assert main(argv + ["--quiet", "--out", str(out)]) == 0
    summary = _summary(out)
    table = pd.DataFrame(summary["records"])
    assert len(table) == 8 and set(table["seed"]) == {0, 1}
    assert set(table["method"]) == {"estimator", "batch", "batch_window", "ekf"}
    assert (table["result"] == "successful").all()
    assert (table["latency_s_per_sample"] > 0).all()
    rms = np.array(table["rms"].tolist())
    assert rms.shape == (8, 3) and np.all(np.isfinite(rms))
    # every method sees the same noisy frames, and they differ between seeds
    batch = table[table.method == "batch"]
    assert not np.allclose(rms[batch.index[0]], rms[batch.index[1]])
    assert pd.read_csv(out / "records.csv").shape[0] == 8
    assert (out / "comparison.png").stat().st_size > 0
    assert "batch_window" in capsys.readouterr().out
    with pytest.raises(SystemExit) as bad:
        main(["compare", "velocity", "--data", "x.npz", "--duration", "2"])
    assert bad.value.code == 2
    assert "--duration and --rate apply to the problem's scene" in capsys.readouterr().err


@pytest.mark.slow
def test_sweep_then_tune_commands(tmp_path, capsys):
    """`visjax sweep`, then `visjax tune` of the same problem (one process: the set-up and
    the compiled sweep are reused): the table, a flagged gain, strict JSON summaries, the
    tuned gains ten times better than eq. (63)'s on held-out seeds."""
    import pandas as pd

    grid = "K_scale=0.01/10,rho_scale=0.1/1"  # multipliers of eq. (63)'s gains
    common = ["velocity", "--grid", grid, "--duration", "2", "--seeds", "2"]
    sweep_out, tune_out = tmp_path / "sweep", tmp_path / "tune"
    assert main(["sweep", *common, "--quiet", "--out", str(sweep_out)]) == 0
    table = pd.read_parquet(sweep_out / "runs.parquet")
    assert len(table) == 8 and set(table["seed"]) == {0, 1}
    pd.testing.assert_frame_equal(pd.read_csv(sweep_out / "runs.csv"), table, check_dtype=False)
    # K x 10 breaks Euler's stability bound at 1 kHz: flagged rows without numbers
    bad = table[table["K_scale"] == 10.0]
    assert set(bad["result"]) == {"unstable_step"} and bad["rms_worst"].isna().all()
    # strict JSON (no NaN): loads with any parser
    summary = json.loads((sweep_out / "summary.json").read_text(), parse_constant=pytest.fail)
    assert read_summary(sweep_out / "summary.json")["kind"] == "sweep"
    assert summary["metric"] == "rms_worst"
    assert summary["best"]["params"] == {"K_scale": 0.01, "rho_scale": 0.1}
    assert summary["paper"]["params"] == {"K_scale": 1.0, "rho_scale": 1.0}
    np.testing.assert_allclose(summary["best_gains"]["K"], 0.01 * np.array(K_EQ63), rtol=1e-12)
    # held-out seeds 2 and 3: the paper's gains at 0.1 px are an order of magnitude worse
    assert summary["held_out_seeds"] == [2, 3]
    assert summary["paper"]["metric"] > 10 * summary["best"]["metric"] > 0
    assert (sweep_out / "sweep.png").stat().st_size > 10_000

    assert main(["tune", *common, "--steps", "5", "--quiet", "--out", str(tune_out)]) == 0
    summary = json.loads((tune_out / "summary.json").read_text(), parse_constant=pytest.fail)
    assert read_summary(tune_out / "summary.json")["kind"] == "tune"
    assert set(summary) >= {"metric", "best", "paper", "sweep_best"}
    assert summary["best"]["metric"] * 10 < summary["paper"]["metric"]
    # the tuned point is no worse on the training seeds than the sweep's best it started at
    assert summary["training_loss"]["tuned"] <= summary["training_loss"]["sweep_best"]
    assert "held-out improvement" in capsys.readouterr().out
    for name in ("runs.parquet", "runs.csv", "history.csv", "tune.png", "sweep.png"):
        assert (tune_out / name).stat().st_size > 0


def test_noise_seeds_give_medians_and_the_spread(tmp_path, capsys):
    """--seeds S: S noise seeds from --seed; errors as medians with each seed's beside them,
    the estimates with a leading seed axis (the figures draw the 10-90 % band)."""
    out = tmp_path / "v"
    argv = ["velocity", "--duration", "1", "--noise", "0.2", "--seeds", "2", "--seed", "3"]
    assert main([*argv, "--quiet", "--out", str(out)]) == 0
    summary = _summary(out)
    per_seed = np.array(summary["rms_window_seeds"])
    assert summary["seeds"] == 2 and summary["seed"] == 3 and per_seed.shape == (2, 6)
    np.testing.assert_allclose(summary["rms_window"], per_seed.mean(0), rtol=1e-12)
    estimate = np.load(out / "estimate.npz")
    assert estimate["v_hat"].shape == (2, 1000, 6)
    inside = (estimate["t"] >= 0.5) & (estimate["t"] < 1.0)
    err = estimate["v_hat"][:, inside] - estimate["velocity"][inside]
    np.testing.assert_allclose(np.sqrt(np.mean(err**2, axis=1)), per_seed, rtol=1e-12)
    assert not np.allclose(per_seed[0], per_seed[1])  # two different noise draws
    # seeds need noise, and apply to the paper's simulation only
    for bad in (["velocity", "--seeds", "2"], ["euclidean", "--seeds", "3", "--data", "x.npz"]):
        with pytest.raises(SystemExit):
            main(bad)
    err = capsys.readouterr().err
    assert "needs --noise above 0" in err and "not to --data" in err


@pytest.mark.slow  # its video and 300-dpi figure (5 s): the reproduction smoke above runs the
# testbed's job in the unit tier
def test_testbed_command(tmp_path):
    """`visjax testbed` end to end on set I.1: the PUMA's camera follows the set, the
    marker is tracked, the observer runs on the tracked pixels."""
    out = tmp_path / "tb"
    argv = ["testbed", "--set", "I.1", "--duration", str(TESTBED_S), "--no-studies"]
    assert main(argv + ["--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    entry = summary["sets"]["I.1"]
    assert summary["settings"]["studies"] is False and summary["settings"]["video"] is True
    assert entry["units"] == "cm" and entry["thesis_rms"] == [0.0016, 0.0047, 0.0214]
    assert entry["feasible"] and entry["result"] == "successful"
    assert len(entry["rms"]) == 3 and all(isinstance(x, float) for x in entry["rms"])
    for name in ("testbed_I.1.png", "testbed_I.1.mp4", "testbed_I.1.npz"):
        assert (out / name).stat().st_size > 1000
    table = pd.read_csv(out / "tables.csv")
    assert list(table["axis"]) == ["x", "y", "z"]
    assert list(table["thesis_rms_m"]) == [0.0016, 0.0047, 0.0214]
    np.testing.assert_allclose(table["rms_m"], entry["rms"], rtol=1e-12)
    with np.load(out / "testbed_I.1.npz") as z:
        r = SimpleNamespace(**{k: z[k] for k in z.files})
    assert r.estimate.shape[1] == 3 and r.pixels.shape[1] == 2
    # the PUMA's camera really moves with the set's velocities (inverse velocity
    # kinematics integrated, forward kinematics read back)
    assert twin_kinematics_residual(r, lambda t: np.zeros((len(t), 3))) < 1e-7
    np.testing.assert_allclose(r.position[:, 2], 0.80, atol=1e-6)  # the table is level
    # the encoders: a count of 2.4e-5 rad over one camera period, plus half a period's lag
    assert np.abs(r.velocity_measured - r.velocity_true).max() < 3e-3
    check_testbed_tracking(
        SimpleNamespace(
            tracking_rms_px=entry["tracking_rms_px"],
            pixels=r.pixels,
            rms=np.array(entry["rms"]),
            rms_ideal=np.array(entry["rms_ideal_pixels"]),
            estimate=r.estimate,
            rms_frames=np.array(entry["rms_frames"]),
        )
    )
    with pytest.raises(SystemExit) as e:
        main(["testbed", "--set", "IX", "--out", str(tmp_path / "x")])
    assert e.value.code == 2 and not (tmp_path / "x").exists()
