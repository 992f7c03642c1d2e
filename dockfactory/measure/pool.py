"""measure's worker processes: each loads the detector once and then reads, detects, solves and
draws whole images, so two images use two cores without sharing an interpreter lock (threads
reached 8-9 frames/s on 2 cores where the per-image CPU time allows about 13-17).

Workers are spawned (never forked from a process that has imported torch), load the model, and
wait at a barrier with the parent: the parent's clock starts when every worker is ready, as it
starts after loading the model in a single process. At most ``2 * workers`` images are in
flight; each result is handed to ``on_done`` as it arrives (in completion order).

A worker that dies (the out-of-memory killer's SIGKILL, a crash in native code) breaks the whole
process pool: the pool is started again and the images that were in flight are measured once
more, one at a time; an image that kills its worker when alone is reported as failed
(``WorkerDied``) and the others go on.
"""
from __future__ import annotations

import multiprocessing
import os
import signal
import threading
from collections import deque
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

from dockfactory.core.errors import DockfactoryError

_STATE: dict = {}


class WorkerDied(Exception):
    """The worker measuring an image died (alone: that image killed it); the message says how."""


def _init_worker(task, weights, min_score: float, backend: str, markers, model: str, out: Path,
                 size: float | None, camera, max_pixels, barrier) -> None:
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
                  camera=camera, max_pixels=max_pixels)
    barrier.wait()


def _work(index: int, path: Path):
    s = _STATE
    return s["task"](s["detector"], s["markers"], index, path, s["model"], s["min_score"], s["out"], s["size"],
                     s["camera"], s["max_pixels"])


def _death(exitcodes) -> str:
    """How the dead worker(s) ended, e.g. 'killed by SIGKILL (what the out-of-memory killer sends)'."""
    for code in exitcodes:
        if code is not None and code < 0:
            name = signal.Signals(-code).name if -code in signal.valid_signals() else f"signal {-code}"
            return f"killed by {name}" + (" (what the out-of-memory killer sends)" if -code == signal.SIGKILL else "")
        if code:
            return f"exited with status {code}"
    return "ended unexpectedly"


READY_TIMEOUT_S = 600.0   # a worker loads the detector within this, or the pool gives up


def spawn_ready(workers: int, initializer, initargs: tuple) -> ProcessPoolExecutor:
    """A pool of ``workers`` spawned processes, returned when each has run ``initializer(*initargs,
    barrier)`` up to its ``barrier.wait()`` (the initializer calls ``barrier.abort()`` when it
    fails); DockfactoryError when one cannot load the detector."""
    ctx = multiprocessing.get_context("spawn")
    barrier = ctx.Barrier(workers + 1)
    executor = ProcessPoolExecutor(workers, mp_context=ctx, initializer=initializer, initargs=(*initargs, barrier))
    for _ in range(workers):   # the pool starts its processes on demand: one no-op each
        executor.submit(int)
    try:
        barrier.wait(timeout=READY_TIMEOUT_S)
    except threading.BrokenBarrierError:
        executor.shutdown(wait=True, cancel_futures=True)
        raise DockfactoryError("measure: a worker process could not load the detector "
                               "(run with --workers 1 to see why)") from None
    return executor


class MeasurePool:
    """``with MeasurePool(...) as pool: pool.run(jobs, on_done)``; the constructor returns when
    every worker has loaded the detector. ``task(detector, markers, index, path, model,
    min_score, out, size, camera, max_pixels)`` (a module-level function) measures one image in a
    worker; ``on_done(job, frame, error)`` gets each job ``(index, path)`` with the task's result,
    or None and a :class:`WorkerDied` / the exception the task raised."""

    def __init__(self, task, workers: int, weights, min_score: float, backend: str, markers, model: str, out: Path,
                 size: float | None, camera=None, max_pixels=None):
        self.workers = workers
        self.initargs = (task, weights, min_score, backend, markers, model, out, size, camera, max_pixels)
        self.executor = None
        self._start()

    def _start(self) -> None:
        self.executor = spawn_ready(self.workers, _init_worker, self.initargs)

    def _restart(self) -> str:
        """Shut the broken pool down, start a new one; returns how its worker(s) died."""
        processes = list((getattr(self.executor, "_processes", None) or {}).values())
        self.executor.shutdown(wait=True, cancel_futures=True)   # joins them: their exit codes are final
        codes = [p.exitcode for p in processes]
        self._start()
        return _death(sorted(codes, key=lambda c: c == -signal.SIGTERM))   # the pool SIGTERMs the survivors

    def run(self, jobs, on_done) -> None:
        """Measure every job ``(index, path)``; see the class docstring."""
        pending = deque(jobs)
        while pending:
            suspects = self._batch(pending, on_done, 2 * self.workers)
            if suspects is None:
                continue
            self._restart()
            for job in suspects:   # alone, so a death names its image
                if self._batch(deque([job]), on_done, 1) is not None:
                    on_done(job, None, WorkerDied(f"the worker process measuring it {self._restart()}"))

    def _batch(self, pending: deque, on_done, limit: int) -> list | None:
        """Run ``pending`` until it is empty (None) or the pool breaks: then the jobs that were
        in flight (``pending`` keeps the ones not yet submitted)."""
        flight: dict = {}
        broken: list | None = None
        while (pending or flight) and broken is None:
            while pending and len(flight) < limit:
                try:
                    future = self.executor.submit(_work, *pending[0])
                except BrokenProcessPool:
                    broken = []
                    break
                flight[future] = pending.popleft()
            done, _ = wait(flight, return_when=FIRST_COMPLETED) if flight else (set(), set())
            if any(isinstance(f.exception(), BrokenProcessPool) for f in done):
                broken = []
                wait(flight)
                done = set(flight)
            for f in done:
                job, exc = flight.pop(f), f.exception()
                if isinstance(exc, BrokenProcessPool):
                    broken.append(job)
                else:
                    on_done(job, None if exc else f.result(), exc)
        return broken

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.executor.shutdown(wait=True, cancel_futures=True)
