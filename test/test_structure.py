"""The package's shape (docs/architecture.md, "Design rules"): no import cycle among its modules,
counting imports made only for type checking and lazy imports inside functions; no class over
350 lines and no function over 80; the numerical core imports nothing but the standard library
and the numerical stack (matplotlib only lazily, for plots), never rclpy.

The checks read the source with :mod:`ast` (nothing is imported), and are themselves tested on
a small planted package, so that a check that could never fail is caught."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "rls_uncertainty"
MAX_CLASS_LINES = 350
MAX_FUNCTION_LINES = 80

# The numerical core: the numerical stack and the standard library only (matplotlib lazily, for
# plots), never rclpy, a ROS message package, a bag or a web library.
NUMERICAL = {"numpy", "scipy"}
CORE = (
    "rls_uncertainty.estimator", "rls_uncertainty.frequency", "rls_uncertainty.aero",
    "rls_uncertainty.simulation", "rls_uncertainty.datapath", "rls_uncertainty.offline.results",
    "rls_uncertainty.offline.figure_data", "rls_uncertainty.campaign.table4",
    "rls_uncertainty.instruments",
)


def modules(package: Path) -> dict[str, tuple[Path, bool]]:
    """Dotted module name -> (file, is a package's ``__init__``), for every ``.py`` of the package."""
    out = {}
    for path in sorted(package.rglob("*.py")):
        if "node_modules" in path.parts:
            continue
        parts = list(path.relative_to(package.parent).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        out[".".join(parts[:-1] if is_package else parts)] = (path, is_package)
    return out


def imports(name: str, path: Path, is_package: bool) -> list[tuple[str, bool]]:
    """(dotted name, lazy) of every import of the module, anywhere in its body (top level,
    ``if TYPE_CHECKING:``, inside functions: lazy), relative imports resolved; ``from M import
    x`` gives both ``M`` and ``M.x`` (x may be a submodule)."""
    here = name if is_package else name.rpartition(".")[0]
    found = []

    def visit(node: ast.AST, lazy: bool) -> None:
        names: set[str] = set()
        if isinstance(node, ast.Import):
            names = {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here.split(".")[: len(here.split(".")) - node.level + 1]
                module = ".".join([*base, node.module] if node.module else base)
            else:
                module = node.module or ""
            names = {module} | {f"{module}.{alias.name}" for alias in node.names}
        found.extend((n, lazy) for n in sorted(names))
        inner = lazy or isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda)
        for child in ast.iter_child_nodes(node):
            visit(child, inner)

    visit(ast.parse(path.read_text()), False)
    return found


def import_graph(package: Path) -> dict[str, set[str]]:
    """Module -> the package's modules it imports (an imported name maps to its longest prefix
    that is a module: ``pkg.mod.Class`` -> ``pkg.mod``)."""
    known = modules(package)
    graph = {}
    for name, (path, is_package) in known.items():
        deps = set()
        for imported, _lazy in imports(name, path, is_package):
            target = imported
            while target and target not in known:
                target = target.rpartition(".")[0]
            if target and target != name:
                deps.add(target)
        graph[name] = deps
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle as ``[a, b, ..., a]``, or None (depth-first search, iterative)."""
    done: set[str] = set()
    for start in sorted(graph):
        if start in done:
            continue
        path, stack = [start], [iter(sorted(graph[start]))]
        while stack:
            following = next(stack[-1], None)
            if following is None:
                done.add(path.pop())
                stack.pop()
            elif following in path:
                return [*path[path.index(following):], following]
            elif following not in done:
                path.append(following)
                stack.append(iter(sorted(graph[following])))
    return None


def oversized(package: Path) -> list[str]:
    """Classes over MAX_CLASS_LINES and functions (methods and nested functions included) over
    MAX_FUNCTION_LINES, by qualified name, counted from the ``def``/``class`` line to the last
    line, docstring included."""
    found = []

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
                limit = MAX_CLASS_LINES if isinstance(child, ast.ClassDef) else MAX_FUNCTION_LINES
                lines = (child.end_lineno or child.lineno) - child.lineno + 1
                if lines > limit:
                    found.append(f"{prefix}.{child.name}: {lines} lines (at most {limit})")
                visit(child, f"{prefix}.{child.name}")
            else:
                visit(child, prefix)

    for name, (path, _) in modules(package).items():
        visit(ast.parse(path.read_text()), name)
    return found


def foreign_imports(package: Path, core: tuple[str, ...]) -> list[str]:
    """Imports of a core module (or of a module of a core package) outside the numerical
    stack: at module level anything but the standard library, numpy and scipy; inside a
    function (a lazy import, for plots only) anything but those and matplotlib."""
    top = package.name
    found = []
    for name, (path, is_package) in modules(package).items():
        if not any(name == c or name.startswith(c + ".") for c in core):
            continue
        for target, lazy in imports(name, path, is_package):
            first = target.split(".")[0]
            allowed = NUMERICAL | ({"matplotlib"} if lazy else set())
            if first and first not in sys.stdlib_module_names and first not in allowed | {top}:
                found.append(f"{name}: {target}" + (" (lazy)" if lazy else ""))
    return sorted(found)


# The wings from the ground up (docs/architecture.md, "Modules"): a wing imports only wings below it
# and the shared modules; wings on one floor do not import each other. A wing not listed (the
# front ends above the offline tools) may import anything below.
FLOORS = (
    ("errors",),
    ("extras", "progress"),
    ("schema", "files", "executors"),
    ("aero", "estimator"),
    ("frequency", "state_file", "instruments"),
    ("datapath",),
    ("settings",),
    ("simulation",),
    ("offline",),
    ("ros",),
)


def upward_imports(package: Path, floors: tuple[tuple[str, ...], ...]) -> list[str]:
    """Imports from a wing into a wing on its own floor or above it (the wing is the first part
    of a module's name below the package)."""
    floor = {wing: i for i, wings in enumerate(floors) for wing in wings}
    top = package.name
    found = []
    graph = import_graph(package)
    for name, targets in graph.items():
        wing = name.split(".")[1] if "." in name else ""
        if wing not in floor:
            continue
        for target in sorted(targets):
            other = target.split(".")[1] if "." in target else ""
            if other == wing or not target.startswith(top + "."):
                continue
            if other not in floor or floor[other] >= floor[wing]:
                found.append(f"{name} -> {target}")
    return found


def test_each_wing_imports_only_the_wings_below_it():
    assert upward_imports(PACKAGE, FLOORS) == []


def test_no_module_of_the_package_imports_into_a_cycle():
    cycle = find_cycle(import_graph(PACKAGE))
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def test_no_class_is_over_350_lines_and_no_function_over_80():
    assert oversized(PACKAGE) == []


def test_the_numerical_core_imports_only_numpy_and_the_standard_library():
    assert foreign_imports(PACKAGE, CORE) == []


@pytest.fixture
def planted(tmp_path: Path) -> Path:
    """A package with a cycle through a type-checking import and a lazy one, one class of 351
    lines, one function of 81 lines, core modules that import rclpy lazily and matplotlib at
    module level."""
    package = tmp_path / "pkg"
    (package / "sub").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "sub" / "__init__.py").write_text("from .b import B\n")
    (package / "a.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.sub import B\n")
    (package / "sub" / "b.py").write_text("class B:\n    def f(self):\n        from ..c import g\n")
    (package / "c.py").write_text("from . import a\n\ndef g():\n    import rclpy\n    import matplotlib\n")
    body = "\n".join(f"    x{i} = {i}" for i in range(350))
    (package / "d.py").write_text(f"class Big:\n{body}\n\nclass Small:\n    y = 0\n")
    body = "\n".join(f"    x{i} = {i}" for i in range(80))
    (package / "e.py").write_text(
        f"import numpy\nimport matplotlib\n\ndef long():\n{body}\n\ndef short():\n    return 0\n")
    return package


def test_the_checks_find_what_was_planted(planted: Path):
    cycle = find_cycle(import_graph(planted))
    assert cycle is not None and cycle[0] == cycle[-1]
    assert set(cycle) == {"pkg.a", "pkg.sub", "pkg.sub.b", "pkg.c"}
    assert oversized(planted) == ["pkg.d.Big: 351 lines (at most 350)", "pkg.e.long: 81 lines (at most 80)"]
    assert foreign_imports(planted, ("pkg.c", "pkg.e")) == ["pkg.c: rclpy (lazy)", "pkg.e: matplotlib"]


def test_the_wing_check_finds_an_import_into_a_wing_above_or_beside(planted: Path):
    # pkg.sub.b imports pkg.c (lazily), pkg.c imports pkg.a (a wing not listed: a front end).
    assert upward_imports(planted, (("c",), ("sub",))) == ["pkg.c -> pkg.a"]
    assert upward_imports(planted, (("sub",), ("c",))) == ["pkg.c -> pkg.a", "pkg.sub.b -> pkg.c"]
    assert upward_imports(planted, (("sub", "c", "a"),)) == ["pkg.a -> pkg.sub", "pkg.c -> pkg.a", "pkg.sub.b -> pkg.c"]
    (planted / "c.py").write_text("def g():\n    return 0\n")  # the cycle broken: c, then sub, then a
    assert upward_imports(planted, (("c",), ("sub",), ("a",))) == []


def test_an_acyclic_package_has_no_cycle(planted: Path):
    (planted / "c.py").write_text("def g():\n    return 0\n")
    assert find_cycle(import_graph(planted)) is None
