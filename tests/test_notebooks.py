"""The notebooks run end to end (on short settings)."""

import pathlib

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = pathlib.Path(__file__).parents[1] / "notebooks"


@pytest.mark.parametrize(
    "name,env,expect",
    [
        (
            "velocity_fixed_camera.ipynb",
            {"VISJAX_NB_DURATION": "1"},
            ("z1* recovered", "noise [px]"),
        ),
        ("uio_moving_camera.ipynb", {"VISJAX_NB_DURATION": "2"}, ("rank (3.20)", "toolbox K_c")),
        (
            "uncalibrated_structure.ipynb",
            {"VISJAX_NB_DURATION": "3"},
            ("final position errors", "median PE"),
        ),
        (
            "gain_tuning.ipynb",
            {"VISJAX_NB_SHORT": "1"},
            ("held-out improvement", "certified Lipschitz bound", "central difference"),
        ),
    ],
)
def test_notebook_executes(name, env, expect, monkeypatch):
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    NotebookClient(
        nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(NOTEBOOKS)}}
    ).execute()
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not any(o.get("output_type") == "error" for o in outputs)
    text = "".join(o.get("text", "") for o in outputs if o.get("output_type") == "stream")
    assert all(e in text for e in expect)
