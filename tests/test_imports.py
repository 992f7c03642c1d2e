"""Every module outside blender_scenes/ imports in a process where bpy is absent."""
import subprocess
import sys

BLOCK_BPY = """
import sys, importlib.abc
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split('.')[0] in ('bpy', 'mathutils'):
            raise ImportError('bpy is not available in this process')
sys.meta_path.insert(0, Block())
"""


def test_modules_import_without_bpy(repo_root):
    modules = []
    for pkg in ("generator", "detector", "solver", "eval"):
        for path in sorted((repo_root / pkg).glob("*.py")):
            modules.append(pkg if path.stem == "__init__" else f"{pkg}.{path.stem}")
    code = BLOCK_BPY + "\nimport importlib\n" + "".join(f"importlib.import_module({m!r})\n" for m in modules)
    code += "assert 'bpy' not in sys.modules\nprint('ok', len(%r))\n" % (modules,)
    proc = subprocess.run([sys.executable, "-c", code], cwd=repo_root, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("ok")


def test_cli_help_is_instant_and_bpy_free(repo_root):
    code = BLOCK_BPY + "\nfrom generator.cli import build_parser\nbuild_parser().format_help()\n" \
        "assert 'bpy' not in sys.modules and 'torch' not in sys.modules\n"
    proc = subprocess.run([sys.executable, "-c", code], cwd=repo_root, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
