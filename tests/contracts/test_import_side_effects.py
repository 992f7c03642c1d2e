"""Importing the library changes nothing in the caller's process: no environment variable (the
BLAS kernel, thread counts, OpenMP's wait), no sys.path entry, warning filter, logging handler,
signal handler, thread count, random state or numpy setting. The ``dockfactory`` command sets
what the app needs at its entry point (dockfactory.entry), before numpy loads.

Each module is imported in a clean interpreter after numpy, torch and bpy (bpy's own import sets
MaterialX search paths; only the Blender workers' modules import it); the state is compared after
every import, so a failure names the module. OpenCV is not imported first: its loader adds to
LD_LIBRARY_PATH, which the project's modules put back (core.cv).
"""
import os
import subprocess
import sys

CHECK = r'''
import importlib, logging, os, pkgutil, signal, sys, warnings
import numpy, torch
try:
    import bpy  # noqa: F401
except ImportError:
    bpy = None

def state():
    return {"environment": dict(os.environ), "sys.path": list(sys.path),
            "warning filters": [str(f) for f in warnings.filters],
            "logging": ([str(h) for h in logging.getLogger().handlers], logging.getLogger().level),
            "torch threads": torch.get_num_threads(),
            "OpenCV threads": sys.modules["cv2"].getNumThreads() if "cv2" in sys.modules else None,
            "numpy random state": numpy.random.get_state()[1][:4].tolist(),
            "numpy errors": numpy.geterr(), "numpy print options": numpy.get_printoptions(),
            "signal handlers": [signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)],
            "torch dtype": str(torch.get_default_dtype()), "working folder": os.getcwd()}

before = state()
tops = ["dockfactory", "dockfactory.core", "dockfactory.generator", "dockfactory.solver",
        "dockfactory.detector", "dockfactory.eval"] + (["dockfactory.blender_scenes"] if bpy else [])
names = []
for top in tops:
    names.append(top)
    pkg = importlib.import_module(top)
    names += [m.name for m in pkgutil.walk_packages(pkg.__path__, top + ".")]
for name in names:
    if name.endswith("__main__"):
        continue   # runs the command line
    importlib.import_module(name)
    now = state()
    for key in before:
        if now[key] != before[key] and before[key] is not None:   # None: OpenCV not loaded yet
            print(f"{name} changed {key}")
    before = now
print(f"imported {len(names)}")
'''


def test_importing_any_module_changes_no_environment_variable_and_no_global_state():
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES", "OPENBLAS_NUM_THREADS", "OMP_WAIT_POLICY")}
    out = subprocess.run([sys.executable, "-c", CHECK], capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.strip().splitlines()
    assert lines[-1].startswith("imported ") and int(lines[-1].split()[1]) > 100, lines
    assert lines[:-1] == []


def test_the_one_module_with_a_plain_opencv_import_leaves_no_mark_imported_first():
    """detector/centre.py keeps ``import cv2`` (its source names the noise cards' refinement): its
    package loads OpenCV through core.cv before it."""
    code = ("import os\nb = dict(os.environ)\nimport dockfactory.detector.centre\n"
            "print(sorted(k for k in set(os.environ) | set(b) if os.environ.get(k) != b.get(k)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env={k: v for k, v in os.environ.items() if k != "LD_LIBRARY_PATH"})
    assert out.returncode == 0 and out.stdout.strip() == "[]", out.stdout + out.stderr


def test_the_command_entry_point_sets_the_apps_environment_before_numpy_loads():
    code = ("import os, sys\nimport dockfactory.entry as entry\nsys.argv = ['dockfactory', '--version']\n"
            "try:\n    entry.main()\nexcept SystemExit:\n    pass\n"
            "from dockfactory.core.blas import numpy_simd_on, openblas_core\n"
            "print(os.environ['OPENBLAS_NUM_THREADS'], os.environ['OMP_WAIT_POLICY'], numpy_simd_on(), "
            "openblas_core())")
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES", "OPENBLAS_NUM_THREADS", "OMP_WAIT_POLICY")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    threads, wait, simd, core = out.stdout.strip().splitlines()[-1].split(" ", 3)
    assert (threads, wait, simd) == ("1", "PASSIVE", "[]")
    assert core in ("Prescott", "None")   # None: numpy on another BLAS, nothing to pin
