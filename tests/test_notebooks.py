"""The notebooks run end to end on short settings, and teach what they say they teach.

Each notebook is executed with nbclient (`VISJAX_NB_SHORT=1`). The test fails on any error
output, checks printed lines that could come out wrong (the notebooks also `assert` them:
a gradient against its central difference, a round trip, a result code), and, for the three
paper notebooks, that `jax.jit`, `jax.vmap` and `jax.grad` (or `jax.jacfwd`) are applied to
functions that build the paper's estimator and call `visjax.estimators.run`.
"""

import ast
import pathlib
import re

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = pathlib.Path(__file__).parents[1] / "notebooks"
SHORT = {"VISJAX_NB_SHORT": "1"}

# name -> (printed lines that must appear, estimator class of a paper notebook or None)
CASES = {
    "velocity.ipynb": (
        ("z1* measured", "result: successful", "traces so far: 1", "seeds in"),
        "VelocityEstimator",
    ),
    "moving_point.ipynb": (
        ("rank condition (3.20): True", "result: successful", "traces so far: 1", "seeds in"),
        "MovingPointEstimator",
    ),
    "static_points.ipynb": (
        ("covariance resets", "result: successful", "traces so far: 1", "seeds in"),
        "StaticPointsEstimator",
    ),
    "point_depth.ipynb": (
        ("closed loop, result: successful", "result: successful", "traces so far: 1", "seeds in"),
        "PointDepthEstimator",
    ),
    "homography.ipynb": (
        ("velocity front ends", "result: successful", "traces so far: 1", "seeds in"),
        "HomographyEstimator",
    ),
    "gain_tuning.ipynb": (
        ("held-out improvement", "certified Lipschitz bound", "central difference", "10 %"),
        None,
    ),
    "your_own_data.ipynb": (
        ("DataFormatError:", "exact round trip: True", "from the npz: 0.0e+00"),
        None,
    ),
}
# the first author each paper notebook's first cell cites (by name, never by file number)
AUTHORS = {
    "velocity.ipynb": "Chitrakaran",
    "moving_point.ipynb": "Jang",
    "static_points.ipynb": "Nath",
    "point_depth.ipynb": "Spica",
    "homography.ipynb": "Hamel",
}
# notebooks that print "relative difference: x" for a derivative against finite differences
GRADIENT_NOTEBOOKS = {
    "velocity.ipynb",
    "moving_point.ipynb",
    "static_points.ipynb",
    "gain_tuning.ipynb",
    "point_depth.ipynb",
    "homography.ipynb",
}


def _code(nb) -> str:
    """The code cells as one Python module (IPython magics dropped)."""
    cells = [c.source for c in nb.cells if c.cell_type == "code"]
    lines = [ln for c in cells for ln in c.splitlines() if not ln.lstrip().startswith(("%", "!"))]
    return "\n".join(lines)


def _dotted(node) -> str:
    """`jax.jit` for the expression `jax.jit`, `run` for `run`, else ''."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        inner = _dotted(node.value)
        return f"{inner}.{node.attr}" if inner else node.attr
    return ""


def _transformed(tree) -> dict[str, set[str]]:
    """For each JAX transformation applied in `tree`, the names of the notebook functions it
    is applied to (through nested transformations: `jax.jit(jax.vmap(f))` applies both to
    `f`)."""
    transforms = ("jax.jit", "jax.vmap", "jax.grad", "jax.jacfwd")
    found: dict[str, set[str]] = {t: set() for t in transforms}

    def target(node):
        if isinstance(node, ast.Name):
            return node.id
        if isinstance(node, ast.Call) and _dotted(node.func) in transforms and node.args:
            return target(node.args[0])
        return None

    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and _dotted(node.func) in transforms and node.args:
            name = target(node.args[0])
            if name:
                found[_dotted(node.func)].add(name)
    return found


def _calls(tree) -> dict[str, set[str]]:
    """For each function defined in `tree`, the names it calls (each dotted name's parts:
    `StaticPointsEstimator.from_nominal` gives both)."""
    out = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef):
            names = (_dotted(c.func) for c in ast.walk(node) if isinstance(c, ast.Call))
            out[node.name] = {part for name in names for part in name.split(".") if part}
    return out


@pytest.mark.parametrize("name", sorted(CASES))
def test_notebook_is_saved_clean(name):
    """Saved without outputs, papers named by their authors (never by a file number)."""
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    for cell in nb.cells:
        if cell.cell_type == "code":
            assert cell.get("outputs") == [] and cell.get("execution_count") is None, cell.source
        assert not re.search(r"\bseeds? 00[034]\b|\b00[034]_[0-9a-f]{8}", cell.source)
    if CASES[name][1] is not None:
        assert AUTHORS[name] in nb.cells[0].source, AUTHORS[name]


@pytest.mark.parametrize("name", [n for n, (_, cls) in CASES.items() if cls is not None])
def test_paper_notebook_transforms_the_public_api(name):
    """`jax.jit`, `jax.vmap` and `jax.grad` or `jax.jacfwd` are each applied to a function of
    the notebook that builds the estimator class and calls `visjax.estimators.run`."""
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    tree = ast.parse(_code(nb))
    calls = _calls(tree)
    estimator = CASES[name][1]

    def exercises_api(function):
        # calls `run` and builds the estimator, itself or through a helper of the notebook
        # (`with_alpha(est, z)` returns a copy of an estimator passed in)
        called = calls.get(function, set())
        helpers = set().union(*(calls.get(c, set()) for c in called))
        return "run" in called and bool({estimator, "tree_at"} & (called | helpers))

    applied = _transformed(tree)
    for transform in ("jax.jit", "jax.vmap"):
        assert any(exercises_api(f) for f in applied[transform]), (transform, applied)
    gradients = applied["jax.grad"] | applied["jax.jacfwd"]
    assert any(exercises_api(f) for f in gradients), applied
    assert f"{estimator}(" in _code(nb) or f"{estimator}.from_nominal(" in _code(nb)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CASES))
def test_notebook_executes(name, monkeypatch):
    for key, value in SHORT.items():
        monkeypatch.setenv(key, value)
    monkeypatch.delenv("VISJAX_NB_DURATION", raising=False)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    NotebookClient(
        nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(NOTEBOOKS)}}
    ).execute()
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not any(o.get("output_type") == "error" for o in outputs)
    text = "".join(
        o.get("text", "")
        for o in outputs
        if o.get("output_type") == "stream" and o.get("name") == "stdout"
    )
    for line in CASES[name][0]:
        assert line in text, line
    if name in GRADIENT_NOTEBOOKS:
        # the derivative through the whole run against a central difference
        rel = [float(x) for x in re.findall(r"relative difference: (\S+)", text)]
        assert rel and max(rel) < 1e-4, rel
