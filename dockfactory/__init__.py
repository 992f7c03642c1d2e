"""dockfactory: synthetic-data factory and acceptance judge for uncalibrated monocular docking.

One import root; the subpackages live in the repository's folders (package-dir mapping):
``dockfactory.core`` (core/), ``dockfactory.generator`` (generator/), ``dockfactory.blender_scenes``
(blender_scenes/), ``dockfactory.solver`` (solver/), ``dockfactory.detector`` (detector/),
``dockfactory.eval`` (eval/, the judge); the app (command line, run, measure, ablate) is the
modules of this folder; shipped configs and weights are ``dockfactory.configs`` and
``dockfactory.models``. Layers: core <- generator, blender_scenes, solver, detector <- eval <- app.

Importing it, or any subpackage, changes no environment variable: the ``dockfactory`` command
(:mod:`dockfactory.entry`) sets what the app needs (:func:`set_app_environment`) before numpy
loads; a program that renders datasets through the library calls :func:`pin_label_arithmetic`
on ``os.environ`` before it imports numpy, or a render is refused in one line (core.blas).
"""
from importlib import metadata

# numpy's OpenBLAS kernel, set before numpy loads it: label geometry is float64 matrix products,
# and other kernels round the last bits otherwise, so a dataset is the same bytes on every x86-64
# CPU only with one kernel (dockfactory.core.blas; tests/core/test_blas_pin.py holds it to the kernel
# that made the published datasets: changing it changes labels, not the version id)
LABEL_BLAS_ENV, LABEL_BLAS_CORE = "OPENBLAS_CORETYPE", "Prescott"
# numpy's float64 sin, cos and kin take Intel's SVML paths on AVX-512 CPUs and libm's elsewhere,
# which round the last bits differently: those paths are switched off before numpy loads, so
# every x86-64 CPU computes a label's trigonometry as libm does (dockfactory.core.blas)
LABEL_SIMD_ENV = "NPY_DISABLE_CPU_FEATURES"
LABEL_SIMD_OFF = ("AVX512F", "AVX512CD", "AVX512_KNL", "AVX512_KNM", "AVX512_SKX", "AVX512_CLX",
                  "AVX512_CNL", "AVX512_ICL", "AVX512_SPR")


def pin_label_arithmetic(environ) -> None:
    """Set both label-arithmetic pins (OpenBLAS kernel, numpy's SIMD paths off) in a process's environment.

    Parameters
    ----------
    environ : mutable mapping
        A process's environment (``os.environ`` or a worker's), before numpy loads; numpy features the caller
        already switched off stay off.

    Returns
    -------
    None
        ``environ`` is changed in place.
    """
    environ[LABEL_BLAS_ENV] = LABEL_BLAS_CORE
    off = environ.get(LABEL_SIMD_ENV, "").split()
    environ[LABEL_SIMD_ENV] = " ".join(dict.fromkeys(off + list(LABEL_SIMD_OFF)))


def set_app_environment(environ) -> None:
    """Set what the command line needs in ``environ`` before numpy and torch load.

    The label pins (:func:`pin_label_arithmetic`); one OpenBLAS thread unless the user asks for more (the solver's
    linear systems have a few dozen unknowns, where a second BLAS thread only adds its wake-up on busy cores); a passive
    OpenMP wait unless set (the machine is shared with renders and worker processes).

    Parameters
    ----------
    environ : mutable mapping
        The process's environment (``os.environ``).

    Returns
    -------
    None
        ``environ`` is changed in place; values the user set are kept (the pins excepted).
    """
    pin_label_arithmetic(environ)
    environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

try:
    __version__ = metadata.version("dockfactory")
except metadata.PackageNotFoundError:  # running from an uninstalled source tree
    __version__ = "0+unknown"
