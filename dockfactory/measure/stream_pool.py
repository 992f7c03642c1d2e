"""measure --video/--camera --workers N: frames measured by N worker processes, lines in order.

A stream's frames are independent once no state is carried from one to the next (no window
tracking, no online self-calibration: both are refused with more than one worker), so N
processes can each detect and solve a frame while the parent reads the next ones: the network and
the solve of two frames run on two cores without sharing an interpreter lock. The parent keeps
everything that is sequential: reading, the display filter, the acceptance hook, the lines (in
frame order).

Why and how: docs/measure.md, "Stream workers".
"""
from __future__ import annotations

import os
from collections import deque
from concurrent.futures.process import BrokenProcessPool

from dockfactory.measure.pool import spawn_ready

_STATE: dict = {}


def _init_worker(make_measurer, weights, options, markers, size, barrier) -> None:
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    try:
        import torch
        torch.set_num_threads(1)
        measurer = make_measurer(weights, options, markers, size)
    except BaseException:
        barrier.abort()   # the parent stops waiting at once
        raise
    _STATE["measurer"] = measurer
    barrier.wait()


def _solve(index: int, rgb):
    return _STATE["measurer"].solve(index, rgb)


def _backend() -> str:
    return _STATE["measurer"].detector.backend


class StreamPool:
    """``with StreamPool(make_measurer, workers, weights, options, markers) as pool: for item, record
    in pool.measure(items): ...``: ``make_measurer(weights, options, markers, size)`` (a module-level
    function) builds each worker's measurer (a loaded detector, one thread); ``items`` are a FrameReader's tuples ``(index, t_start, read_ms,
    timestamp_ms, rgb)``; each comes back, in order, with its measure record (as
    ``StreamMeasurer.solve`` gives it); ``size`` (width, height) the frames', to warm each worker's
    network up on. The constructor returns when every worker has loaded the detector
    (DockfactoryError when one cannot)."""

    def __init__(self, make_measurer, workers: int, weights, options, markers, size: tuple[int, int] | None = None):
        self.workers, self.initargs = workers, (make_measurer, weights, options, tuple(markers), size)
        self.executor = None
        self._start()
        self.backend = self.executor.submit(_backend).result()   # the network's runtime, as "auto" chose

    def _start(self) -> None:
        self.executor = spawn_ready(self.workers, _init_worker, self.initargs)

    def _record(self, future, executor, index: int) -> dict:
        """The record of a submitted frame; a worker's death is the frame's failure record (the
        pool is started again once, by the first frame that finds it broken)."""
        try:
            if future is None:
                raise BrokenProcessPool("not submitted")
            return future.result()
        except BrokenProcessPool:
            if executor is self.executor:
                self.executor.shutdown(wait=True, cancel_futures=True)
                self._start()
            return {"ok": False, "category": "measure error",
                    "reason": f"frame {index}: the worker process measuring it died"}

    def measure(self, items):
        """Yield ``(item, record)`` in the order of ``items``, at most ``workers`` in flight."""
        flight: deque = deque()
        for item in items:
            executor = self.executor
            try:
                future = executor.submit(_solve, item[0], item[4])
            except BrokenProcessPool:
                future = None
            flight.append((item, future, executor))
            while len(flight) >= self.workers:
                done, fut, ex = flight.popleft()
                yield done, self._record(fut, ex, done[0])
        while flight:
            done, fut, ex = flight.popleft()
            yield done, self._record(fut, ex, done[0])

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.executor.shutdown(wait=True, cancel_futures=True)
