"""`make lint` is clean: ruff with the rules pyproject.toml selects (pyflakes: unused imports and
variables, undefined names, redefinitions; syntax errors) finds nothing in the repository."""
import shutil
import subprocess
import sys
from pathlib import Path


def test_ruff_finds_nothing(repo_root):
    ruff = shutil.which("ruff") or str(Path(sys.executable).parent / "ruff")
    out = subprocess.run([ruff, "check", "--no-cache", "--output-format", "concise", "."], cwd=repo_root,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-1000:]
