"""`visjax.io.staged_output`: files move into place only on success, nothing is left
behind on failure, and summaries and printed lines name the final folder."""

import json

import pytest

from visjax import __version__
from visjax.io import staged_output, user_path, write_summary


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
    (final / "figures").mkdir()
    (final / "figures" / "old.png").write_text("old")
    with staged_output(final) as staged:
        # hidden, on the same file system as the final folder (inside it when it exists)
        assert staged.parent == final and staged.name.startswith(".visjax-")
        (staged / "figures").mkdir()
        (staged / "figures" / "new.png").write_text("new")
        print(f"wrote {staged / 'summary.json'}")
        assert user_path(str(staged / "x")) == str(final / "x")
        write_summary(staged / "summary.json", _summary(str(staged)))
    assert capsys.readouterr().out.strip() == f"wrote {final / 'summary.json'}"
    assert (final / "notes.txt").read_text() == "mine"  # what the command did not write
    assert sorted(p.name for p in (final / "figures").iterdir()) == ["new.png"]  # replaced
    assert not list(tmp_path.rglob(".visjax-*"))  # no staging folder left
    assert json.loads((final / "summary.json").read_text())["settings"]["out"] == str(final)


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
