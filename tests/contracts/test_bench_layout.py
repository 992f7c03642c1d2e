"""bench/ by topic: the scripts sit in topic folders (bench/<topic>/, one per table of
bench/README.md) and run as ``python -m bench.<topic>.<script>`` from the repository root; they and
the tests import each other as ``bench.<topic>.<script>``, so nothing in bench/ or tests/ edits
``sys.path`` to reach them; every bench command the docs, the Makefile and the speed records give
names a script that exists."""
from __future__ import annotations

import json
import re
from pathlib import Path

# files at bench/'s top level besides the topic folders: the package, the helper the topics share
TOP_LEVEL = {"__init__.py", "README.md", "marker_match.py"}
KEPT_FOLDERS = {"results", "configs"}   # records and the benches' configs, not scripts

# sys.path edits that put a third-party checkout on the path (never bench/ or tests/ code)
THIRD_PARTY_PATHS = {"bench/solver/pose_train.py",          # the unpacked ultralytics wheel and the torchvision stand-in
                     "tests/generator/ultralytics_check.py",  # the same, for the export check
                     "tests/generator/bop_toolkit_check.py"}  # a bop_toolkit checkout
PATH_EDIT = re.compile(r"sys\.path\s*(?:\.(?:insert|append|extend)\s*\(|\[[^\]]*\]\s*=|\+?=(?!=))")

COMMAND = re.compile(r"(?:python3?(?:\.11)?|\$PY)\s+(?:-m\s+(bench(?:\.\w+)+)(?![.\w<])|(bench/[\w/]+\.py))|\bsh\s+(bench/[\w/]+\.sh)")


def _python_files(root: Path, folder: str):
    for path in sorted((root / folder).rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        if not rel.startswith(("bench/results/", "tests/layer_fixture/")):
            yield rel, path


def test_bench_holds_topic_folders(repo_root):
    bench = repo_root / "bench"
    loose = sorted(p.name for p in bench.iterdir() if p.is_file() and p.name not in TOP_LEVEL)
    assert not loose, f"scripts at bench/'s top level (put them in a topic folder): {loose}"
    for folder in (p for p in bench.iterdir() if p.is_dir() and p.name not in KEPT_FOLDERS | {"__pycache__"}):
        assert (folder / "__init__.py").is_file(), f"{folder.name}: not a package (python -m bench.{folder.name}...)"
        assert f"`bench/{folder.name}/`" in (bench / "README.md").read_text(), folder.name


def test_no_sys_path_edits_in_bench_or_tests(repo_root):
    edits = [f"{rel}:{n}" for folder in ("bench", "tests") for rel, path in _python_files(repo_root, folder)
             if rel not in THIRD_PARTY_PATHS
             for n, line in enumerate(path.read_text().splitlines(), 1)
             if PATH_EDIT.search(line.split("#")[0])]
    assert not edits, f"sys.path edits (import bench helpers as bench.<topic>.<script>): {edits}"


def test_bench_imports_name_existing_modules(repo_root):
    missing = []
    for folder in ("bench", "tests"):
        for rel, path in _python_files(repo_root, folder):
            for name in re.findall(r"^\s*(?:from|import)\s+(bench(?:\.\w+)*)", path.read_text(), re.M):
                target = repo_root / name.replace(".", "/")
                if not (target.with_suffix(".py").is_file() or (target / "__init__.py").is_file()):
                    missing.append(f"{rel}: {name}")
    assert not missing, missing


def _documents(root: Path):
    pages = [root / "README.md", root / "Makefile", root / "results" / "README.md", root / "models" / "README.md",
             root / "tests" / "README.md", root / "bench" / "README.md", *sorted((root / "docs").glob("*.md")),
             *sorted((root / "bench" / "results").rglob("README.md")), *sorted((root / "bench").rglob("*.sh"))]
    for page in pages:
        if page.is_file():
            yield page.relative_to(root).as_posix(), page.read_text()
    for name, rec in json.loads((root / "bench/results/speeds/speeds.json").read_text())["records"].items():
        yield f"speeds.json {name}", rec["command"]


def test_every_documented_bench_command_names_a_script(repo_root):
    wrong = []
    for where, text in _documents(repo_root):
        for module, script, shell in COMMAND.findall(text):
            path = module.replace(".", "/") + ".py" if module else script or shell
            if not (repo_root / path).is_file():
                wrong.append(f"{where}: {module or script or shell}")
    assert not wrong, f"bench commands naming no script: {wrong}"
