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


# The solver's internal layer order (solver/__init__.py): a module imports only modules of its
# own layer or below. Every module must be placed here, so a new one states its layer.
LAYERS = {
    # 0 base
    "errors": 0, "options": 0, "checks": 0, "lie": 0, "outline": 0, "stats": 0,
    "camera_models": 0, "model_choice": 0, "layout_points": 0, "synthetic": 0,
    # 1 closed form
    "upnp": 1,
    # 2 refinement (the one LM, Jacobian, covariance) and the bounds on the same Jacobian
    "refine": 2, "crb": 2,
    # 3 estimators
    "estimate": 3, "model_fit": 3, "model_error": 3, "section_shift": 3, "joint": 3, "focal_prior": 3, "focal_profile": 3, "focal_basins": 3,
    # 4 robust estimation and identification
    "ransac": 4, "identify": 4,
    # 5 entry points and the docking pipeline
    "pnpf": 5, "docking": 5, "suspects": 5, "eccentricity": 5, "sequence": 5, "disc_noise": 5,
}


def test_solver_layer_order():
    modules = {p.stem for p in SOLVER.glob("*.py")} - {"__init__"}
    assert modules == set(LAYERS), f"place new modules in LAYERS: {sorted(modules ^ set(LAYERS))}"
    for path in SOLVER.glob("*.py"):
        if path.stem == "__init__":
            continue
        top, _ = _imports(path)
        deps = {m.rsplit(".", 1)[1] for m in top if m.startswith("dockfactory.solver.")}
        up = sorted(d for d in deps if LAYERS[d] > LAYERS[path.stem])
        assert not up, f"{path.stem} (layer {LAYERS[path.stem]}) imports upward: {up}"


def test_the_refinement_has_one_lm_loop():
    """Every refinement (one section, two sections, residual blocks with a camera model) runs
    the one Levenberg-Marquardt loop of solver/refine.py: only refine.py solves damped normal
    equations (the closed form, upnp.py, solves its own linear systems)."""
    for path in SOLVER.glob("*.py"):
        if path.stem not in ("refine", "upnp"):
            assert "linalg.solve" not in path.read_text(), path.name
    assert "def refine_blocks(" in (SOLVER / "refine.py").read_text()
