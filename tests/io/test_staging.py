"""`visjax.io.staged_output`: files move into place only on success, nothing is left
behind on failure, and summaries and printed lines name the final folder."""

import json

import pytest

from visjax import __version__
from visjax.io import staged_output, user_path, write_summary
from visjax.io._staging import MANIFEST, OutputConflictError


def _summary(out: str) -> dict:
    """A valid `euclidean` summary whose settings name `out`."""
    return {
        "kind": "euclidean",
        "visjax_version": __version__,
        "jax_version": "0",
        "created_utc": "2026-01-01T00:00:00+00:00",
        "wall_time_s": 1.0,
        "seed": None,
        "settings": {"out": out, "duration": 1.0},
        "final_position_error_m": [0.001],
        "duration_s": 1.0,
        "noise_px": 0.0,
        "final_camera_prediction_error_px": 0.2,
        "covariance_resets": 3,
    }


def test_success_moves_every_file_and_records_the_final_folder(tmp_path, capsys):
    final = tmp_path / "results"
    final.mkdir()
    (final / "notes.txt").write_text("mine")
    with staged_output(final, command="euclidean") as staged:
        # hidden, on the same file system as the final folder (inside it)
        assert staged.parent == final and staged.name.startswith(".visjax-stage-")
        (staged / "figures").mkdir()
        (staged / "figures" / "new.png").write_text("new")
        print(f"wrote {staged / 'summary.json'}")
        assert user_path(str(staged / "x")) == str(final / "x")
        write_summary(staged / "summary.json", _summary(str(staged)))
    assert capsys.readouterr().out.strip() == f"wrote {final / 'summary.json'}"
    assert (final / "notes.txt").read_text() == "mine"  # what the command did not write
    assert sorted(p.name for p in (final / "figures").iterdir()) == ["new.png"]
    assert not list(tmp_path.rglob(".visjax-stage-*")) and not list(tmp_path.rglob("*.lock"))
    assert json.loads((final / "summary.json").read_text())["settings"]["out"] == str(final)
    manifest = json.loads((final / MANIFEST).read_text())
    assert manifest["command"] == "euclidean"
    assert manifest["entries"] == ["figures", "summary.json"]


def test_a_rerun_replaces_its_own_entries_whole_and_keeps_the_users(tmp_path):
    final = tmp_path / "out"
    with staged_output(final, command="compare") as staged:
        (staged / "old.csv").write_text("1")
        (staged / "figures").mkdir()
        (staged / "figures" / "a.png").write_text("a")
    (final / "notes.txt").write_text("mine")
    with staged_output(final, command="compare") as staged:
        (staged / "figures").mkdir()
        (staged / "figures" / "b.png").write_text("b")
    # the earlier run's entries are gone (nothing mixes), the user's file stays
    assert sorted(p.name for p in final.iterdir()) == [MANIFEST, "figures", "notes.txt"]
    assert [p.name for p in (final / "figures").iterdir()] == ["b.png"]


def test_a_users_entry_with_an_outputs_name_is_never_replaced(tmp_path):
    final = tmp_path / "out"
    (final / "figures").mkdir(parents=True)
    (final / "figures" / "notes.txt").write_text("mine")
    with pytest.raises(OutputConflictError, match="'figures' is not from this command") as e:
        with staged_output(final, command="compare") as staged:
            (staged / "figures").mkdir()
            (staged / "figures" / "a.png").write_text("a")
            (staged / "summary.json").write_text("{}")
    assert (final / "figures" / "notes.txt").read_text() == "mine"
    kept = [p for p in final.iterdir() if p.name.startswith("visjax-results-")]
    assert len(kept) == 1 and str(kept[0]) in str(e.value)  # the results are not lost
    assert sorted(p.name for p in kept[0].iterdir()) == ["figures", "summary.json"]
    assert not list(final.glob(".visjax-stage-*"))


def test_another_commands_results_need_force(tmp_path):
    final = tmp_path / "out"
    with staged_output(final, command="sweep") as staged:
        (staged / "runs.csv").write_text("1")
    with pytest.raises(OutputConflictError, match=r"results of `visjax sweep`.*--force"):
        with staged_output(final, command="compare") as staged:
            raise AssertionError("refused before the block")
    assert (final / "runs.csv").exists()
    with staged_output(final, command="compare", force=True) as staged:
        (staged / "records.csv").write_text("2")
    assert sorted(p.name for p in final.iterdir()) == [MANIFEST, "records.csv"]


def test_a_second_run_into_the_same_folder_is_refused_while_one_writes(tmp_path):
    final = tmp_path / "out"
    with staged_output(final, command="compare") as staged:
        (staged / "a.txt").write_text("first")
        with pytest.raises(OutputConflictError, match="being written by another visjax run"):
            with staged_output(final, command="compare"):
                raise AssertionError("refused before the block")
    assert (final / "a.txt").read_text() == "first"
    with staged_output(final, command="compare") as staged:  # the lock is released
        (staged / "a.txt").write_text("second")
    assert (final / "a.txt").read_text() == "second"


def test_a_killed_runs_staging_folder_is_removed_by_the_next(tmp_path):
    final = tmp_path / "out"
    stale = final / ".visjax-stage-abc123"
    stale.mkdir(parents=True)
    (stale / "half.npz").write_text("half")
    with staged_output(final, command="compare") as staged:
        (staged / "a.txt").write_text("a")
    assert sorted(p.name for p in final.iterdir()) == [MANIFEST, "a.txt"]


def test_an_existing_output_file_needs_force(tmp_path):
    final = tmp_path / "tracks.csv"
    final.write_text("mine")
    with pytest.raises(OutputConflictError, match="exists: --force"):
        with staged_output(final, file=True):
            raise AssertionError("refused before the block")
    assert final.read_text() == "mine"
    with staged_output(final, file=True, force=True) as staged:
        staged.write_text("new")
    assert final.read_text() == "new" and sorted(p.name for p in tmp_path.iterdir()) == [
        "tracks.csv"
    ]


def test_write_summary_inside_records_the_final_folder(tmp_path):
    final = tmp_path / "out"
    with staged_output(final) as staged:
        body = {"settings": {"out": str(staged), "data": str(staged / "d.npz")}}
        from visjax.io._staging import unstaged

        assert unstaged(body) == {"settings": {"out": str(final), "data": str(final / "d.npz")}}
    assert user_path(str(tmp_path)) == str(tmp_path)  # outside: unchanged


def test_failure_moves_nothing_and_leaves_no_staging_folder(tmp_path):
    final = tmp_path / "results"
    with pytest.raises(RuntimeError, match="boom"):
        with staged_output(final) as staged:
            (staged / "half.npz").write_text("half")
            raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


def test_one_file_is_staged_too(tmp_path):
    final = tmp_path / "deep" / "tracks.csv"
    with staged_output(final, file=True) as staged:
        assert staged.name == "tracks.csv"
        staged.write_text("t,x\n")
    assert final.read_text() == "t,x\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["deep"]
