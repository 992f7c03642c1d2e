"""The BLAS kernel behind numpy's matrix products, pinned so labels are the same bytes on every CPU.

A label is float64 geometry (camera, poses, projected markers) and numpy hands its matrix products
to OpenBLAS, which picks a kernel for the CPU it runs on. The Haswell, Zen and SkylakeX kernels
round differently from the SSE3 one in the last bits, so the same config gave other label bytes on
another machine (docs/datasets.md, "Publishing a dataset"). ``import dockfactory`` sets
``OPENBLAS_CORETYPE`` to the SSE3 (Prescott) kernel, which every x86-64 CPU runs and which made the
published paper dataset; it takes effect only if numpy has not been imported before dockfactory,
so a render checks the kernel actually loaded (``check_label_blas``).
"""
from __future__ import annotations

import ctypes
import os

import numpy  # noqa: F401  (loads its BLAS: openblas_core reads the loaded library)

from dockfactory import LABEL_BLAS_CORE
from dockfactory import LABEL_BLAS_ENV as ENV
from dockfactory.core.errors import DockfactoryError


def pin_label_blas(environ=os.environ) -> None:
    """Ask OpenBLAS (when it is loaded after this) for the label kernel."""
    environ[ENV] = LABEL_BLAS_CORE


def openblas_core() -> str | None:
    """The kernel numpy's OpenBLAS runs in this process (e.g. "Haswell"), or None when numpy uses
    another BLAS or the library does not say."""
    try:
        with open("/proc/self/maps") as fh:
            paths = sorted({line.split()[-1] for line in fh if "openblas" in line.lower() and "/" in line})
    except OSError:
        return None
    for path in paths:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for name in ("openblas_get_corename64_", "openblas_get_corename", "scipy_openblas_get_corename64_"):
            fn = getattr(lib, name, None)
            if fn is not None:
                fn.restype = ctypes.c_char_p
                return fn().decode()
    return None


def check_label_blas() -> None:
    """DockfactoryError (one line) when numpy's OpenBLAS runs another kernel than the label one."""
    core = openblas_core()
    if core is not None and core.lower() != LABEL_BLAS_CORE.lower():
        raise DockfactoryError(f"numpy's OpenBLAS runs its {core} kernel, not {LABEL_BLAS_CORE}: labels would "
                               f"differ in the last bits from other machines' (import dockfactory before "
                               f"numpy, or set {ENV}={LABEL_BLAS_CORE})")
