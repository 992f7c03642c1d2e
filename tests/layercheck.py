"""The import-layer checker behind tests/contracts/test_layers.py (tests only; reads sources, imports nothing).

How it works
------------
1. The source tree: pyproject.toml's ``[tool.setuptools.package-dir]`` maps each package of the one
   import root to its folder (``dockfactory.solver`` -> ``solver/``); every ``*.py`` in those folders
   is a module (``solver/docking.py`` -> ``dockfactory.solver.docking``, ``__init__.py`` -> the
   package itself).
2. Every ``import`` / ``from ... import`` statement of every module is parsed with ``ast`` (nothing is
   imported or executed). Relative imports are resolved against the module's package
   (``from . import x`` in ``dockfactory.solver.docking`` -> ``dockfactory.solver.x``). ``from P import
   n`` targets the module ``P.n`` when that is a module of the tree, else ``P``. Each import is
   recorded with its place: module level (including ``if``/``try`` blocks at module level),
   inside a function (any ``def``/``lambda`` body, however nested, including methods), directly
   in a package ``__init__``'s module-level ``__getattr__`` (a PEP 562 lazy facade), or under
   ``if TYPE_CHECKING:`` (never executed: layer-checked, but not an edge of the runtime graph).
3. Layers: each module belongs to the subpackage its name starts with. The contract:

       dockfactory.core            -> (nothing of the project)
       dockfactory.blender_scenes  -> core
       dockfactory.solver          -> core
       dockfactory.detector        -> core
       dockfactory.generator       -> core; blender_scenes only inside functions (it imports bpy)
       dockfactory.eval            -> core, blender_scenes, solver, detector, generator
       dockfactory.<module> (app)  -> every layer above: the command line, run, measure, ablate
       dockfactory (root __init__) -> nothing;  dockfactory.__main__ -> dockfactory.entry only
       dockfactory.configs, dockfactory.models (data packages) -> nothing

   Any module may import its own subpackage and the root ``dockfactory`` package (which imports
   nothing); nothing may import ``dockfactory.__main__``. Anything else is an upward or sideways
   import: a violation.
4. Imports inside functions are allowed only for heavy optional dependencies: HEAVY below (torch
   and kornia, which imports torch; bpy and its mathutils; ray; matplotlib; onnx and onnxruntime,
   the optional ``export-onnx`` extra; weasyprint, the optional ``pdf`` extra of ``report --pdf``).
   Each costs from one to over ten seconds to import here, or
   needs an extra. cv2, pycocotools and OpenEXR are required dependencies that import in well under
   a second and are imported at module level elsewhere in the package, so they are not heavy; neither
   is the standard library. A function-level import of a project module is allowed only when that
   module is heavy itself: its module-level imports reach a HEAVY dependency, directly or through
   other project modules' module-level imports (``dockfactory.blender_scenes.*`` through bpy,
   ``dockfactory.detector.model`` through torch). Everything else at function level is a
   violation (hiding a cycle, or a cheap import, inside a function), except ``dockfactory.entry``'s
   import of ``dockfactory.cli``, which must run after the entry point has set the environment, and
   a lazy facade's imports of its own package's modules (``dockfactory.generator``'s ``__getattr__``:
   importing the package loads none of them); a lazy facade importing anything else is a violation.
   Neither is an edge of the runtime graph, nor makes its importer heavy.
5. Cycles: the graph of module-level (runtime) imports between the tree's modules has no cycle.
   Strongly connected components are found with Tarjan's algorithm; any component of more than one
   module, or a module importing itself, is reported with one cycle through it. The implicit import
   of a parent package (importing ``a.b.c`` runs ``a/b/__init__``) is not an edge: it would make
   every re-exporting ``__init__`` a cycle with its own submodules; an explicit ``from
   dockfactory.solver import x`` inside a solver module is an edge (and a real cycle when the
   ``__init__`` imports that module).

Dynamic imports (``importlib.import_module``, ``__import__``) are not seen; the package has one,
declared here: a package in DISCOVERS_ITS_MODULES (the export registry, ``generator/exports``)
imports every module of its folder in its ``__init__``, recorded as a module-level import of each
(``test_no_dynamic_imports`` keeps every other module free of them).
"""
from __future__ import annotations

import ast
import tomllib
from dataclasses import dataclass
from pathlib import Path

ROOT_PKG = "dockfactory"

# who may import whom (subpackage -> the subpackages it may import at module level or in functions)
ALLOWED = {
    "core": set(),
    "blender_scenes": {"core"},
    "solver": {"core"},
    "detector": {"core"},
    "generator": {"core", "blender_scenes"},
    "eval": {"core", "blender_scenes", "solver", "detector", "generator"},
    "app": {"core", "blender_scenes", "solver", "detector", "generator", "eval"},
    "configs": set(),
    "models": set(),
}
# (importer subpackage, imported subpackage) allowed only inside functions
FUNCTION_ONLY = {("generator", "blender_scenes")}
MAIN_MAY_IMPORT = {"dockfactory.entry"}
# the command's entry point sets the process's environment before numpy loads, so it imports the
# command line inside its function: the one function-level import whose point is its order
ENTRY_DEFERS = {("dockfactory.entry", "dockfactory.cli")}

