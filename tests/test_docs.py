"""The documentation site: `mkdocs build --strict` succeeds, every public name of the package
has its entry in the API reference, and the pages' code names only what exists."""

import ast
import base64
import importlib
import importlib.util
import os
import re
import subprocess
import sys
import time
import tomllib
import types
from pathlib import Path

import pytest
import yaml

from visjax import __version__

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

# the subpackages whose `__init__.py` re-exports the public API
PACKAGES = (
    "geometry",
    "kinematics",
    "sim",
    "estimators",
    "baselines",
    "design",
    "frontend",
    "io",
    "studies",
    "plots",
)
# the papers' modules, documented member by member
PAPERS = ("chitrakaran", "jang", "nath", "spica", "hamel")

# page -> the key figure it shows (figures/NAME.png, from the notebook cell tagged figure-NAME)
KEY_FIGURES = {
    "papers/velocity": "velocity",
    "papers/moving_point": "moving-point",
    "testbed": "testbed",
    "papers/static_points": "static-points",
    "papers/point_depth": "point-depth",
    "papers/homography": "homography",
    "runner": "runner",
    "sweeps-and-tuning": "sweep",
    "your-own-data": "own-data",
    "baselines": "comparison",
    "tables": "tables",
    "geometry": "geometry",
    "extending": "point-depth",
    "errors": "errors",
    "command-line": "comparison",
    "cluster": "sweep",
    "outputs": "tables",
}
# page -> the figure drawn from the repository's records (docs/_hooks/reference_figures.py)
RECORD_FIGURES = {"performance": "performance", "gpu": "float32", "architecture": "layers"}
# page -> API entries its prose links to (by docs/_hooks/api_links.py)
API_LINKS = {
    "runner": ["visjax.estimators.run", "visjax.estimators.SaveAt"],
    "sweeps-and-tuning": ["visjax.studies.sweep", "visjax.studies.tune"],
    "your-own-data": ["visjax.io.data_from_tracks"],
    "baselines": ["visjax.studies.compare"],
    "testbed": ["visjax.papers.jang.testbed"],
}

pytestmark = pytest.mark.skipif(
    not (ROOT / "mkdocs.yml").exists(), reason="no mkdocs.yml (not a source checkout)"
)


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The site, built once for this module: `(site directory, build seconds)`."""
    out = tmp_path_factory.mktemp("site")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1", VISJAX_NB_SHORT="1")  # notebooks: short
    start = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    elapsed = time.perf_counter() - start
    tail = (proc.stdout + proc.stderr)[-4000:]
    assert proc.returncode == 0, f"mkdocs build --strict failed ({elapsed:.1f} s):\n{tail}"
    return out, elapsed


def _package_names(name: str) -> set[str]:
    """The public names `visjax.<name>` re-exports: everything in `dir()` that is neither
    private nor a module."""
    module = importlib.import_module(f"visjax.{name}")
    return {
        n
        for n in dir(module)
        if not n.startswith("_") and not isinstance(getattr(module, n), types.ModuleType)
    }


def _paper_names(name: str) -> set[str]:
    """The public names defined (not imported) at the top level of `visjax.papers.<name>`."""
    module = importlib.import_module(f"visjax.papers.{name}")
    tree = ast.parse(Path(module.__file__).read_text())
    names = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return {n for n in names if not n.startswith("_")}


def _public_names() -> dict[str, set[str]]:
    """Every documented object's full path, by module."""
    names = {f"visjax.{p}": _package_names(p) for p in PACKAGES}
    names.update({f"visjax.papers.{p}": _paper_names(p) for p in PAPERS})
    names["visjax"] = {"RESULTS", "result_names"}
    return names


