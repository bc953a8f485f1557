"""The layers of docs/architecture.md: imports flow down, OpenCV and cvxpy load only when used."""

import ast
import pathlib
import subprocess
import sys

PACKAGE = pathlib.Path(__file__).parents[1] / "visjax"
# a package imports only from those before it (and the shared bottom modules: result codes,
# input checks, small closed-form linear algebra, the XLA options)
LAYERS = [
    "geometry",
    "kinematics",
    "sim",
    "estimators",
    "baselines",
    "design",
    "io",
    "frontend",
    "studies",
    "plots",
    "papers",
]


def _absolute(path: pathlib.Path, node: ast.ImportFrom) -> list[str]:
    """The parts of the visjax module an import names, relative to the package (`from
    ...estimators import run` in `papers/jang/_problem.py` -> `["estimators"]`; `from ..
    import papers` -> `["papers"]`); empty for an import from outside visjax."""
    package = list(path.relative_to(PACKAGE).parts[:-1])
    if node.level:
        base = package[: len(package) - (node.level - 1)]
        return base + (node.module.split(".") if node.module else [])
    if node.module and node.module.split(".")[0] == "visjax":
        return node.module.split(".")[1:]
    return []


def _imported_subpackages(path: pathlib.Path) -> set[str]:
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            parts = _absolute(path, node)
            if parts:
                found.add(parts[0])
            elif node.level and not node.module:  # `from .. import papers` at the top
                found.update(alias.name for alias in node.names)
    return found


def test_imports_flow_down_the_layers():
    for i, name in enumerate(LAYERS):
        allowed = set(LAYERS[:i]) | {"_results", "_util", "_small", "_xla_workaround", "_version"}
        module = PACKAGE / f"{name}.py"
        for path in [module] if module.is_file() else (PACKAGE / name).rglob("*.py"):
            used = _imported_subpackages(path) - {name}
            assert used <= allowed, (str(path.relative_to(PACKAGE)), used - allowed)


def _module(path: pathlib.Path) -> str:
    parts = list(path.relative_to(PACKAGE).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _import_graph() -> dict[str, set[str]]:
    """Module -> the visjax modules it imports, every import counted (at the top or inside
    a function); `from X import y` is the module `X.y` where that is one."""
    modules = {_module(p): p for p in PACKAGE.rglob("*.py")}
    graph = {}
    for name, path in modules.items():
        found = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ImportFrom):
                continue
            parts = _absolute(path, node)
            if not parts and not (node.level and not node.module):
                continue
            for alias in node.names:
                target = ".".join([*parts, alias.name])
                while target and target not in modules:
                    target = target.rpartition(".")[0]
                if target != name:
                    found.add(target)
        graph[name] = found
    return graph


def test_no_import_circle():
    """Issue 45: no circle among the package's modules, function-local imports included
    (a package's `__init__` and the modules it re-exports included)."""
    graph = _import_graph()
    index, low, stack, circles = {}, {}, [], []

    def visit(v):  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while (w := stack.pop()) != v:
                component.append(w)
            if component:
                circles.append(sorted([v, *component]))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    assert circles == []
    assert len(graph) > 60 and sum(map(len, graph.values())) > 200  # the graph was read


def test_no_function_local_import_of_a_visjax_module():
    """Issue 45: every arrow is at the top of its module, where a reader sees it (optional
    heavy libraries may stay lazy)."""
    found = []
    for path in PACKAGE.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                for sub in ast.walk(node):
                    if isinstance(sub, ast.ImportFrom) and _absolute(path, sub):
                        found.append(f"{path.relative_to(PACKAGE)}:{sub.lineno}")
    assert found == []


def _private_imports(path: pathlib.Path) -> list[str]:
    """The modules of another subpackage that `path` imports by a private name
    (`from ..studies._parts import ...`, `from .io._staging import ...`): a subpackage's
    private modules are its own (the shared bottom modules `visjax._*` excepted)."""
    rel = path.relative_to(PACKAGE).parts
    own = rel[0] if len(rel) > 1 else None
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if not (isinstance(node, ast.ImportFrom) and node.module):
            continue
        if node.level >= 1:
            # resolve the relative import against the package of `path`
            base = list(rel[:-1])[: len(rel) - node.level] if node.level <= len(rel) - 1 else []
            parts = base + node.module.split(".")
        elif node.module.startswith("visjax."):
            parts = node.module.split(".")[1:]
        else:
            continue
        if len(parts) >= 2 and parts[0] != own and parts[1].startswith("_"):
            found.append(".".join(parts))
    return found


