"""Plausible mistakes on the command line end in one line, never a traceback nor silent
garbage: a failed run on a data file names its result code (exit 1, its files kept), a grid
with an unknown or invalid parameter and a study too large for the machine are refused
before any work (exit 2), and a data file with most frames missing a feature says so."""

import json
import re
import sys
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.example_data import velocity_example
from visjax import io, studies, verbs
from visjax._results import RESULTS
from visjax.cli import main

TOY = ["--import", "tests.studies.slow_toy"]  # `slow-toy`: built at once, one parameter `gain`


def _velocity_file(path, *, jump_at=None, drop_from=None, dtype=np.float64, jump_px=2e4):
    """The example velocity scene, 0.1 s at 1 kHz, 6 features, noise- and dropout-free
    (every file here has the same shapes: one compiled run serves them all). `jump_at`:
    from that frame on the pixels jump `jump_px` sideways (a tracker that switched to
    other coordinates); `drop_from`: feature 6 missing from that frame on."""
    data = velocity_example(duration=0.1, noise_px=0.0, dropout=0.0)
    pixels = np.array(data.pixels)
    if jump_at is not None:
        pixels[jump_at:, :, 0] += jump_px
    if drop_from is not None:
        pixels[drop_from:, 5] = np.nan
    arrays = {k: v for k, v in vars(data).items() if v is not None}
    arrays["pixels"] = pixels
    np.savez(path, **{k: np.asarray(v, dtype) for k, v in arrays.items()})
    return path


@pytest.fixture
def no_study(monkeypatch):
    """Every study function raises if called: a refusal comes before any work."""

    def never(*args, **kwargs):
        raise AssertionError("the study started")

    for name in ("sweep", "tune", "compare"):
        monkeypatch.setattr(studies, name, never)


def _refused(argv, capsys) -> str:
    """The command refused before any work: exit status 2, one line; returns it."""
    started = time.perf_counter()
    with pytest.raises(SystemExit) as e:
        main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2, err
    assert err.startswith("visjax: error:") and err.count("\n") == 1, err
    assert time.perf_counter() - started < 30  # no compile, no run
    return err


# 1. a failed run on a data file: its result code, one line, exit 1, its files kept


