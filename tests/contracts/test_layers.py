"""Layers point one way and modules import without cycles (static: the sources are parsed, never
imported; see tests/layercheck.py for how the walk, the contract and the cycle search work).

    dockfactory.core  <-  blender_scenes, solver, detector, generator (blender_scenes only inside
    functions)  <-  eval  <-  the app (modules of the dockfactory/ folder: cli, pipeline, measure,
    ablate);   dockfactory/__init__ imports nothing, __main__ only dockfactory.entry (which imports
    dockfactory.cli inside its function, after setting the environment).

Function-level imports only for heavy optional dependencies (torch, kornia, bpy, mathutils, ray,
matplotlib, onnx, onnxruntime, weasyprint) or for a project module that imports one of them at module level,
and in a package's lazy facade (PEP 562 ``__getattr__`` of its ``__init__``) for its own modules.
The checker is shown to fail on a miniature tree with deliberate violations
(tests/layer_fixture/), so a green run means something.
"""
from pathlib import Path

from layercheck import (
    DISCOVERS_ITS_MODULES,
    collect_imports,
    cycles,
    heavy_modules,
    layer_violations,
    source_tree,
    strongly_connected,
)

FIXTURE = Path(__file__).resolve().parents[1] / "layer_fixture"


def _report(title: str, items: list[str]) -> str:
    return f"{len(items)} {title}:\n  " + "\n  ".join(items)


def test_the_walk_sees_every_module_of_the_package(repo_root):
    modules = source_tree(repo_root)
    for name in ("dockfactory", "dockfactory.__main__", "dockfactory.core.config",
                 "dockfactory.generator.render_worker", "dockfactory.blender_scenes.render",
                 "dockfactory.solver.docking", "dockfactory.detector.model", "dockfactory.cli",
                 "dockfactory.configs", "dockfactory.models"):
        assert name in modules
    _, imports = collect_imports(repo_root)
    assert any(i.where == "function" for i in imports) and any(i.where == "module" for i in imports)
    heavy = heavy_modules(imports, modules)
    assert {"dockfactory.blender_scenes.render", "dockfactory.detector.model"} <= heavy
    assert not any(m.startswith(("dockfactory.core", "dockfactory.solver")) for m in heavy)


def test_layers_point_one_way(repo_root):
    modules, imports = collect_imports(repo_root)
    bad = layer_violations(imports, modules)
    assert not bad, _report("import(s) break the layer contract", bad)


def test_no_module_cycles(repo_root):
    modules, imports = collect_imports(repo_root)
    found = cycles(imports, modules)
    assert not found, _report("module-level import cycle(s)", found)


def test_no_dynamic_imports(repo_root):
    """The walk cannot see importlib.import_module / __import__: keep the package free of them, but
    for the packages that import their own folder's modules (DISCOVERS_ITS_MODULES), whose imports
    the walk records: one module-level import of each module of the folder."""
    tree = source_tree(repo_root)
    hits = [name for name, p in tree.items() if "import_module(" in p.read_text() or "__import__(" in p.read_text()]
    assert sorted(hits) == sorted(DISCOVERS_ITS_MODULES), hits
    _, imports = collect_imports(repo_root)
    for package in DISCOVERS_ITS_MODULES:
        own = {m for m in tree if m.rpartition(".")[0] == package}
        seen = {i.target for i in imports if i.module == package and i.where == "module"}
        assert own and own <= seen, sorted(own - seen)


def test_the_checker_fails_on_deliberate_violations():
    modules, imports = collect_imports(FIXTURE)
    bad = layer_violations(imports, modules)
    flagged = sorted({b.split(": ")[0] for b in bad})
    assert flagged == sorted([
        "core/config.py:2",          # upward: core -> eval
        "core/io.py:2",              # upward, relative: core -> generator (from ..generator import)
        "solver/sideways.py:2",      # sideways: solver -> detector
        "solver/docking.py:6",       # function level, not heavy (a cycle dodged in a function)
        "detector/infer.py:7",       # function level: cv2 is not heavy
        "generator/sampler.py:2",    # generator -> blender_scenes at module level
        "generator/worker.py:5",     # upward, even under TYPE_CHECKING
        "generator/__init__.py:9",   # a lazy facade's __getattr__ imports another package's module
        "dockfactory/cli.py:2",      # nothing imports the entry point
        "dockfactory/cli.py:6",      # function level, not heavy
        "eval/judge.py:2",           # upward: the judge imports the app layer
        "configs/__init__.py:2",     # a data package imports the project
        "dockfactory/__init__.py:2",  # the root package imports a subpackage
    ]), "\n".join(bad)
    # what is fine stays fine: heavy deps and heavy project modules in functions, relative
    # sibling imports, __main__ -> eval.cli, blender_scenes -> core, eval -> anything below
    for ok in ("core/geometry.py", "detector/model.py", "blender_scenes/render.py",
               "eval/report.py", "dockfactory/__main__.py", "dockfactory/entry.py", "solver/identify.py",
               "dockfactory/pipeline.py"):
        assert not any(b.startswith(ok) for b in bad), ok
    assert {"detector/infer.py:5", "detector/infer.py:6", "generator/worker.py:9",
            "generator/__init__.py:7"}.isdisjoint(flagged)   # (:7: a lazy facade's own module)
    assert heavy_modules(imports, modules) >= {"dockfactory.detector.model",
                                               "dockfactory.blender_scenes.render"}


def test_the_cycle_check_fails_on_deliberate_cycles():
    modules, imports = collect_imports(FIXTURE)
    found = cycles(imports, modules)
    assert sorted(found) == [
        "dockfactory.__main__ -> dockfactory.entry -> dockfactory.cli -> dockfactory.__main__",
        "dockfactory.core.cycle_a -> dockfactory.core.cycle_b -> dockfactory.core.cycle_a",
    ], found
    # the cycle dodged inside solver.docking's function is not a runtime edge (the layer check
    # reports it instead): no cycle between solver.docking and solver.identify
    assert not any("solver" in c for c in found)


def test_tarjan_on_small_graphs():
    g = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"e"}, "f": {"d"}}
    comps = strongly_connected(g)
    assert sorted(comps) == [["a", "b", "c"], ["d"], ["e"], ["f"]]
    chain = {str(i): {str(i + 1)} for i in range(3000)} | {"3000": {"0"}}   # deep: no recursion limit
    assert [len(c) for c in strongly_connected(chain)] == [3001]
