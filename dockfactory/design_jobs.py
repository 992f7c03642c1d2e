"""Every design of a space predicted in worker processes: each design's row (eval.design_rank.design_row)
depends only on the design, the space, the scene, the spec and the card, and its simulated frames are
seeded by the design's label (eval.design_refusals), so the rows are the same, to the digit and in
order, whatever the number of jobs.

Workers are forked from the command's process (it has imported neither torch nor bpy, and runs one
OpenBLAS thread: dockfactory.set_app_environment) so that they start without importing anything or
pickling the space; each is handed one design index at a time and returns its row. A process that
has imported torch (whose OpenMP threads a fork does not carry) predicts every design itself.
"""
from __future__ import annotations

import multiprocessing
import os
import sys
from concurrent.futures import ProcessPoolExecutor

from dockfactory.eval.design_rank import design_row

__all__ = ["design_rows", "default_jobs"]

_SHARED: dict = {}   # the inputs every row needs, set in the parent before the workers fork


def default_jobs() -> int:
    """One job per core the process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def _row(index: int) -> dict:
    s = _SHARED
    return design_row(s["designs"][index], s["space"], s["scene"], s["spec"], s["card"], s["fails_at"])


def design_rows(designs, space, scene, spec, card, fails_at: float | None, jobs: int = 1) -> list[dict]:
    """[eval.design_rank.design_row of each of ``designs``], in their order, over ``jobs`` processes
    (1, a single design, or torch imported: in this process). Errors a row raises reach the caller as
    in one process."""
    _SHARED.update(designs=list(designs), space=space, scene=scene, spec=spec, card=card, fails_at=fails_at)
    try:
        n = len(_SHARED["designs"])
        if jobs <= 1 or n <= 1 or "torch" in sys.modules or "fork" not in multiprocessing.get_all_start_methods():
            return [_row(i) for i in range(n)]
        workers = min(jobs, n)
        ctx = multiprocessing.get_context("fork")
        with ProcessPoolExecutor(workers, mp_context=ctx) as pool:
            return list(pool.map(_row, range(n)))   # one design a task: their costs differ by 100x
    finally:
        _SHARED.clear()
