"""The solver's layering: imports only core and itself, no function-level imports of project
modules, and no cycle between its modules (checked on the source, no import needed)."""
from __future__ import annotations

import ast
from pathlib import Path

import dockfactory.solver

SOLVER = Path(dockfactory.solver.__file__).parent


def _imports(path: Path):
    """(module-level project imports, function-level project imports) of a source file."""
    tree = ast.parse(path.read_text())
    top, nested = set(), []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and \
                node.module.startswith("dockfactory"):
            names = [node.module]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names if a.name.startswith("dockfactory")]
        else:
            continue
        (top.update(names) if node.col_offset == 0 else nested.extend(names))
    return top, nested


def test_solver_imports_only_core_and_itself():
    for path in SOLVER.glob("*.py"):
        top, nested = _imports(path)
        assert not nested, f"{path.name}: function-level project imports {nested}"
        bad = [m for m in top if not m.startswith(("dockfactory.core", "dockfactory.solver"))]
        assert not bad, f"{path.name} imports {bad}"


def test_solver_modules_form_no_cycle():
    graph = {}
    for path in SOLVER.glob("*.py"):
        if path.stem == "__init__":
            continue
        top, _ = _imports(path)
        graph[path.stem] = {m.rsplit(".", 1)[1] for m in top
                            if m.startswith("dockfactory.solver.")}
    done, active = set(), []

    def visit(mod):
        if mod in active:
            raise AssertionError("import cycle: " + " -> ".join(active + [mod]))
        if mod in done:
            return
        active.append(mod)
        for dep in sorted(graph.get(mod, ())):
            visit(dep)
        active.pop()
        done.add(mod)

    for mod in sorted(graph):
        visit(mod)