@pytest.mark.slow  # the documentation build: the second command (.ci/run)
def test_site_builds_strict_with_every_public_name(site):
    """The strict build succeeds (the fixture), and the API reference has an entry (an
    anchor `id="visjax.<module>.<name>"`) for every public name and for each result code
    visjax adds to diffrax's. One test, so that under pytest-xdist the site is built once."""
    out, elapsed = site
    print(f"mkdocs build --strict: {elapsed:.1f} s")
    pages = ("index", "papers/velocity", "papers/moving_point", "papers/static_points", "runner")
    for page in pages:
        assert (out / page.removesuffix("index") / "index.html").exists(), page

    html = "\n".join(p.read_text() for p in sorted((out / "api").rglob("*.html")))
    anchors = set(re.findall(r'id="(visjax[\w.]*)"', html))
    names = _public_names()
    assert all(names.values()), {m: n for m, n in names.items() if not n}
    missing = sorted(
        f"{module}.{name}"
        for module, module_names in names.items()
        for name in module_names
        if f"{module}.{name}" not in anchors
    )
    assert not missing, f"public names without an entry in the API reference: {missing}"

    tree = ast.parse((ROOT / "visjax" / "_results.py").read_text())
    (cls,) = [n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "RESULTS"]
    codes = [t.id for n in cls.body if isinstance(n, ast.Assign) for t in n.targets]
    assert len(codes) >= 10, codes
    missing = [c for c in codes if f"visjax.RESULTS.{c}" not in anchors]
    assert not missing, f"result codes without an entry in the API reference: {missing}"

    # the notebooks, executed by the build, rendered with their figures
    for notebook in sorted((ROOT / "notebooks").glob("*.ipynb")):
        page = (out / "notebooks" / notebook.stem / "index.html").read_text()
        assert page.count("data:image/png;base64") >= 1, notebook.name
        assert "Traceback" not in page, notebook.name
    # each paper page and guide shows its key figure: the PNG its notebook's tagged cell drew
    drawn = {
        base64.b64decode(b)
        for notebook in (out / "notebooks").glob("*/index.html")
        for b in re.findall(r"data:image/png;base64,([A-Za-z0-9+/=]+)", notebook.read_text())
    }
    for page, name in KEY_FIGURES.items():
        html = (out / page / "index.html").read_text()
        assert re.search(rf'<img [^>]*src="(\.\./)+figures/{name}\.png"', html), (page, name)
        png = (out / "figures" / f"{name}.png").read_bytes()
        assert png.startswith(b"\x89PNG") and len(png) > 10_000, (name, len(png))
        assert png in drawn, name
    for page, name in RECORD_FIGURES.items():
        html = (out / page / "index.html").read_text()
        assert re.search(rf'<img [^>]*src="(\.\./)+figures/{name}\.png"', html), (page, name)
        assert (out / "figures" / f"{name}.png").read_bytes().startswith(b"\x89PNG"), name
    # every guide of the nav shows a figure
    nav = yaml.safe_load((ROOT / "mkdocs.yml").read_text().replace("!!python", "#"))["nav"]
    guides = [p.removesuffix(".md") for g in nav if "Guides" in g for d in g["Guides"]
              for p in d.values()]  # fmt: skip
    shown = set(KEY_FIGURES) | set(RECORD_FIGURES)
    assert set(guides) <= shown, sorted(set(guides) - shown)
    # the names a page writes as code link to their API entries, first use on each page
    for page, names in API_LINKS.items():
        html = (out / page / "index.html").read_text()
        for full in names:
            module = full.rsplit(".", 1)[0].removeprefix("visjax.").split(".")[0]
            assert re.search(rf'href="(\.\./)+api/{module}/#{re.escape(full)}"', html), (
                page,
                full,
            )
    # the equations need no network: MathJax is served with the site, no page loads a CDN
    assert (out / "_static" / "mathjax" / "MathJax.js").is_file()
    assert (out / "_static" / "mathjax" / "config" / "TeX-AMS-MML_HTMLorMML-full.js").is_file()
    mathjax_url = re.compile(r"""https?://[^"' ]*mathjax""", re.I)
    for page in out.rglob("*.html"):
        assert not mathjax_url.search(page.read_text()), page
    # long code lines scroll inside their block, never cut
    assert "white-space: pre" in (out / "_static" / "extra.css").read_text()


