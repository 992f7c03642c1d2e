"""The arithmetic behind labels pinned so they are the same bytes on every x86-64 CPU: numpy's
BLAS kernel and its SIMD paths for sin, cos and kin.

The ``dockfactory`` command and every render worker it starts set ``OPENBLAS_CORETYPE`` (the SSE3 Prescott kernel)
and switch numpy's AVX-512 paths off (``NPY_DISABLE_CPU_FEATURES``) before numpy loads; ``check_label_blas``
refuses a render when numpy was loaded otherwise.

Why and how: docs/datasets.md, "Label arithmetic pinned".
"""
from __future__ import annotations

import ctypes
import os

import numpy  # noqa: F401  (loads its BLAS: openblas_core reads the loaded library)

try:
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
except ImportError:   # numpy < 2
    from numpy.core._multiarray_umath import __cpu_dispatch__, __cpu_features__

from dockfactory import LABEL_BLAS_CORE, LABEL_SIMD_ENV, LABEL_SIMD_OFF, pin_label_arithmetic
from dockfactory import LABEL_BLAS_ENV as ENV
from dockfactory.core.errors import DockfactoryError

_HOW_TO_PIN = "run the dockfactory command, or call dockfactory.pin_label_arithmetic(os.environ) before numpy loads"


def pin_label_blas(environ=os.environ) -> None:
    """Ask OpenBLAS for the label kernel and numpy for libm's trigonometry (both when they are
    loaded after this); features the caller already switched off stay off."""
    pin_label_arithmetic(environ)


def numpy_simd_on() -> list[str]:
    """The AVX-512 paths numpy runs in this process (empty when pinned or on a CPU without them): a
    feature the CPU has counts only when this numpy build dispatches to it (numpy 1.26 has no
    AVX512_SPR paths, and a CPU that has the feature still runs the others' paths, switched off)."""
    return [name for name in LABEL_SIMD_OFF if __cpu_features__.get(name) and name in __cpu_dispatch__]


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
    """DockfactoryError (one line) when numpy's OpenBLAS runs another kernel than the label one, or
    numpy runs its AVX-512 paths."""
    simd = numpy_simd_on()
    if simd:
        raise DockfactoryError(f"numpy runs its {simd[0]} paths: labels' sin and cos would differ in the last bits "
                               f"from other machines' ({_HOW_TO_PIN}, or set "
                               f"{LABEL_SIMD_ENV}=\"{' '.join(LABEL_SIMD_OFF)}\")")
    core = openblas_core()
    if core is not None and core.lower() != LABEL_BLAS_CORE.lower():
        raise DockfactoryError(f"numpy's OpenBLAS runs its {core} kernel, not {LABEL_BLAS_CORE}: labels would "
                               f"differ in the last bits from other machines' ({_HOW_TO_PIN}, or set "
                               f"{ENV}={LABEL_BLAS_CORE})")