HEAVY = {"torch", "kornia", "bpy", "mathutils", "ray", "matplotlib", "onnx", "onnxruntime", "weasyprint"}
# packages whose __init__ imports every module of its own folder at module level (pkgutil and
# importlib: a module added to the folder registers itself); the walk records those imports
DISCOVERS_ITS_MODULES = {"dockfactory.generator.exports"}


@dataclass(frozen=True)
class Import:
    module: str      # importer
    target: str      # imported module (resolved, absolute)
    line: int
    where: str       # "module" | "function" | "type-checking"
    path: str        # importer's file, relative to the tree root


def source_tree(root: Path) -> dict[str, Path]:
    """``{module name: file}`` of every module of the package-dir mapping in ``root/pyproject.toml``."""
    pyproject = tomllib.loads((root / "pyproject.toml").read_text())
    mapping = pyproject["tool"]["setuptools"]["package-dir"]
    modules = {}
    for pkg, folder in mapping.items():
        for path in sorted((root / folder).glob("*.py")):
            modules[pkg if path.stem == "__init__" else f"{pkg}.{path.stem}"] = path
    return modules


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


class _Collector(ast.NodeVisitor):
    def __init__(self, module: str, is_package: bool, known: set[str], path: str):
        self.module, self.known, self.path = module, known, path
        self.is_package = is_package
        self.package = module if is_package else module.rpartition(".")[0]
        self.depth = 0
        self.lazy = False   # directly in the package's module-level __getattr__ (PEP 562)
        self.classes = 0    # a method named __getattr__ is not the module's
        self.type_checking = 0
        self.found: list[Import] = []

    def _where(self) -> str:
        if self.depth:
            return "lazy-facade" if self.lazy and self.depth == 1 else "function"
        return "type-checking" if self.type_checking else "module"

    def _add(self, target: str, line: int) -> None:
        imp = Import(self.module, target, line, self._where(), self.path)
        if imp not in self.found:   # `from P import a, b` of two names of P: one import of P
            self.found.append(imp)

    def visit_FunctionDef(self, node):
        lazy = self.is_package and not (self.depth or self.classes) and getattr(node, "name", None) == "__getattr__"
        self.depth += 1
        self.lazy |= lazy
        self.generic_visit(node)
        self.lazy &= not lazy
        self.depth -= 1

    visit_AsyncFunctionDef = visit_FunctionDef
    visit_Lambda = visit_FunctionDef

    def visit_ClassDef(self, node):
        self.classes += 1
        self.generic_visit(node)
        self.classes -= 1

    def visit_If(self, node):
        if _is_type_checking(node.test):
            self.type_checking += 1
            for child in node.body:
                self.visit(child)
            self.type_checking -= 1
            for child in node.orelse:
                self.visit(child)
        else:
            self.generic_visit(node)

    def visit_Import(self, node):
        for alias in node.names:
            self._add(alias.name, node.lineno)

    def visit_ImportFrom(self, node):
        if node.level:
            parts = self.package.split(".")
            if node.level - 1 >= len(parts):
                raise ValueError(f"{self.path}:{node.lineno}: relative import beyond the top package")
            base = ".".join(parts[:len(parts) - (node.level - 1)])
            base = f"{base}.{node.module}" if node.module else base
        else:
            base = node.module
        for alias in node.names:
            sub = f"{base}.{alias.name}"
            self._add(sub if sub in self.known else base, node.lineno)


def collect_imports(root: Path) -> tuple[dict[str, Path], list[Import]]:
    modules = source_tree(root)
    known = set(modules)
    found: list[Import] = []
    for name, path in modules.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        c = _Collector(name, path.stem == "__init__", known, str(path.relative_to(root)))
        c.visit(tree)
        found += c.found
        if name in DISCOVERS_ITS_MODULES:   # at the line of its import_module call
            line = next((i for i, text in enumerate(path.read_text().splitlines(), 1) if "import_module(" in text), 0)
            found += [Import(name, m, line, "module", str(path.relative_to(root))) for m in sorted(modules)
                      if m.rpartition(".")[0] == name]
    return modules, found


def is_project(name: str) -> bool:
    return name == ROOT_PKG or name.startswith(ROOT_PKG + ".")


SUBPACKAGES = {"core", "blender_scenes", "solver", "detector", "generator", "eval", "configs", "models"}


def subpackage(name: str) -> str | None:
    """``dockfactory.solver.docking`` -> ``solver``; a module of the root folder
    (``dockfactory.cli``, ``dockfactory.measure``) -> ``app``, the top floor; the root package and
    ``__main__`` -> None."""
    parts = name.split(".")
    if len(parts) < 2 or parts[1] == "__main__":
        return None
    return parts[1] if parts[1] in SUBPACKAGES else "app"


