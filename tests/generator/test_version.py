"""OUTPUT_SOURCES (the modules whose code is hashed into every dataset version id) covers every
dockfactory module a render worker process imports, and names only modules that exist.

Two views of "what the worker imports":
- fast: a fresh interpreter imports the worker module and the bpy adapter it loads on ``init``
  (``dockfactory.blender_scenes.render``, needs bpy) and lists ``sys.modules``. Because project
  modules are imported at module level (tests/contracts/test_layers.py forbids function-level imports of
  cheap project modules), these two imports reach every project module the worker can run;
- render: the real worker module runs as ``__main__`` (what ``python -m
  dockfactory.generator.render_worker`` in generator/worker_pool.py does) through its JSON-lines
  protocol: init, one rendered frame of the shipped smoke config, quit; then ``sys.modules`` is
  listed. This also catches a module imported lazily while rendering or post-processing.
Package ``__init__`` modules are ignored: they hold no output-shaping code, except the BLAS kernel
that ``dockfactory/__init__.py`` pins, which tests/core/test_blas_pin.py holds to the published one.
"""
import importlib.util
import json
import subprocess
import sys

import pytest

from dockfactory.core.config import load_config
from dockfactory.core.resources import shipped_config
from dockfactory.core.scene import to_dict
from dockfactory.generator.render_job import worker_init_request
from dockfactory.generator.sampler import frame_plan, sample_frame
from dockfactory.generator.version import OUTPUT_SOURCES

LIST_MODULES = """
import sys
mods = sorted(n for n, m in list(sys.modules.items())
              if n.startswith('dockfactory.') and not (getattr(m, '__file__', '') or '').endswith('__init__.py'))
"""


def _missing(imported: list[str]) -> list[str]:
    return sorted(set(imported) - set(OUTPUT_SOURCES))


def test_output_sources_name_existing_modules():
    assert len(set(OUTPUT_SOURCES)) == len(OUTPUT_SOURCES)
    for name in OUTPUT_SOURCES:
        spec = importlib.util.find_spec(name)   # finds, does not import (no bpy needed)
        assert spec is not None and spec.origin and spec.origin.endswith(".py"), name
        assert not spec.origin.endswith("__init__.py"), name


def test_output_sources_cover_the_worker_imports(tmp_path):
    code = ("import dockfactory.generator.render_worker, dockfactory.blender_scenes.render\n"
            + LIST_MODULES + "print('\\n'.join(mods))\n")
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    imported = proc.stdout.split()
    assert "dockfactory.generator.render_worker" in imported and "dockfactory.blender_scenes.render" in imported
    assert not _missing(imported), f"imported by the render worker, not in OUTPUT_SOURCES: {_missing(imported)}"


# runs the worker module as __main__ exactly as `python -m` does, then lists what it imported
RUN_WORKER = """
import runpy, sys
out_path = sys.argv[1]
try:
    runpy.run_module('dockfactory.generator.render_worker', run_name='__main__', alter_sys=True)
except SystemExit as exc:
    assert not exc.code, exc.code
""" + LIST_MODULES + """
with open(out_path, 'w') as fh:
    fh.write('\\n'.join(mods + ['dockfactory.generator.render_worker']))
"""


@pytest.mark.render
def test_output_sources_cover_a_running_worker(tmp_path):
    cfg = load_config(shipped_config("smoke"))
    spec = frame_plan(cfg)[0]
    root = tmp_path / "dataset"
    init = worker_init_request(cfg, root, 1, keep_exr=False)
    requests = [init, {"op": "render", "frame": to_dict(sample_frame(cfg, spec))}, {"op": "quit"}]
    listing = tmp_path / "modules.txt"
    proc = subprocess.run([sys.executable, "-c", RUN_WORKER, str(listing)], cwd=tmp_path,
                          input="".join(json.dumps(r) + "\n" for r in requests),
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    replies = [json.loads(line) for line in proc.stdout.splitlines()]
    assert [r["op"] for r in replies] == ["init", "render"] and all(r["ok"] for r in replies), replies
    assert (root / "labels" / f"{spec.frame_id}.json").is_file()
    imported = listing.read_text().split()
    assert "dockfactory.blender_scenes.render" in imported and "dockfactory.generator.labels" in imported
    assert not _missing(imported), f"imported by the render worker, not in OUTPUT_SOURCES: {_missing(imported)}"
