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


def _imported_subpackages(path: pathlib.Path) -> set[str]:
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level >= 1 and node.module:
            rel = path.relative_to(PACKAGE).parts
            if node.level == 2 or (node.level == 1 and len(rel) == 1):
                found.add(node.module.split(".")[0])
        elif isinstance(node, ast.ImportFrom) and node.level == 2 and not node.module:
            found.update(alias.name for alias in node.names)  # `from .. import papers`
        elif isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("visjax."):
            found.add(node.module.split(".")[1])
    return found


def test_imports_flow_down_the_layers():
    for i, name in enumerate(LAYERS):
        allowed = set(LAYERS[:i]) | {"_results", "_util", "_small", "_xla_workaround", "_version"}
        module = PACKAGE / f"{name}.py"
        for path in [module] if module.is_file() else (PACKAGE / name).glob("*.py"):
            used = _imported_subpackages(path) - {name}
            assert used <= allowed, (path.name, used - allowed)


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