def test_no_import_of_another_packages_private_module():
    """Issue 45: a subpackage uses another one through its public names only."""
    bad = {
        str(path.relative_to(PACKAGE)): found
        for path in PACKAGE.rglob("*.py")
        if (found := _private_imports(path))
    }
    assert not bad, bad


PAPERS = {"papers", "chitrakaran", "jang", "nath", "spica", "hamel"}


def _paper_constants_used(path: pathlib.Path, source: str | None = None) -> list[str]:
    """The constants (UPPER_CASE names) of `visjax.papers` that a module (its `source`,
    default the file's) imports (`from .papers.chitrakaran import K_EQ63`) or reads as an
    attribute (`papers.jang.SETS`)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text() if source is None else source)):
        if isinstance(node, ast.ImportFrom) and PAPERS & set(_absolute(path, node)):
            found += [a.name for a in node.names if a.name.isupper()]
        elif isinstance(node, ast.Attribute) and node.attr.isupper():
            chain, value = [], node.value
            while isinstance(value, ast.Attribute):
                chain.append(value.attr)
                value = value.value
            if isinstance(value, ast.Name):
                chain.append(value.id)
            if PAPERS & set(chain):
                found.append(".".join([*reversed(chain), node.attr]))
    return found


def test_paper_constants_are_used_only_in_papers():
    """Issue 45: a paper's numbers (published gains, its scene's constants) are read in
    `visjax/papers` only; the command line takes its defaults from the registered
    problem's `parameters()`."""
    bad = {
        str(path.relative_to(PACKAGE)): found
        for path in PACKAGE.rglob("*.py")
        if "papers" not in path.relative_to(PACKAGE).parts
        and (found := _paper_constants_used(path))
    }
    assert not bad, bad
    # the check sees what it looks for
    source = "from .papers.chitrakaran import K_EQ63\nx = papers.jang.SETS\n"
    found = _paper_constants_used(PACKAGE / "probe.py", source)
    assert found == ["K_EQ63", "papers.jang.SETS"]


def test_importing_visjax_loads_neither_opencv_nor_cvxpy():
    code = (
        "import sys, visjax; "
        "assert 'cv2' not in sys.modules and 'cvxpy' not in sys.modules, "
        "[m for m in ('cv2', 'cvxpy') if m in sys.modules]"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]


def test_only_the_command_line_sets_float64():
    """`DESIGN.md`: float64 is set once, in `cli.main`; the library never flips the global
    flag (`jax.config.update("jax_enable_x64", ...)`, `jax.enable_x64(...)` outside a
    `with` that restores it)."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text())
        restoring = {
            id(item.context_expr) for node in ast.walk(tree) if isinstance(node, ast.With)
            for item in node.items
        }  # fmt: skip
        for node in ast.walk(tree):
            if not isinstance(node, ast.Call) or id(node) in restoring:
                continue
            text = ast.unparse(node.func)
            args = [a.value for a in node.args if isinstance(a, ast.Constant)]
            if (text.endswith("config.update") and "jax_enable_x64" in args) or text.endswith(
                "enable_x64"
            ):
                found.append(f"{path.relative_to(PACKAGE)}:{node.lineno}")
    assert len(found) == 1 and found[0].startswith("cli.py:"), found


def test_every_registered_problem_is_final():
    """`DESIGN.md`: a paper's problems are `@final` (a method is added to a registered
    problem without subclassing it); read from each builder's return annotation."""
    import typing

    import visjax.papers  # noqa: F401  (registers the papers' problems)
    from visjax import studies

    papers = [
        n
        for n in studies.problem_names()
        if studies.registered(n).build.__module__.startswith("visjax.papers")
    ]  # not a test's own registered problems
    assert len(papers) == 5, papers
    for name in papers:
        returned = typing.get_type_hints(studies.registered(name).build)["return"]
        classes = typing.get_args(returned) or (returned,)
        for cls in classes:
            assert getattr(cls, "__final__", False), (name, cls.__name__)


LINE_LIMITS = {"cli.py": 300, "verbs.py": 350}
"""Issue 45 and `DESIGN.md`: the command line parses and dispatches, the commands call the
studies, print and write; what either grows past its limit belongs in `studies` (or in
`_options.py`, the option vocabulary)."""


def test_the_command_line_and_the_commands_stay_small():
    long = {
        name: lines
        for name, limit in LINE_LIMITS.items()
        if (lines := len((PACKAGE / name).read_text().splitlines())) > limit
    }
    assert not long, long