def _code_blocks(language: str):
    for page in sorted(DOCS.rglob("*.md")):
        for block in re.findall(rf"```{language}\n(.*?)```", page.read_text(), flags=re.S):
            yield page.relative_to(DOCS), block


def test_python_blocks_parse_and_import_what_exists():
    """Every Python block parses, and every name it imports from visjax exists (a block
    that calls `run(...)` with `...` is a signature, not code)."""
    checked = 0
    for page, block in _code_blocks("python"):
        if block.lstrip().startswith("run(estimator"):
            continue
        tree = ast.parse(block, filename=str(page))
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.ImportFrom)
                and node.module
                and node.module.startswith("visjax")
            ):
                module = importlib.import_module(node.module)
                for alias in node.names:
                    assert hasattr(module, alias.name) or importlib.util.find_spec(
                        f"{node.module}.{alias.name}"
                    ), f"{page}: `from {node.module} import {alias.name}`: no such name"
                checked += 1
    assert checked > 0


def test_pages_name_the_papers_not_their_files():
    for page in sorted(DOCS.rglob("*.md")):
        text = page.read_text()
        found = re.findall(r"seed[ -]?00[034]|00[034]_[0-9a-f]{16}", text, flags=re.I)
        assert not found, f"{page.relative_to(DOCS)}: {found}"


def test_changelog_citation_and_license_agree_with_the_package():
    """CHANGELOG.md's newest version is the package's, versions newest first; CITATION.cff
    parses as YAML with the fields CFF 1.2 requires, the package's version and the five
    papers visjax implements; LICENSE is the Apache-2.0 text pyproject.toml declares."""
    versions = re.findall(
        r"^## (\d+\.\d+\.\d+) \(\d{4}-\d\d-\d\d\)$", (ROOT / "CHANGELOG.md").read_text(), re.M
    )
    assert versions and versions[0] == __version__
    as_tuples = [tuple(map(int, v.split("."))) for v in versions]
    assert as_tuples == sorted(as_tuples, reverse=True) and len(set(versions)) == len(versions)

    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert {"cff-version", "message", "title", "authors"} <= set(cff)
    assert str(cff["version"]) == __version__
    titles = " | ".join(ref["title"] for ref in cff["references"]).lower()
    for words in (
        "moving object's velocity",
        "unknown input observer",
        "uncalibrated camera",
        "active structure from motion",
        "special linear group",
    ):
        assert words in titles, words
    assert all(ref["authors"] for ref in cff["references"])

    license_text = (ROOT / "LICENSE").read_text()
    assert "Apache License" in license_text and "Version 2.0, January 2004" in license_text
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["license"]["text"] == cff["license"] == "Apache-2.0"


def test_tables_page_names_every_problems_columns_and_units():
    """docs/tables.md documents each founding and landmark problem's named columns (each
    field of its `columns`, the first component's name) and every key of its `units`."""
    from visjax.papers.chitrakaran import VelocityProblem
    from visjax.papers.hamel import HomographyProblem
    from visjax.papers.jang import MovingPointProblem
    from visjax.papers.nath import StaticPointsProblem
    from visjax.papers.spica import PointDepthProblem

    page = (DOCS / "tables.md").read_text()
    for cls in (
        VelocityProblem, MovingPointProblem, StaticPointsProblem, PointDepthProblem,
        HomographyProblem,
    ):  # fmt: skip
        assert cls.units, cls.__name__
        for field, names in cls.columns.items():
            assert f"`{field}`" in page, (cls.__name__, field)
            if isinstance(names, tuple):  # the first component named, the rest by pattern
                assert f"`{names[0]}`" in page, (cls.__name__, names[0])
        components = {
            n for names in cls.columns.values() if isinstance(names, tuple) for n in names
        }
        for key in set(cls.units) - components:
            assert f"`{key}`" in page, (cls.__name__, key)
