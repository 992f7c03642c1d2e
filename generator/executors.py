"""Where frames are rendered: local worker processes, or actors on a Ray cluster.

Both drive the same render worker (``python -m dockfactory.generator.render_worker``) through
:func:`render_with_retries`, and both yield the same events to the job:
``("done", frame_id, info)``, ``("retry", frame_id, reason)``, ``("failed", frame_id, reason)``.
"""
from __future__ import annotations

import queue
import threading
from collections import deque
from collections.abc import Iterator
from pathlib import Path

from dockfactory.core.errors import DockfactoryError
from dockfactory.generator.worker_pool import WorkerDied, WorkerProcess


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


class _PipelinedFeeder:
    """The state of :func:`render_pipelined`: frames in flight, frames to retry alone, attempts."""

    def __init__(self, worker: WorkerProcess, next_frame, timeout_s: float, retries: int, recycle_after: int,
                 is_done, emit, depth: int):
        self.worker, self.next_frame, self.is_done, self.emit = worker, next_frame, is_done, emit
        self.timeout_s, self.retries, self.recycle_after, self.depth = timeout_s, retries, recycle_after, depth
        self.attempts: dict[str, int] = {}
        self.isolate: deque = deque()     # frames to retry alone
        self.inflight: deque = deque()    # (frame, alone)
        self.draining = False             # recycling: let the frames in flight finish, then restart

    def run(self) -> None:
        while True:
            self._fill()
            if not self.inflight:
                if self.draining:
                    self.draining = False
                    continue
                return
            self._receive()

    def _lost(self, frames: list[dict], reason: str) -> None:
        """Frames lost with the worker: complete ones are done, the others are retried alone."""
        suspects = [f for f in frames if not self.is_done(f["spec"]["frame_id"])]
        for f in frames:
            if f not in suspects:
                self.emit(("done", f["spec"]["frame_id"], {"timings_s": None, "recovered": True}))
        for f in suspects:
            fid = f["spec"]["frame_id"]
            if len(frames) == 1:
                self.attempts[fid] = self.attempts.get(fid, 0) + 1
                if self.attempts[fid] > self.retries:
                    self.emit(("failed", fid, reason))
                    continue
            self.emit(("retry", fid, reason))
            self.isolate.append(f)

    def _drop_inflight(self, first: list[dict], reason: str) -> None:
        """Kill the worker and count ``first`` and every frame in flight as lost."""
        self.worker.kill()
        frames = first + [f for f, _ in self.inflight]
        self.inflight.clear()
        self._lost(frames, reason)

    def _fill(self) -> None:
        """Send frames until ``depth`` are in flight (a frame under suspicion goes alone)."""
        inflight = self.inflight
        while not self.draining and len(inflight) < self.depth and not (inflight and inflight[-1][1]):
            if self.isolate:
                if inflight:
                    break        # a frame under suspicion goes alone
                frame, alone = self.isolate.popleft(), True
            else:
                frame, alone = self.next_frame(), False
            if frame is None:
                break
            try:
                if self.worker.proc is None:
                    self.worker.start(self.timeout_s)
                self.worker.send({"op": "render", "frame": frame})
                inflight.append((frame, alone))
            except Exception as exc:   # could not start or reach the worker
                self.worker.kill()
                frames = [f for f, _ in inflight] + [frame]
                inflight.clear()
                self._lost(frames if len(frames) > 1 else [frame], f"{type(exc).__name__}: {exc}")

    def _receive(self) -> None:
        """Wait for the answer about the oldest frame in flight and act on it."""
        frame, _ = self.inflight[0]
        try:
            reply = self.worker.recv(self.timeout_s)
        except (WorkerDied, ValueError) as exc:
            self.draining = False
            self._drop_inflight([], f"worker crashed or hung: {exc}")
            return
        self.inflight.popleft()
        fid = frame["spec"]["frame_id"]
        if reply.get("frame_id") not in (None, fid):
            self._drop_inflight([frame], f"worker answered for {reply.get('frame_id')}, expected {fid}")
            return
        if reply.get("ok"):
            self.worker.frames_done += 1
            self.emit(("done", fid, reply))
            if self.worker.frames_done >= self.recycle_after:   # cap memory growth of long bpy runs
                self.draining = True
        else:   # an error the worker reported for this very frame
            self._frame_error(frame, fid, reply.get("error", "unknown error"))
        if self.draining and not self.inflight:
            self.worker.close()

    def _frame_error(self, frame: dict, fid: str, error: str) -> None:
        self.attempts[fid] = self.attempts.get(fid, 0) + 1
        if self.attempts[fid] > self.retries:
            self.emit(("failed", fid, error))
        else:
            self.emit(("retry", fid, error))
            self.isolate.append(frame)


def render_pipelined(worker: WorkerProcess, next_frame, timeout_s: float, retries: int, recycle_after: int,
                     is_done, emit, depth: int = 2) -> None:
    """Feed one worker with up to ``depth`` frames in flight until ``next_frame()`` returns None.

    The worker finishes frame k (sensor model, labels, writes) while it renders frame k + 1, and
    answers in request order. A crash or hang loses every frame in flight. A frame that turns out
    to be complete on disk (``is_done(frame_id)``) is not rendered again. When several frames
    were in flight nobody knows which one killed the worker, so each is retried alone; only a
    crash with a single frame in flight counts against that frame (at most ``retries`` retries).
    ``emit(event)`` receives ("done" | "retry" | "failed", frame_id, info) events.
    """
    _PipelinedFeeder(worker, next_frame, timeout_s, retries, recycle_after, is_done, emit, depth).run()