@pytest.mark.slow  # the unit tier's time (the file route's failure: the next test; the code
# `worse_than_trivial`: tests/studies/test_study.py's `Verdict.outcome`)
def test_a_jumping_tracker_is_refused_or_named(tmp_path, capsys):
    """A tracker that switched to other coordinates from frame 50: 20,000 px sideways is
    outside the image the intrinsics imply, refused at load (exit 2, one line naming
    `pixels`); 250 px, inside the image, runs and its estimate is far worse than zero
    velocity: the result `worse_than_trivial` (exit 1, one line), its files kept with the
    `quality` that says so (issue 44: never a bare `successful`)."""
    path = _velocity_file(tmp_path / "jump.npz", jump_at=50)
    assert main(["velocity", "--data", str(path), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "`pixels`'s u coordinates span" in err, err
    path = _velocity_file(tmp_path / "jump.npz", jump_at=50, jump_px=250.0)
    out = tmp_path / "out"
    assert main(["velocity", "--data", str(path), "--quiet", "--out", str(out)]) == 1
    printed = capsys.readouterr()
    assert printed.err.startswith(
        "visjax: error: run velocity: the result is worse_than_trivial"
    ), printed.err
    assert printed.err.count("\n") == 1 and "None" not in printed.out
    assert "estimator, worse_than_trivial" in printed.out
    summary = json.loads((out / "summary.json").read_text())
    io.validate_summary(summary)
    assert summary["kind"] == "run"  # `visjax velocity --data` is `visjax run velocity --data`
    assert summary["result"] == "worse_than_trivial" and summary["quality"]["ratio_to_trivial"] > 10
    assert summary["dropped_fraction"] == 0.0
    assert (out / "estimates.parquet").exists() and (out / "run.png").exists()


class _Stopped(eqx.Module):
    ts: jax.Array
    outputs: dict
    result: RESULTS
    failed_sample: jax.Array


class _Diverging(studies.AbstractProblem):
    """A problem whose one method always diverges at sample 2."""

    methods = ("estimator",)
    metric = "error"

    samples: jax.Array

    def parameters(self):
        return {"gain": studies.Parameter(1.0, "-", True, "a gain")}

    def inputs(self, key):
        return self.samples + 0.1 * jax.random.normal(key, self.samples.shape)

    def solve(self, method, params, inputs, *, outputs=False):
        value = params["gain"] * inputs
        return _Stopped(jnp.arange(4.0), {"value": value}, RESULTS.diverged, jnp.array(2))

    def metrics(self, method, solution):
        return {"error": jnp.max(jnp.abs(solution.outputs["value"]))}


@pytest.fixture
def diverging():
    from visjax.studies import _registry

    name = "diverging-toy"
    studies.register_problem(name, lambda *, noise_px=0.0: _Diverging(jnp.zeros(4)), replace=True)
    yield name
    _registry._REGISTRY.pop(name, None)


def test_a_failed_run_of_the_run_verb_is_the_same_rule(diverging, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", diverging, "--quiet", "--out", str(out)]) == 1
    printed = capsys.readouterr()
    assert printed.err == f"visjax: error: run {diverging}: the run failed: diverged at sample 2\n"
    assert "None" not in printed.out and "error = -" in printed.out
    summary = io.read_summary(out / "summary.json")
    assert summary["result"] == "diverged" and summary["failed_sample"] == 2
    assert summary["metrics"] == {"error": None}


# 2. a grid names the problem's parameters, with valid values, checked before any work


def test_an_unknown_grid_axis_is_refused_naming_the_valid_ones(no_study, capsys):
    for command in ("sweep", "tune"):
        err = _refused([*TOY, command, "slow-toy", "--grid", "gian=1/2"], capsys)
        assert "'gian'" in err and "did you mean 'gain'?" in err and "gain" in err
    err = _refused([*TOY, "sweep", "slow-toy", "--grid", "gain=1/2,nosuch=3"], capsys)
    assert "'nosuch'" in err and "did you mean" not in err


@pytest.mark.parametrize(
    "argv, hint",
    [
        (["velocty"], "'velocity'"),  # a command
        (["run", "velocty"], "'velocity'"),  # a problem
        ([*TOY, "run", "slow-toy", "--method", "estimatr"], "'estimator'"),  # a method
        ([*TOY, "compare", "slow-toy", "--methods", "estimatr"], "'estimator'"),
        (["run", "moving_point", "--set", "II_2"], "'II.2'"),  # a variant
        (["testbed", "--set", "II_2"], "'II.2'"),
        (["run", "velocity", "--dtype", "float23"], "'float32'"),  # an option's value
        (["compare", "velocity", "--table", "tx"], "'tex'"),
        (["run", "velocity", "--format", "sgv"], "'svg'"),
        ([*TOY, "sweep", "slow-toy", "--grid", "gian=1/2"], "'gain'"),
    ],
)
def test_every_unknown_name_suggests_the_closest(argv, hint, no_study, capsys):
    """A misspelt command, problem, method, variant, option value, figure format
    or grid axis is one line naming the closest valid name."""
    assert f"(did you mean {hint}?)" in _refused(argv, capsys)


@pytest.mark.parametrize(
    "grid, says",
    [
        ("gain=1:2", "three numbers"),
        ("gain=a:2:3", "'a' is not a number"),
        ("gain=1:2:3.5", "'3.5' is not a whole number"),
        ("gain=1/x", "'x' is not a number"),
    ],
)
def test_grid_syntax_errors_name_what_is_wrong(grid, says, no_study, capsys):
    err = _refused([*TOY, "sweep", "slow-toy", "--grid", grid], capsys)
    assert says in err and "unpack" not in err


@pytest.mark.parametrize(
    "grid, says",
    [
        ("gain=-1/2", "must be positive"),
        ("gain=0/2", "must be positive"),
        ("gain=nan/2", "not finite"),
        ("gain=1/inf", "not finite"),
        ("gain=-1:10:3", "positive ends"),
    ],
)
def test_invalid_grid_values_are_refused(grid, says, no_study, capsys):
    err = _refused([*TOY, "sweep", "slow-toy", "--grid", grid], capsys)
    assert says in err and "gain" in err


def test_sweep_options_that_exclude_each_other_are_usage_errors(no_study, capsys, tmp_path):
    """`verbs.Request` refuses what cannot run before any work: a sweep's parts need
    `--out`; `--resume` and `--force` exclude each other; tune follows one path, no job
    slice."""
    out = ["--out", str(tmp_path / "o")]
    err = _refused([*TOY, "sweep", "slow-toy", "--grid", "gain=1/2", "--resume"], capsys)
    assert "need --out" in err
    err = _refused([*TOY, "sweep", "slow-toy", "--resume", "--force", *out], capsys)
    assert "exclude each other" in err
    err = _refused([*TOY, "tune", "slow-toy", "--shard", "0/2", *out], capsys)
    assert "--shard i/N is for sweep" in err
    assert not (tmp_path / "o").exists()


# 3. studies sized before they start: the run count, then the memory


def test_absurd_run_counts_are_refused(no_study, capsys):
    err = _refused([*TOY, "compare", "slow-toy", "--seeds", "2000000000"], capsys)
    assert "2e+09 runs" in err and "--seeds" in err
    grid = ["--grid", "gain=1:10:100000"]
    err = _refused([*TOY, "sweep", "slow-toy", *grid, "--seeds", "100000"], capsys)
    assert "1e+10 runs" in err
    err = _refused(
        [*TOY, "tune", "slow-toy", *grid[:1], "gain=1/2", "--steps", "1000000000"], capsys
    )
    assert "--steps" in err
    err = _refused([*TOY, "sweep", "slow-toy", "--grid", "gain=1:10:2000000000"], capsys)
    assert "2e+09 points" in err  # counted from the text: no grid of that size is built


def test_durations_and_methods_are_refused_before_building(capsys):
    """A `--duration` past `MAX_STEPS` samples (a run would exhaust memory building its
    scene) are refused before the problem is built, an unknown `--method` (the closest
    suggested) by the built problem before any run."""
    err = _refused(["run", "velocity", "--duration", "1e9"], capsys)
    assert "1e+12 samples" in err and "MAX_STEPS" in err
    err = _refused(["velocity", "--duration", "1e9"], capsys)
    assert "1e+12 samples" in err
    err = _refused(["sweep", "point_depth", "--duration", "2e5", "--rate", "1000"], capsys)
    assert "2e+08 samples" in err
    err = _refused(["run", "velocity", "--method", "ekff"], capsys)
    assert "unknown method 'ekff' (did you mean 'ekf'?)" in err and "studies.add_method" in err


def test_a_comparison_too_long_is_refused_after_its_first_seed(tmp_path, capsys):
    """A million seeds of a problem whose seed takes about 0.25 s (the command line times
    one call per method and seed): the first seed puts the rest at ~70 h, past
    `--max-hours` (24 by default): refused then, exit 2, one line with the estimate;
    nothing written."""
    out = tmp_path / "out"
    argv = [*TOY, "compare", "slow-toy", "--seeds", "1000000", "--quiet", "--out", str(out)]
    started = time.perf_counter()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("visjax: error: compare slow-toy: 1000000 seeds would take about")
    assert err.count("\n") == 1 and "--max-hours" in err, err
    hours = float(re.search(r"about ([0-9.e+]+) h", err)[1])
    assert 50 < hours < 300, err  # ~0.25 s a seed, measured
    assert time.perf_counter() - started < 60 and not out.exists()
    # the limit is the user's to raise: 2 seeds under 1 h run
    assert main([*argv[:5], "2", "--quiet", "--max-hours", "1"]) == 0


def test_a_study_larger_than_the_memory_is_refused(no_study, monkeypatch, capsys):
    from visjax.studies import _plan

    monkeypatch.setattr(_plan, "available_memory", lambda: 100.0)  # bytes
    for argv in (
        ["sweep", "slow-toy", "--grid", "gain=1/2", "--seeds", "2"],
        ["tune", "slow-toy", "--grid", "gain=1/2", "--seeds", "2"],
        ["compare", "slow-toy", "--seeds", "2"],
    ):
        err = _refused([*TOY, *argv], capsys)
        assert "MiB available" in err, err


def test_tune_measures_its_chunk_before_it_runs(monkeypatch, capsys):
    """Past the bound before any compile, `tune` has the sweep measure its chunk (XLA's
    analysis, as `sweep` does): too large, it is refused before any run, exit 2."""
    from visjax.studies import _sweep

    def never(*args, **kwargs):
        raise AssertionError("the tuning started")

    monkeypatch.setattr(studies, "tune", never)
    monkeypatch.setattr(_sweep, "available_memory", lambda: 800.0)
    argv = [*TOY, "tune", "slow-toy", "--grid", "gain=1/2", "--seeds", "2", "--quiet"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "use a chunk of at most" in err, err


# 4. the coverage of a data file: reported, and past the limit not "successful"


def test_the_study_commands_read_the_dropped_fraction_of_a_file(tmp_path):
    """The fraction of frames with a feature missing, read from the file by the study
    commands before any run (the command's run on it is the slow test below)."""
    path = _velocity_file(tmp_path / "drop.npz", drop_from=25, dtype=np.float32)
    assert io.VelocityData.load(path).dropped_fraction() == 0.75 > io.MAX_DROPPED_FRACTION
    dropped = verbs._dropped(verbs.Request("run", "velocity", data=str(path)))
    assert dropped["fraction"] == 0.75 and dropped["over"]
    import tests.studies.slow_toy  # noqa: F401  (registers slow-toy)

    toy = verbs.Request("run", "slow-toy", data=str(path))
    assert verbs._dropped(toy) is None  # a format of its own: not reported
    full = _velocity_file(tmp_path / "full.npz")
    assert not verbs._dropped(verbs.Request("run", "velocity", data=str(full)))["over"]


@pytest.mark.slow  # a velocity problem's compile on a file of its own shapes (13 s)
def test_a_file_with_most_frames_missing_a_feature_is_not_successful(tmp_path, capsys):
    # float32, as a tracker may write it: it runs as float64
    path = _velocity_file(tmp_path / "drop.npz", drop_from=25, dtype=np.float32)
    out = tmp_path / "out"
    assert main(["velocity", "--data", str(path), "--quiet", "--out", str(out)]) == 1
    printed = capsys.readouterr()
    assert printed.err.count("\n") == 1 and "too_many_dropped_frames" in printed.err
    assert "75 of 100 (75.0%)" in printed.out and "run velocity" in printed.err
    summary = io.read_summary(out / "summary.json")
    assert summary["dropped_fraction"] == 0.75
    assert summary["result"] == "too_many_dropped_frames" != "successful"


def test_variant_names_never_write_outside_out(tmp_path, capsys):
    """A registered problem whose variants are named like paths (`a/b`, `/abs`, `..`):
    each variant's folder is one plain entry inside `--out` (issue 44); two names that
    map to one folder are refused when the problem is registered."""
    from tests.studies.slow_toy import slow_toy
    from visjax.studies import _registry

    name = "pathlike-toy"
    studies.register_problem(
        name, lambda *, noise_px=0.1, variant=None: slow_toy(noise_px=noise_px),
        variants=("a/b", "/abs", "../up"), replace=True,
    )  # fmt: skip
    try:
        out = tmp_path / "parent" / "out"
        sets = ["--set", "a/b", "--set", "/abs", "--set", "../up"]
        assert main(["compare", name, *sets, "--seeds", "1", "--quiet", "--out", str(out)]) == 0
        assert sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.iterdir()) == ["parent"]
        assert sorted(p.name for p in (tmp_path / "parent").iterdir()) == ["out"]
        for folder in ("a_b", "_abs", "___up"):
            assert (out / folder / "summary.json").exists()
        assert not (tmp_path / "abs").exists() and not (out / "a").exists()
        with pytest.raises(ValueError, match="share the output folder 'a_b'"):
            studies.register_problem(name, slow_toy, variants=("a.b", "a/b"), replace=True)
        with pytest.raises(ValueError, match="makes no output folder name"):
            studies.register_problem(name, slow_toy, variants=("..",), replace=True)
    finally:
        _registry._REGISTRY.pop(name, None)


@pytest.mark.parametrize(
    "source, code, says",
    [
        (None, 2, "no module named 'nosuch_mod_44' in the current folder"),
        ("def broken(:\n", 1, "your module raised SyntaxError"),
        ("raise RuntimeError('my module is broken')\n", 1, "raised RuntimeError: my module is"),
        (
            "from visjax import studies\n"
            "def build(*, noise_px=0.1):\n    return 1 / 0\n"
            "studies.register_problem('zero-toy', build, replace=True)\n",
            1,
            "its builder nosuch_mod_44.build raised ZeroDivisionError",
        ),
    ],
)
def test_import_failures_say_so_in_one_line(tmp_path, monkeypatch, capsys, source, code, says):
    """`--import MODULE` (issue 44): a module in the current folder is found; one that is
    not found is one line (exit 2); one that does not parse, raises on import, or whose
    builder raises is one line naming it, then the user's own traceback (their code)."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", ".")])
    monkeypatch.delitem(sys.modules, "nosuch_mod_44", raising=False)
    if source is not None:
        (tmp_path / "nosuch_mod_44.py").write_text(source)
    try:
        status = main(["--import", "nosuch_mod_44", "run", "zero-toy", "--quiet"])
    except SystemExit as e:  # refused while parsing
        status = e.code
    assert status == code
    err = capsys.readouterr().err
    first, *rest = err.splitlines()
    assert first.startswith("visjax: error: ") and says in first, err
    if code == 2:
        assert rest == []
    else:
        assert first.endswith("(your code's traceback below)")
        assert rest[0] == "Traceback (most recent call last):"
        assert "nosuch_mod_44.py" in err and "visjax/cli.py" not in err
    sys.modules.pop("nosuch_mod_44", None)


def test_a_broken_plugin_breaks_no_other_command(monkeypatch, capsys):
    """An installed entry point (`visjax.problems`) that raises on import is loaded only
    when named: every other command works (the parser lists it); naming it is one line."""
    from visjax.studies import _registry

    class Broken:
        name, value = "broken-plugin", "some_pkg.problems:build"

        def load(self):
            raise ImportError("No module named 'some_dependency'")

    monkeypatch.setitem(_registry._PENDING, "broken-plugin", Broken())
    assert "broken-plugin" in studies.problem_names()
    assert studies.registered("velocity").name == "velocity"
    err = _refused(["run", "broken-plugin", "--quiet"], capsys)
    assert "Traceback" not in err
    assert "'some_pkg.problems:build'" in err and "failed to load: ImportError" in err
    _registry._BROKEN.pop("broken-plugin", None)


def test_ray_address_with_nothing_listening_is_one_line(capsys):
    """`--ray ADDRESS` where nothing listens (a closed port on 127.0.0.1; tests contact no
    other address): one line naming the address and the wait, quickly (issue 44)."""
    import socket

    pytest.importorskip("ray")
    with socket.socket() as s:  # a port that was free a moment ago: closed now
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    started = time.perf_counter()
    argv = [*TOY, "sweep", "slow-toy", "--seeds", "1", "--quiet", "--ray", f"127.0.0.1:{port}"]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--ray 127.0.0.1:{port}: nothing answers" in err, err
    assert time.perf_counter() - started < 30


class _Far(studies.AbstractProblem):
    """Estimates 2 from noisy samples; its estimator answers `offset + mean`: with a large
    offset, worse than the trivial estimate 0 (whose error is 2)."""

    methods = ("estimator", "mean")
    metric = "error"
    trivial_label = "zero"

    samples: jax.Array
    offset: float = eqx.field(static=True, default=0.0)

    def parameters(self):
        return {"gain": studies.Parameter(1.0, "-", True, "a gain")}

    def inputs(self, key):
        return self.samples + 0.01 * jax.random.normal(key, self.samples.shape)

    def solve(self, method, params, inputs, *, outputs=False):
        shift = self.offset if method == "estimator" else 0.0
        return _Stopped(
            jnp.arange(4.0), {"value": jnp.mean(inputs) + shift}, RESULTS.successful, jnp.array(-1)
        )

    def metrics(self, method, solution):
        return {"error": jnp.abs(solution.outputs["value"] - 2.0)}

    def trivial(self):
        return {"error": jnp.asarray(2.0)}


@pytest.mark.parametrize("offset, flag", [(0.1, "ok"), (3.0, "worse_than_trivial")])
def test_an_estimate_worse_than_the_trivial_one_is_not_a_success(offset, flag, tmp_path, capsys):
    """Issue 44: `run` compares the estimate with the trivial one (`trivial()`): an error
    at least `QUALITY_RATIO` times the trivial error is the result `worse_than_trivial`
    (exit 1, files kept, `quality` recorded); `compare` counts such runs per method."""
    from visjax.studies import _registry

    name = f"far-toy-{flag}"
    studies.register_problem(
        name, lambda *, noise_px=0.0: _Far(jnp.full(8, 2.0), offset), replace=True
    )
    try:
        out = tmp_path / "run"
        assert main(["run", name, "--quiet", "--out", str(out)]) == (0 if flag == "ok" else 1)
        printed = capsys.readouterr()
        summary = io.read_summary(out / "summary.json")
        q = summary["quality"]
        assert q["flag"] == flag and q["trivial"] == 2.0 and q["trivial_estimate"] == "zero"
        np.testing.assert_allclose(q["ratio_to_trivial"], summary["metrics"]["error"] / 2.0)
        if flag == "ok":
            assert summary["result"] == "successful" and printed.err == ""
        else:
            assert summary["result"] == "worse_than_trivial"
            assert printed.err.startswith(f"visjax: error: run {name}: the result is worse")
        out = tmp_path / "compare"
        assert main(["compare", name, "--seeds", "3", "--quiet", "--out", str(out)]) == 0
        summary = io.read_summary(out / "summary.json")
        expected = {"estimator": 0 if flag == "ok" else 3, "mean": 0}
        assert summary["quality"]["worse_than_trivial"] == expected
        assert all(r["ratio_to_trivial"] is not None for r in summary["records"])
        assert ("warning: 3 run(s) no better than zero" in capsys.readouterr().out) == (
            flag != "ok"
        )
    finally:
        _registry._REGISTRY.pop(name, None)


class _Lagging(_Far):
    """`_Far` whose estimator also reports its output error, `offset` off every sample,
    against the noise of the samples (0.01): an observer that lags them."""

    def innovation(self, method, params, solution, inputs):
        from visjax.estimators import innovation

        error = jnp.full_like(inputs, self.offset) + (inputs - jnp.mean(inputs))
        return innovation(inputs[:, None], error[:, None])


@pytest.mark.parametrize("offset, flag", [(0.0, "ok"), (0.1, "innovation_too_large")])
def test_an_observer_off_its_measurements_is_warned_without_the_truth(
    offset, flag, tmp_path, capsys
):
    """Issue 44 (item 1): `run` records the observer's output error against the noise the
    data imply (`quality.innovation`, `problem.innovation`) and warns past
    `INNOVATION_GATE`, without changing the result (the truth says the estimate is fine)."""
    from visjax.studies import INNOVATION_GATE, _registry

    name = f"lag-toy-{flag}"
    studies.register_problem(
        name, lambda *, noise_px=0.0: _Lagging(jnp.full(64, 2.0), offset), replace=True
    )
    try:
        out = tmp_path / "run"
        assert main(["run", name, "--quiet", "--out", str(out)]) == 0
        printed = capsys.readouterr()
        summary = io.read_summary(out / "summary.json")
        q = summary["quality"]
        assert summary["result"] == "successful" and q["flag"] == flag, q
        ratio = q["innovation"]["ratio"]
        assert (ratio > INNOVATION_GATE) == (flag != "ok") and q["innovation"]["samples"] == 64
        assert ("warning: run" in printed.err) == (flag != "ok"), printed.err
    finally:
        _registry._REGISTRY.pop(name, None)


def test_seed_loops_are_timed_against_max_hours(monkeypatch):
    """Issue 44: `velocity|moving_point|static_points --seeds N` estimate the whole loop
    after the second seed (the first reuses the compiled run) and refuse it past
    `--max-hours`, before the rest; within it, nothing is said."""
    from visjax.papers import _reproduction

    now = iter([0.0, 30.0, 31.0, 32.0])  # start; seed 1 (compiles): 30 s; then 1 s each
    monkeypatch.setattr(_reproduction.time, "perf_counter", lambda: next(now))
    clock = _reproduction.SeedClock(1_000_000, 24.0, "velocity")
    clock.tick()
    with pytest.raises(studies.StudyTooLong, match=r"velocity: 1000000 runs estimated at 278 h"):
        clock.tick()
    now = iter([0.0, 30.0, 31.0, 32.0])
    clock = _reproduction.SeedClock(1000, 24.0, "velocity")
    for _ in range(3):
        clock.tick()  # 30 s + 999 s: well within a day


@pytest.mark.slow  # two velocity runs (a compile)
def test_velocity_seeds_past_max_hours_are_refused_in_one_line(capsys):
    argv = ["velocity", "--duration", "0.05", "--noise", "0.1", "--seeds", "100000", "--quiet"]
    assert main([*argv, "--max-hours", "0.001"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "100000 runs estimated at" in err and "--max-hours" in err


def test_a_signal_inside_a_gc_callback_is_sent_again_not_dropped():
    """JAX registers a garbage collector callback; an exception raised there (SIGTERM's
    `_Interrupted`) is printed with a traceback and dropped, and the run went on (issue
    44's re-probe): the handler sees such a frame (`_in_gc_callback`) and sends the
    signal again once the callback returned."""
    import gc

    from visjax.studies._study import _in_gc_callback

    seen = []

    def callback(phase, info):
        seen.append(_in_gc_callback(sys._getframe()))

    gc.callbacks.append(callback)
    try:
        gc.collect()
    finally:
        gc.callbacks.remove(callback)
    assert seen and all(seen)
    assert not _in_gc_callback(sys._getframe())


def test_a_study_command_builds_its_problem_once(capsys):
    """The command line checks a study on the built problem and runs the command on the
    same one (`verbs.check_study` returns it, the command takes it as `built`): no second
    build, no cache keyed on a file's modification time."""
    from tests.studies.slow_toy import slow_toy

    builds = []

    def counted(*, noise_px: float = 0.1):
        builds.append(noise_px)
        return slow_toy(noise_px=noise_px)

    studies.register_problem("counted-toy", counted, replace=True)
    for argv in (
        ["sweep", "counted-toy", "--grid", "gain=1/2", "--seeds", "1", "--quiet"],
        ["compare", "counted-toy", "--seeds", "1", "--quiet"],
    ):
        builds.clear()
        assert main(argv) == 0, capsys.readouterr().err
        assert builds == [0.1], argv


def test_an_optional_extra_missing_is_one_line_naming_it(tmp_path, monkeypatch, capsys):
    """Without `rosbags` or `rerun-sdk` (the extras `visjax[ros]`, `visjax[viz]`), the
    commands that need them refuse in one line naming the extra, before any work."""
    import importlib.util

    real = importlib.util.find_spec
    missing = {"rosbags", "rosbags.highlevel", "rerun"}
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name in missing else real(name, *a)
    )
    bag = tmp_path / "a.bag"
    bag.write_bytes(b"")
    argv = ["import-bag", str(bag), "--problem", "velocity", "--image-topic", "/i",
            "--camera-info", "/c", "--twist", "/t", "--out", str(tmp_path / "d.npz")]  # fmt: skip
    assert "pip install 'visjax[ros]'" in _refused(argv, capsys)
    argv = ["run", "velocity", "--rerun", str(tmp_path / "a.rrd"), "--out", str(tmp_path / "r")]
    assert "pip install 'visjax[viz]'" in _refused(argv, capsys)
