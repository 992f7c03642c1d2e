"""measure's worker processes: each loads the detector once and then reads, detects, solves and
draws whole images, so two images use two cores without sharing an interpreter lock (threads
reached 8-9 frames/s on 2 cores where the per-image CPU time allows about 13-17).

Workers are spawned (never forked from a process that has imported torch), load the model, and
wait at a barrier with the parent: the parent's clock starts when every worker is ready, as it
starts after loading the model in a single process. Records come back in input order; at most
``2 * workers`` images are in flight.
"""
from __future__ import annotations

import multiprocessing
import os
import threading
from collections import deque
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from dockfactory.core.errors import DockfactoryError

_STATE: dict = {}


def _init_worker(task, weights, min_score: float, backend: str, markers, model: str, out: Path,
                 size: float | None, camera, barrier) -> None:
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    try:
        import torch

        from dockfactory.detector.infer import MarkerDetector
        torch.set_num_threads(1)
        detector = MarkerDetector(weights, conf_threshold=min_score, backend=backend)
        if detector.backend == "onnx":
            detector.network.threads = 1
    except BaseException:
        barrier.abort()   # the parent stops waiting at once
        raise
    _STATE.update(task=task, detector=detector, markers=markers, model=model, min_score=min_score, out=out, size=size,
                  camera=camera)
    barrier.wait()


def _work(index: int, path: Path):
    s = _STATE
    return s["task"](s["detector"], s["markers"], index, path, s["model"], s["min_score"], s["out"], s["size"],
                     s["camera"])


class MeasurePool:
    """``with MeasurePool(...) as pool: frames = pool.run(paths, progress)``; the constructor
    returns when every worker has loaded the detector. ``task(detector, markers, index, path,
    model, min_score, out, size, camera)`` (a module-level function) measures one image in a worker."""

    def __init__(self, task, workers: int, weights, min_score: float, backend: str, markers, model: str, out: Path,
                 size: float | None, camera=None):
        ctx = multiprocessing.get_context("spawn")
        barrier = ctx.Barrier(workers + 1)
        self.workers = workers
        self.executor = ProcessPoolExecutor(workers, mp_context=ctx, initializer=_init_worker,
                                            initargs=(task, weights, min_score, backend, markers, model, out, size, camera,
                                                      barrier))
        for _ in range(workers):   # the pool starts its processes on demand: one no-op each
            self.executor.submit(int)
        try:
            barrier.wait(timeout=600)
        except threading.BrokenBarrierError:
            self.executor.shutdown(wait=True, cancel_futures=True)
            raise DockfactoryError("measure: a worker process could not load the detector "
                                   "(run with --workers 1 to see why)") from None

    def run(self, paths, progress=None) -> list:
        frames, flight = [], deque()
        for i, p in enumerate(paths):
            flight.append(self.executor.submit(_work, i, p))
            while len(flight) > 2 * self.workers or (flight and i == len(paths) - 1):
                frames.append(flight.popleft().result())
                if progress:
                    progress(len(frames), len(paths))
        return frames

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.executor.shutdown(wait=True, cancel_futures=True)