def heavy_modules(imports: list[Import], modules) -> set[str]:
    """Project modules whose module-level imports reach a HEAVY dependency (transitively)."""
    edges: dict[str, set[str]] = {m: set() for m in modules}
    heavy = set()
    for imp in imports:
        if imp.where != "module":
            continue
        if is_project(imp.target):
            edges[imp.module].add(imp.target)
        elif imp.target.split(".")[0] in HEAVY:
            heavy.add(imp.module)
    changed = True
    while changed:
        changed = False
        for m, targets in edges.items():
            if m not in heavy and targets & heavy:
                heavy.add(m)
                changed = True
    return heavy


def layer_violations(imports: list[Import], modules) -> list[str]:
    heavy = heavy_modules(imports, modules)
    out = []
    for imp in imports:
        where = f"{imp.path}:{imp.line}: {imp.module} imports {imp.target}"
        if imp.where == "lazy-facade" and not imp.target.startswith(imp.module + "."):
            out.append(f"{where} in its lazy __getattr__ (PEP 562): a lazy facade imports only its own "
                       f"package's modules")
        if imp.where == "function":
            top = imp.target.split(".")[0]
            if is_project(imp.target):
                if imp.target not in heavy and (imp.module, imp.target) not in ENTRY_DEFERS:
                    out.append(f"{where} inside a function, but it is not heavy "
                               f"(import it at module level; if that makes a cycle, fix the cycle)")
            elif top not in HEAVY:
                out.append(f"{where} inside a function: only heavy optional dependencies "
                           f"({', '.join(sorted(HEAVY))}) may be imported there")
        if not is_project(imp.target):
            continue
        src, dst = subpackage(imp.module), subpackage(imp.target)
        if imp.target == f"{ROOT_PKG}.__main__":
            out.append(f"{where}: nothing may import the command-line entry point")
        elif src is None:   # the root package or __main__
            if not (imp.module == f"{ROOT_PKG}.__main__" and imp.target in MAIN_MAY_IMPORT):
                out.append(f"{where}: the root package imports none of its subpackages "
                           f"(only __main__ imports {', '.join(sorted(MAIN_MAY_IMPORT))})")
        elif dst is None or dst == src:
            continue   # the root package (imports nothing) or the own subpackage
        elif src not in ALLOWED or dst not in ALLOWED[src]:
            kind = "an unknown subpackage" if src not in ALLOWED or dst not in ALLOWED else (
                "upward" if src in ALLOWED[dst] else "sideways")
            allowed = ", ".join(sorted(ALLOWED.get(src, set()))) or "nothing of the project"
            out.append(f"{where}: {kind} import ({src} may import {allowed})")
        elif (src, dst) in FUNCTION_ONLY and imp.where != "function":
            out.append(f"{where} at module level: {src} may import {dst} only inside functions "
                       f"(it imports bpy)")
    return out


def module_graph(imports: list[Import], modules) -> dict[str, set[str]]:
    """Runtime module-level import edges between the tree's modules."""
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for imp in imports:
        if imp.where == "module" and imp.target in graph:
            graph[imp.module].add(imp.target)
    return graph


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components (iterative), each sorted."""
    index, low, on_stack, stack, comps = {}, {}, set(), [], []
    counter = 0
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, it = work[-1]
            advanced = False
            for nxt in it:
                if nxt not in index:
                    index[nxt] = low[nxt] = counter
                    counter += 1
                    stack.append(nxt)
                    on_stack.add(nxt)
                    work.append((nxt, iter(sorted(graph[nxt]))))
                    advanced = True
                    break
                if nxt in on_stack:
                    low[node] = min(low[node], index[nxt])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                comp = []
                while True:
                    m = stack.pop()
                    on_stack.discard(m)
                    comp.append(m)
                    if m == node:
                        break
                comps.append(sorted(comp))
    return comps


def _one_cycle(graph, comp: list[str]) -> list[str]:
    """A cycle through the first module of a strongly connected component (BFS back to it)."""
    members = set(comp)
    start = comp[0]
    prev = {start: None}
    queue = [start]
    while queue:
        node = queue.pop(0)
        for nxt in sorted(graph[node]):
            if nxt == start:
                path = [node]
                while prev[path[-1]] is not None:
                    path.append(prev[path[-1]])
                return path[::-1] + [start]
            if nxt in members and nxt not in prev:
                prev[nxt] = node
                queue.append(nxt)
    return comp


def cycles(imports: list[Import], modules) -> list[str]:
    graph = module_graph(imports, modules)
    out = []
    for comp in strongly_connected(graph):
        if len(comp) > 1 or comp[0] in graph[comp[0]]:
            out.append(" -> ".join(_one_cycle(graph, comp)))
    return out
