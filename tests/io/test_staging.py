"""`visjax.io.staged_output`: files move into place only on success, nothing is left
behind on failure, and summaries and printed lines name the final folder."""

import json

import pytest

from visjax import __version__
from visjax.io import staged_output, user_path, write_summary
from visjax.io._staging import MANIFEST, OutputConflictError


def _summary(out: str) -> dict:
    """A valid `static_points` summary whose settings name `out`."""
    return {
        "kind": "static_points",
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


def _snapshot(folder) -> dict:
    """Every file under `folder` (links not followed) with its bytes."""
    out = {}
    for path in sorted(folder.rglob("*")):
        if path.is_symlink():
            out[str(path.relative_to(folder))] = ("link", str(path.readlink()))
        elif path.is_file():
            out[str(path.relative_to(folder))] = path.read_bytes()
    return out


@pytest.mark.parametrize(
    "entries", [[".."], ["."], ["../sibling.txt", "/etc"], ["", "a/b", "..\\x"]]
)
def test_a_manifest_naming_dot_dot_or_a_path_removes_nothing(tmp_path, entries, capsys):
    """A `.visjax-outputs.json` anyone left in `--out` (a copied folder, a hand edit):
    entries that are not plain names of the folder are never removed (issue 44)."""
    parent = tmp_path / "parent"
    final = parent / "out"
    final.mkdir(parents=True)
    (parent / "sibling.txt").write_text("beside --out")
    (final / "mine.txt").write_text("in --out")
    (final / MANIFEST).write_text(json.dumps({"command": "compare", "entries": entries}))
    before = _snapshot(parent)
    with staged_output(final, command="compare") as staged:
        (staged / "records.csv").write_text("1")
    after = _snapshot(parent)
    assert after.pop("out/records.csv") == b"1"
    after.pop(f"out/{MANIFEST}")
    before.pop(f"out/{MANIFEST}")
    assert after == before  # byte-identical: nothing of the user's removed or changed
    assert "left as it is" in capsys.readouterr().err


def test_a_forged_or_stale_entry_is_not_removed(tmp_path):
    """A plain name in the manifest without the fingerprint the command recorded (a
    forged manifest), or an output the user changed since: left as it is; an output of
    the same name is then kept aside, never written over the user's."""
    final = tmp_path / "out"
    final.mkdir()
    (final / "data.npz").write_bytes(b"users data")
    (final / MANIFEST).write_text(json.dumps({"command": "compare", "entries": ["data.npz"]}))
    with staged_output(final, command="compare") as staged:
        (staged / "records.csv").write_text("1")
    assert (final / "data.npz").read_bytes() == b"users data"
    # an output of the run, then changed by the user: the rerun removes it no longer
    (final / "records.csv").write_text("edited by hand, longer")
    with staged_output(final, command="compare") as staged:
        (staged / "other.csv").write_text("2")
    assert (final / "records.csv").read_text() == "edited by hand, longer"
    # an unchanged output of the earlier run is still replaced whole
    with staged_output(final, command="compare") as staged:
        (staged / "third.csv").write_text("3")
    assert not (final / "other.csv").exists() and (final / "third.csv").exists()
    assert (final / "records.csv").exists() and (final / "data.npz").exists()


def test_a_users_folder_is_never_written_into_directly(tmp_path):
    """A sweep writes its parts straight into `--out/<variant>/parts`: a user's own
    `I_1/`, `parts/` or a link there is refused before any work, byte-identical."""
    from visjax.io._staging import written_directly

    final = tmp_path / "out"
    (final / "I_1").mkdir(parents=True)
    (final / "I_1" / "notes.txt").write_text("mine")
    (final / "parts").mkdir()
    (final / "parts" / "part-0000000.parquet").write_text("my own file of that name")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "keep.txt").write_text("keep")
    (final / "linked").symlink_to(elsewhere, target_is_directory=True)
    before = _snapshot(tmp_path)
    for name in ("I_1/parts", "parts", "linked/parts"):
        with pytest.raises(OutputConflictError, match=f"'{name.split('/')[0]}' is not from"):
            with staged_output(final, command="sweep", force=True):
                written_directly(final / name)
    assert _snapshot(tmp_path) == before


def test_an_interrupted_direct_entry_is_the_next_runs_own(tmp_path):
    """What a run wrote straight into `--out` before it was interrupted (a sweep's parts)
    is its own for the next run (`--resume`): it may write there again, and a finished run
    records it in the manifest."""
    from visjax.io._staging import written_directly

    final = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        with staged_output(final, command="sweep"):
            written_directly(final / "I_1" / "parts")
            (final / "I_1" / "parts").mkdir(parents=True)
            (final / "I_1" / "parts" / "part-0000000.parquet").write_text("p0")
            raise KeyboardInterrupt
    with staged_output(final, command="sweep") as staged:
        written_directly(final / "I_1" / "parts")
        (final / "I_1" / "parts" / "part-0000001.parquet").write_text("p1")
        (staged / "I_1").mkdir()
        (staged / "I_1" / "summary.json").write_text("{}")
    assert sorted(p.name for p in (final / "I_1" / "parts").iterdir()) == [
        "part-0000000.parquet",
        "part-0000001.parquet",
    ]
    manifest = json.loads((final / MANIFEST).read_text())
    assert manifest["entries"] == ["I_1"] and set(manifest["fingerprints"]) == {"I_1"}
    assert not list(final.glob(".visjax-direct*"))


def test_clear_parts_removes_only_a_sweeps_files(tmp_path):
    """`--force` on a sweep clears its parts folder of what a sweep writes, nothing else;
    through a link, nothing at all."""
    from visjax.studies._parts import PartsError, clear_parts

    parts = tmp_path / "parts"
    parts.mkdir()
    for name in ("part-0000000.parquet", "manifest.json", ".manifest.json.tmp1"):
        (parts / name).write_text("sweep")
    (parts / "mine.txt").write_text("mine")
    clear_parts(parts)
    assert [p.name for p in parts.iterdir()] == ["mine.txt"]
    (parts / "mine.txt").unlink()
    (parts / "part-0000000.parquet").write_text("sweep")
    clear_parts(parts)
    assert not parts.exists()  # emptied, then removed
    target = tmp_path / "target"
    target.mkdir()
    (target / "part-0000000.parquet").write_text("not through a link")
    (tmp_path / "link").symlink_to(target, target_is_directory=True)
    with pytest.raises(PartsError, match="symbolic link"):
        clear_parts(tmp_path / "link")
    assert (target / "part-0000000.parquet").read_text() == "not through a link"