class LocalExecutor:
    """``workers`` render processes on this machine, each fed by a thread (two frames in flight
    per worker, see :func:`render_pipelined`)."""

    def __init__(self, workers: int, log_dir: Path, env: dict | None = None, is_done=None):
        self.workers = workers
        self.log_dir = Path(log_dir)
        self.env = env
        self.is_done = is_done or (lambda fid: False)

    def run(self, frames: list[dict], init: dict, timeout_s: float, retries: int,
            recycle_after: int) -> Iterator[tuple[str, str, object]]:
        work: queue.Queue = queue.Queue()
        for f in frames:
            work.put(f)
        events: queue.Queue = queue.Queue()
        stop = threading.Event()

        def next_frame():
            if stop.is_set():
                return None
            try:
                return work.get_nowait()
            except queue.Empty:
                return None

        def slot(i: int) -> None:
            worker = WorkerProcess(init, self.log_dir / f"worker-{i}.log", self.env)
            try:
                render_pipelined(worker, next_frame, timeout_s, retries, recycle_after, self.is_done, events.put)
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


MAX_ACTOR_LOSSES_PER_WORKER = 3   # actors lost (a node died) per requested worker before the render gives up


def _render_actor_class(ray, threads: int, timeout_s: float, retries: int, recycle_after: int):
    """The Ray actor class: one render worker process per actor, ``threads`` CPUs reserved."""
    @ray.remote(num_cpus=threads)
    class RenderActor:
        def __init__(self, init, log_path, env):
            self.worker = WorkerProcess(init, Path(log_path), env)

        def render(self, frame):
            return render_with_retries(self.worker, frame, timeout_s, retries, recycle_after)

        def close(self):
            self.worker.close()
    return RenderActor


class RayExecutor:
    """Render actors on a Ray cluster (``address`` None: a local ``ray.init()``, or the cluster this
    process is already connected to).

    Each actor owns one render worker process and writes into ``root``, which must be on a
    filesystem every node sees. dockfactory must be installed on every node. An actor lost with
    its node (or killed) is noticed when its frame's result is asked for: the frame goes back to
    the queue (a "retry" event naming the loss) and the surviving actors take it; when no actor
    survives, as many new ones are started (Ray places them on the nodes left, and waits for
    resources if there are none). More than ``MAX_ACTOR_LOSSES_PER_WORKER`` losses per worker
    stop the render (DockfactoryError). A frame the lost node had half written is rendered again:
    every file is written atomically and the label last, so a half-written frame never counts as
    done, and a frame rendered twice is the same bytes.
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
        actor_class = _render_actor_class(ray, self.threads, timeout_s, retries, recycle_after)
        try:
            yield from _RayDispatch(ray, actor_class, self, init, frames).run()
        finally:
            if started_here:
                ray.shutdown()


class _RayDispatch:
    """One render's actors, their frames in flight and the frames still to render."""

    def __init__(self, ray, actor_class, executor: RayExecutor, init: dict, frames):
        self.ray, self.actor_class, self.ex, self.init = ray, actor_class, executor, init
        self.todo = deque(frames)
        self.actors: list = []
        self.pending: dict = {}   # object ref -> (actor, frame)
        self.started = self.losses = 0

    def _start_actors(self, n: int) -> None:
        for _ in range(n):
            log = str(self.ex.log_dir / f"ray-worker-{self.started}.log")
            self.actors.append(self.actor_class.remote(self.init, log, self.ex.env))
            self.started += 1

    def _feed_idle(self) -> None:
        busy = {id(a) for a, _ in self.pending.values()}
        for actor in self.actors:
            if self.todo and id(actor) not in busy:
                frame = self.todo.popleft()
                self.pending[actor.render.remote(frame)] = (actor, frame)

    def _lost(self, actor, frame, exc) -> tuple:
        """A lost actor's frame back to the queue; new actors when none survives."""
        self.losses += 1
        if self.losses > MAX_ACTOR_LOSSES_PER_WORKER * self.ex.workers:
            raise DockfactoryError(f"Ray: {self.losses} render actors lost (nodes died?); giving up "
                                   f"({type(exc).__name__})")
        self.actors = [a for a in self.actors if a is not actor]
        self.todo.appendleft(frame)
        if not self.actors:
            self._start_actors(min(self.ex.workers, len(self.todo)))
        words = " ".join(str(exc).split())[:160]
        return ("retry", frame["spec"]["frame_id"], f"its Ray actor was lost (node died?): {type(exc).__name__}: "
                                                    f"{words}")

    def run(self):
        self._start_actors(min(self.ex.workers, len(self.todo)))
        self._feed_idle()
        while self.pending:
            ready, _ = self.ray.wait(list(self.pending), timeout=0.5)
            if not ready:
                yield ("tick", "", None)
                continue
            for ref in ready:
                actor, frame = self.pending.pop(ref)
                try:
                    events = self.ray.get(ref)
                except self.ray.exceptions.RayActorError as exc:
                    yield self._lost(actor, frame, exc)
                else:
                    yield from events
            self._feed_idle()
        for actor in self.actors:
            try:
                self.ray.get(actor.close.remote())
            except self.ray.exceptions.RayActorError:
                pass   # lost with its node after its last frame
