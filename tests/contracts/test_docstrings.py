"""Docstrings are contracts: every public entry point has numpydoc Parameters / Returns / Raises sections
(scikit-image's model), and a module docstring says what the module is in at most 15 lines (the reasoning, the
measurements and the history live in docs/ or the results READMEs, named by a pointer)."""
import ast
import importlib
import inspect
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PACKAGE_FOLDERS = ("core", "solver", "eval", "detector", "generator", "blender_scenes", "dockfactory")
MAX_MODULE_DOC_LINES = 15

# the public entry points outside the facades: module -> functions
ENTRY_POINTS = {
    "dockfactory": ("pin_label_arithmetic", "set_app_environment"),
    "dockfactory.eval.evaluate": ("evaluate",),
    "dockfactory.measure": ("measure",),
    "dockfactory.detector.centre": ("refine_centre",),
}
# the package facades: every function a facade's __all__ names is an entry point. A subpackage that gets a
# facade (an __init__ with __all__) is added here.
FACADES = ("dockfactory.solver", "dockfactory.eval.report", "dockfactory.generator.exports", "dockfactory.detector",
            "dockfactory.eval", "dockfactory.generator", "dockfactory.generator.datasets", "dockfactory.core.camera_chain")
# entry points that raise nothing of their own (they set environment variables or look a value up): no Raises section
RAISE_NOTHING = {"dockfactory.pin_label_arithmetic", "dockfactory.set_app_environment",
                 "dockfactory.eval.report.pdf_engine", "dockfactory.eval.verdict_exit_status"}

EXEMPT_FROM_DOC_LENGTH: set[str] = set()


def _entry_points():
    out = [(mod, name) for mod, names in ENTRY_POINTS.items() for name in names]
    for facade in FACADES:
        module = importlib.import_module(facade)
        out += [(facade, name) for name in module.__all__ if inspect.isfunction(getattr(module, name))]
    return out


def _sections(doc: str) -> set[str]:
    """The numpydoc section headers of a docstring: a title line underlined by dashes."""
    lines = [line.strip() for line in inspect.cleandoc(doc).splitlines()]
    return {title for title, rule in zip(lines, lines[1:]) if rule and set(rule) == {"-"} and len(rule) >= 3}


@pytest.mark.parametrize("module, name", _entry_points(), ids=lambda v: v)
def test_entry_point_has_a_numpydoc_contract(module, name):
    fn = getattr(importlib.import_module(module), name)
    doc = inspect.getdoc(fn) or ""
    summary = doc.splitlines()[0] if doc else ""
    assert summary and not summary.startswith(" "), f"{module}.{name}: no one-line summary"
    sections = _sections(doc)
    wanted = {"Parameters", "Returns"} if f"{module}.{name}" in RAISE_NOTHING else {"Parameters", "Returns",
                                                                                      "Raises"}
    assert wanted <= sections, f"{module}.{name}: missing numpydoc sections {sorted(wanted - sections)}"


@pytest.mark.parametrize("qualified", sorted(RAISE_NOTHING))
def test_the_entry_points_without_raises_raise_nothing_of_their_own(qualified):
    """An entry point excused from Raises has no raise statement (and says so by omitting the section)."""
    module, name = qualified.rsplit(".", 1)
    source = inspect.getsource(getattr(importlib.import_module(module), name))
    assert not any(isinstance(n, ast.Raise) for n in ast.walk(ast.parse(source))), qualified


def test_every_entry_point_documents_each_parameter():
    """Each parameter of the signature is named in Parameters (alone or in a group ``a, b : ...``)."""
    missing = []
    for module, name in _entry_points():
        fn = getattr(importlib.import_module(module), name)
        doc = inspect.getdoc(fn) or ""
        block = doc.split("Parameters\n----------", 1)[-1].split("\n\n", 1)[0]
        named = {p.strip() for line in block.splitlines() if line and not line.startswith(" ") and ":" in line
                 for p in line.split(":", 1)[0].split(",")}
        missing += [f"{module}.{name}({p})" for p in inspect.signature(fn).parameters if p not in named]
    assert not missing, missing


def _module_doc_lines(path: Path) -> int:
    tree = ast.parse(path.read_text())
    node = tree.body[0] if tree.body else None
    if not (isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value,
                                                                                                 str)):
        return 0
    return node.end_lineno - node.lineno + 1


def test_module_docstrings_are_at_most_15_lines():
    long = {str(p.relative_to(REPO)): n for folder in PACKAGE_FOLDERS for p in sorted((REPO / folder).rglob("*.py"))
            if (n := _module_doc_lines(p)) > MAX_MODULE_DOC_LINES}
    over = {p: n for p, n in long.items() if p not in EXEMPT_FROM_DOC_LENGTH}
    assert not over, f"module docstrings over {MAX_MODULE_DOC_LINES} lines (move the reasoning to docs/): {over}"


def test_the_exemptions_are_still_needed():
    """An exempt file that no longer exists or whose docstring got short leaves the list."""
    stale = [p for p in EXEMPT_FROM_DOC_LENGTH
             if not (REPO / p).exists() or _module_doc_lines(REPO / p) <= MAX_MODULE_DOC_LINES]
    assert not stale, stale


def test_the_exempt_output_sources_are_the_version_modules():
    """The files exempt for the dataset version id are modules of OUTPUT_SOURCES."""
    from dockfactory.generator.version import OUTPUT_SOURCES
    folders = {"dockfactory.core": "core", "dockfactory.core.camera_chain": "core/camera_chain",
               "dockfactory.generator": "generator", "dockfactory.blender_scenes": "blender_scenes"}
    versioned = {f"{folders[m.rsplit('.', 1)[0]]}/{m.rsplit('.', 1)[1]}.py" for m in OUTPUT_SOURCES}
    others = {"detector/centre.py", "detector/centre_camera.py"}
    assert EXEMPT_FROM_DOC_LENGTH - others <= versioned


def test_pointers_name_existing_docs():
    """A docstring pointer 'docs/x.md, "Section"' (or results/) names a page that exists and says that (a heading
    or its start). Pointers into bench/ are left to bench's own tests (bench/ is being reorganised)."""
    bad = []
    for folder in PACKAGE_FOLDERS:
        for p in sorted((REPO / folder).rglob("*.py")):
            for page, _, section in re.findall(r"(?<![\w/])((?:docs|results)/[\w./-]+\.md), ([\"'])([^\n]+?)\2", p.read_text()):
                target = REPO / page
                if not (target.exists() and section in target.read_text()):
                    bad.append(f"{p.relative_to(REPO)}: {page}, {section!r}")
    assert not bad, bad
