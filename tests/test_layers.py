"""The package structure, read from the source with ``ast``: the estimator's rooms import only
downwards, no module imports itself through others, and the packages depend one way
(``harness -> reports -> estimator``), the outer two through the estimator's public API only.

Imports under ``if TYPE_CHECKING:`` are annotations, never executed, and are not counted.
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# lowest first: a room may import its own modules and those of the rooms before it
ROOMS = ("core", "rays", "model", "solvers", "light", "pipeline", "diagnostics", "methods", "config", "api",
         "__init__")
# array math, UV unwrapping, BLAS threads; no renderer below rays
THIRD_PARTY_IN_CORE = {"numpy", "scipy", "xatlas", "threadpoolctl"}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _is_package(name: str) -> bool:
    return (ROOT / Path(*name.split(".")) / "__init__.py").exists()


def _exists(name: str) -> bool:
    return _is_package(name) or (ROOT / Path(*name.split("."))).with_suffix(".py").exists()


def _type_checking_lines(tree: ast.AST) -> set[int]:
    lines = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            for child in node.body:
                lines.update(range(child.lineno, (child.end_lineno or child.lineno) + 1))
    return lines


def imports_of(path: Path) -> set[str]:
    """The absolute names of the modules a file imports at run time (``from pkg import mod``
    counts as ``pkg.mod`` when that is a module)."""
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    tree = ast.parse(path.read_text())
    skip = _type_checking_lines(tree)
    found = set()
    for node in ast.walk(tree):
        if getattr(node, "lineno", None) in skip:
            continue
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - node.level + 1]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module
            for alias in node.names:
                full = f"{source}.{alias.name}"
                found.add(full if _exists(full) else source)
    return found


def _files(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


def _room(module: str) -> str:
    parts = module.split(".")
    return "__init__" if len(parts) == 1 else parts[1]


def test_every_estimator_module_lies_in_a_room():
    for path in _files("estimator"):
        assert _room(_module_name(path)) in ROOMS, f"{path.relative_to(ROOT)} lies outside the rooms {ROOMS}"


@pytest.mark.parametrize("path", _files("estimator"), ids=lambda p: str(p.relative_to(ROOT)))
def test_rooms_import_only_downwards(path):
    module = _module_name(path)
    rank = ROOMS.index(_room(module))
    for imported in imports_of(path):
        top = imported.split(".")[0]
        assert top not in ("harness", "reports"), f"{module} imports {imported}: the estimator stands alone"
        if top == "estimator" and imported != "estimator":
            assert ROOMS.index(_room(imported)) <= rank, f"{module} ({_room(module)}) imports {imported} (higher room)"
        if _room(module) == "core" and top != "estimator":
            assert top in THIRD_PARTY_IN_CORE or top in sys.stdlib_module_names, \
                f"{module} imports {imported}: core holds array types and math, no renderer"


def test_no_import_circle():
    graph = {}
    for package in ("estimator", "reports", "harness"):
        for path in _files(package):
            graph[_module_name(path)] = {m for m in imports_of(path) if m.split(".")[0] in graph or
                                         m.split(".")[0] in ("estimator", "reports", "harness")}
    state: dict[str, int] = {}

    def visit(node, trail):
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if nxt == node or nxt not in graph:
                continue
            if state.get(nxt) == 1:
                cycle = trail[trail.index(nxt):] + [nxt] if nxt in trail else [node, nxt]
                pytest.fail("import circle: " + " -> ".join(cycle))
            if nxt not in state:
                visit(nxt, trail + [nxt])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])


@pytest.mark.parametrize("package", ["reports", "harness"])
def test_outer_packages_use_the_public_api_and_point_one_way(package):
    for path in _files(package):
        for imported in imports_of(path):
            assert imported.split(".")[0] != "harness" or package == "harness", \
                f"{path.relative_to(ROOT)} imports {imported}: reports must not depend on harness"
            if imported.startswith("estimator."):
                public = imported.removeprefix("estimator.")
                assert public in _public_modules(), \
                    f"{path.relative_to(ROOT)} imports {imported}: use the public API (import estimator)"


def _public_modules() -> set[str]:
    """Modules re-exported by ``estimator/__init__.py`` (``from estimator import sh`` resolves to them)."""
    names = set()
    tree = ast.parse((ROOT / "estimator" / "__init__.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            for alias in node.names:
                full = f"estimator.{node.module}.{alias.name}" if node.module else f"estimator.{alias.name}"
                if _exists(full):
                    names.add(alias.name)
                    names.add(full.removeprefix("estimator."))
    return names
