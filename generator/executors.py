"""Where frames are rendered: local worker processes, or actors on a Ray cluster.

Both drive the same render worker (``python -m blender_scenes.worker``) through
:func:`render_with_retries`, and both yield the same events to the job:
``("done", frame_id, info)``, ``("retry", frame_id, reason)``, ``("failed", frame_id, reason)``.
"""
from __future__ import annotations

import queue
import threading
from collections.abc import Iterator
from pathlib import Path

from generator.worker_pool import WorkerDied, WorkerProcess


def render_with_retries(worker: WorkerProcess, frame: dict, timeout_s: float, retries: int,
                        recycle_after: int) -> list[tuple[str, str, object]]:
    """Render one frame, restarting a crashed or hung worker; events in the order they happened."""
    fid = frame["spec"]["frame_id"]
    events = []
    attempt = 0
    while True:
        try:
            if worker.proc is None:
                worker.start(timeout_s)
            reply = worker.request({"op": "render", "frame": frame}, timeout_s)
            if reply.get("ok"):
                worker.frames_done += 1
                if worker.frames_done >= recycle_after:   # cap memory growth of long bpy runs
                    worker.close()
                events.append(("done", fid, reply))
                return events
            reason = reply.get("error", "unknown error")
        except WorkerDied as exc:
            reason = f"worker crashed or hung: {exc}"
            worker.kill()
        except Exception as exc:  # worker failed to start, unreadable reply ...
            reason = f"{type(exc).__name__}: {exc}"
            worker.kill()
        attempt += 1
        if attempt > retries:
            events.append(("failed", fid, reason))
            return events
        events.append(("retry", fid, reason))


class LocalExecutor:
    """``workers`` render processes on this machine, each fed by a thread."""

    def __init__(self, workers: int, log_dir: Path, env: dict | None = None):
        self.workers = workers
        self.log_dir = Path(log_dir)
        self.env = env

    def run(self, frames: list[dict], init: dict, timeout_s: float, retries: int,
            recycle_after: int) -> Iterator[tuple[str, str, object]]:
        work: queue.Queue = queue.Queue()
        for f in frames:
            work.put(f)
        events: queue.Queue = queue.Queue()
        stop = threading.Event()

        def slot(i: int) -> None:
            worker = WorkerProcess(init, self.log_dir / f"worker-{i}.log", self.env)
            try:
                while not stop.is_set():
                    try:
                        frame = work.get_nowait()
                    except queue.Empty:
                        return
                    for ev in render_with_retries(worker, frame, timeout_s, retries, recycle_after):
                        events.put(ev)
            finally:
                worker.close()
                events.put(("slot-exit", str(i), None))

        n = min(self.workers, len(frames))
        threads = [threading.Thread(target=slot, args=(i,), daemon=True) for i in range(n)]
        for t in threads:
            t.start()
        alive = n
        try:
            while alive:
                try:
                    ev = events.get(timeout=0.5)
                except queue.Empty:
                    yield ("tick", "", None)
                    continue
                if ev[0] == "slot-exit":
                    alive -= 1
                else:
                    yield ev
        finally:
            stop.set()
            for t in threads:
                t.join(timeout=2.0)


class RayExecutor:
    """Render actors on a Ray cluster (``address`` None: a local ``ray.init()``).

    Each actor owns one render worker process and writes into ``root``, which must be on a
    filesystem every node sees. dockfactory must be installed on every node.
    """

    def __init__(self, workers: int, threads: int, address: str | None, log_dir: Path, env: dict | None = None):
        self.workers, self.threads, self.address = workers, threads, address
        self.log_dir = Path(log_dir)
        self.env = env

    def run(self, frames, init, timeout_s, retries, recycle_after):
        import ray  # optional dependency, only for --executor ray

        started_here = not ray.is_initialized()
        if started_here:
            kwargs = {"address": self.address} if self.address else {"num_cpus": max(self.threads * self.workers, 1)}
            ray.init(include_dashboard=False, log_to_driver=False, **kwargs)

        @ray.remote(num_cpus=self.threads)
        class RenderActor:
            def __init__(self, init, log_path, env):
                self.worker = WorkerProcess(init, Path(log_path), env)

            def render(self, frame):
                return render_with_retries(self.worker, frame, timeout_s, retries, recycle_after)

            def close(self):
                self.worker.close()

        try:
            n = min(self.workers, len(frames))
            actors = [RenderActor.remote(init, str(self.log_dir / f"ray-worker-{i}.log"), self.env) for i in range(n)]
            pending = {}
            todo = list(frames)
            for actor in actors:
                if todo:
                    pending[actor.render.remote(todo.pop(0))] = actor
            while pending:
                ready, _ = ray.wait(list(pending), timeout=0.5)
                if not ready:
                    yield ("tick", "", None)
                    continue
                for ref in ready:
                    actor = pending.pop(ref)
                    yield from ray.get(ref)
                    if todo:
                        pending[actor.render.remote(todo.pop(0))] = actor
            ray.get([a.close.remote() for a in actors])
        finally:
            if started_here:
                ray.shutdown()
