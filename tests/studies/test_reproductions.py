"""The registry of reproductions (`studies.register_reproduction`): what `visjax reproduce`
iterates; a user's reproduction appears in its table; rows are checked."""

import json
import math

import pandas as pd
import pytest

from visjax import studies
from visjax.cli import main
from visjax.studies import _reproductions

MODULE = """
from visjax import studies


def run(out=None, *, quick=False, quiet=False, formats=("png",), scale=2.0):
    value = scale * (0.5 if quick else 1.0)
    return [studies.reproduction_row("mine: a number", value, 1.0, "truth", "m")]


studies.register_reproduction("mine", run, title="My reproduction", quick="half")
"""


@pytest.fixture
def empty_registry(monkeypatch):
    """The registry with no reproduction in it (restored after the test)."""
    monkeypatch.setattr(_reproductions, "_REPRODUCTIONS", {})


def test_the_papers_reproductions_are_registered_in_order():
    names = studies.reproduction_names()
    assert names[:5] == ["velocity", "geometry", "moving_point", "static_points", "testbed"]
    assert {"point_depth", "homography"} <= set(names)
    folders = [studies.registered_reproduction(n).folder for n in names]
    assert len(set(folders)) == len(folders)  # one output folder each
    with pytest.raises(ValueError, match="did you mean 'velocity'"):
        studies.registered_reproduction("velocty")


def test_a_users_reproduction_appears_in_reproduce(tmp_path, monkeypatch, capsys, empty_registry):
    (tmp_path / "my_repro.py").write_text(MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    out = tmp_path / "results"
    argv = ["--import", "my_repro", "reproduce", "--quick", "--quiet", "--out", str(out)]
    assert main(argv) == 0
    assert studies.reproduction_names() == ["mine"]
    table = pd.read_parquet(out / "summary.parquet")
    assert table.to_dict("records") == [
        {
            "name": "mine: a number",
            "value": 1.0,
            "reference": 1.0,
            "reference_kind": "truth",
            "unit": "m",
        }  # fmt: skip
    ]  # the quick setting: 2 x 0.5
    summary = json.loads((out / "summary.json").read_text())
    assert summary["rows"] == table.to_dict("records")
    assert summary["settings"]["reproductions"] == ["mine"]
    printed = capsys.readouterr().out
    assert "== My reproduction ==" in printed and "mine: a number" in printed
    # its own options, by keyword
    entry = studies.registered_reproduction("mine")
    assert entry.rows(None, scale=3.0)[0]["value"] == 3.0


@pytest.mark.parametrize(
    "rows, message",
    [
        ("not rows", "a row is a dict"),
        (42, "not a list of rows"),
        ([{"name": "x", "value": 1.0}], "a row is a dict of the keys"),
        (
            [dict(name="x", value=math.nan, reference=1.0, reference_kind="truth", unit="m")],
            "`value` must be a finite number",
        ),  # fmt: skip
        (
            [dict(name="x", value=1.0, reference=None, reference_kind="truth", unit="m")],
            "`reference` must be a finite number",
        ),  # fmt: skip
        (
            [dict(name="x", value=1.0, reference=1.0, reference_kind="guess", unit="m")],
            "`reference_kind` must be one of",
        ),  # fmt: skip
        (
            [dict(name="x", value=True, reference=1.0, reference_kind="truth", unit="m")],
            "`value` must be a finite number",
        ),  # fmt: skip
    ],
)
def test_bad_rows_are_refused_naming_the_row(rows, message, empty_registry):
    studies.register_reproduction("bad", lambda out, **kw: rows, title="bad")
    with pytest.raises(ValueError, match=message):
        studies.registered_reproduction("bad").rows(None)


def test_an_infeasible_value_is_none():
    row = studies.reproduction_row("x", None, 2, "published", "m")
    assert studies.check_rows("x", [row]) == [row] and row["value"] is None


def test_names_and_folders_are_one_each(empty_registry):
    def run(out, **kw):
        return []

    studies.register_reproduction("a", run, title="A")
    with pytest.raises(ValueError, match="registered already"):
        studies.register_reproduction("a", run, title="A again")
    with pytest.raises(ValueError, match="share the output folder 'a'"):
        studies.register_reproduction("b", run, title="B", folder="a")
    with pytest.raises(ValueError, match="a reproduction's name"):
        studies.register_reproduction("../x", run, title="X")
    # (under jaxtyping's run-time checks the annotation refuses it first, naming `run`)
    with pytest.raises(TypeError, match="must be callable|parameter 'run'"):
        studies.register_reproduction("c", None, title="C")
    studies.register_reproduction("a", run, title="A, replaced", replace=True)
    assert studies.registered_reproduction("a").title == "A, replaced"


def test_quick_reproductions_run_on_the_hosts_cpu_where_the_default_is_an_accelerator(
    monkeypatch, empty_registry
):
    """Issue 47: `reproduce --quick`'s small runs compile more than they compute; on a GPU
    they run on the host's CPU (`jax.default_device`), the full settings on the GPU."""
    import jax

    seen = []

    def run(out=None, *, quick=False, quiet=False, formats=("png",)):
        seen.append(jax.config.jax_default_device)
        return [studies.reproduction_row("x: y", 1.0, 1.0, "truth", "m")]

    studies.register_reproduction("where", run, title="Where")
    entry = studies.registered_reproduction("where")
    entry.rows(quick=True)
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    entry.rows(quick=True)
    entry.rows(quick=False)
    cpu = jax.devices("cpu")[0]
    assert seen[0] is None and seen[1] == cpu and seen[2] is None
