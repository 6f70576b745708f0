"""The code's layering holds: no import cycle among the Python package's modules (the layers
between packages are import-linter's contracts, `make lint`) nor among the Rust core's files,
and no function-level import of sitgen dodges one."""

from __future__ import annotations

import ast
import re
from pathlib import Path

from tests.conftest import ROOT

PYTHON = ROOT / "python" / "sitgen"
CORE = ROOT / "crates" / "sitgen-core" / "src"


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one node (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return found


def _python_modules() -> dict[str, Path]:
    modules = {}
    for path in PYTHON.rglob("*.py"):
        parts = ["sitgen", *path.relative_to(PYTHON).with_suffix("").parts]
        if parts[-1] == "__init__":
            parts.pop()
        modules[".".join(parts)] = path
    return modules


def test_no_python_module_imports_itself_round_a_cycle() -> None:
    modules = _python_modules()
    edges: dict[str, set[str]] = {}
    lazy = []
    for name, path in modules.items():
        tree = ast.parse(path.read_text())
        guarded = {id(n) for top in tree.body if isinstance(top, ast.If) for n in ast.walk(top)}
        for node in ast.walk(tree):
            if not (isinstance(node, ast.ImportFrom) and node.module and node.level == 0):
                continue
            targets = [f"{node.module}.{a.name}" for a in node.names] + [node.module]
            target = next((t for t in targets if t in modules and t != "sitgen"), None)
            if target is None or target == name:
                continue
            edges.setdefault(name, set()).add(target)
            if (
                node.col_offset > 0
                and id(node) not in guarded
                and not name.startswith("sitgen.cli")
            ):
                lazy.append(f"{name}:{node.lineno} imports {target}")
    assert _cycles(edges) == []
    # The CLI imports each command's modules when the command runs, to start fast.
    assert lazy == [], "a function-level import hides a dependency"


def test_no_rust_core_file_imports_itself_round_a_cycle() -> None:
    files = {}
    for path in CORE.rglob("*.rs"):
        parts = list(path.relative_to(CORE).with_suffix("").parts)
        if parts[-1] in ("mod", "lib"):
            parts.pop()
        if "tests" in parts or parts[-1:] == ["test_data"]:
            continue
        files[tuple(parts)] = path
    edges: dict[str, set[str]] = {}
    for module, path in files.items():
        text = path.read_text().split("#[cfg(test)]")[0]
        for base, group in re.findall(
            r"use\s+((?:crate|super|self)(?:::\w+)*)(?:::\{([^;]*)\})?", text
        ):
            paths = [base] + [
                f"{base}::{g.strip().split('::')[0]}" for g in group.split(",") if g.strip()
            ]
            for used in paths:
                steps = used.split("::")
                here = {"crate": [], "super": list(module[:-1]), "self": list(module)}[steps[0]]
                steps = steps[1:]
                while steps and steps[0] == "super":
                    here, steps = here[:-1], steps[1:]
                full = here + steps
                target = next(
                    (tuple(full[:n]) for n in range(len(full), 0, -1) if tuple(full[:n]) in files),
                    None,
                )
                # A child using its parent's items is how Rust modules nest, not a cycle.
                if target is None or target == module or module[: len(target)] == target:
                    continue
                edges.setdefault("::".join(module), set()).add("::".join(target))
    assert _cycles(edges) == []
