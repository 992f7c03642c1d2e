"""Render worker process: ``python -m dockfactory.generator.render_worker``.

Builds the Blender scene once (through the bpy adapter, ``dockfactory.blender_scenes.render``),
then renders frame after frame by updating it and post-processes each EXR (sensor model, labels). Requests
arrive as JSON lines on stdin (``init``, ``render``, ``state``, ``quit``); replies go as JSON lines to the
original stdout, while everything Blender prints is sent to stderr (the job's log). Fault injection for
tests: ``DOCKFACTORY_FAULT``. The worker dies with the process that started it
(``DOCKFACTORY_WORKER_PARENT``).

Why and how: docs/rendering.md, "The render worker's requests".
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import tempfile
import threading
import time
import traceback

from dockfactory.core.scene import FrameScene, StaticScene, from_dict
from dockfactory.generator.frame_output import computed_coverage, finish_frame
from dockfactory.generator.marker_regions import marker_regions


def _protocol_stream():
    """Keep the real stdout for replies; route fd 1 (Blender's chatter) to stderr."""
    out = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    return out


def _rss_mb() -> float:
    """Resident memory of this process (MB), from /proc (0 where there is no /proc)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


def _inject_fault(frame_id: str) -> None:
    spec = os.environ.get("DOCKFACTORY_FAULT", "")
    if not spec or ":" not in spec:
        return
    kind, target = spec.split(":", 1)
    if target != frame_id:
        return
    if kind == "crash-always":
        os.kill(os.getpid(), 9)
    mark = os.path.join(os.environ.get("DOCKFACTORY_FAULT_DIR", tempfile.gettempdir()), f"fault-{kind}-{frame_id}")
    if os.path.exists(mark):
        return
    open(mark, "w").close()
    if kind == "crash":
        os.kill(os.getpid(), 9)
    if kind == "hang":
        time.sleep(3600)


def _scratch_dir() -> str:
    """A private scratch folder on tmpfs when there is one; stale ones of dead workers are removed."""
    base = "/dev/shm" if os.path.isdir("/dev/shm") else tempfile.gettempdir()
    for name in os.listdir(base):
        parts = name.split("-")
        if name.startswith("dockfactory-") and len(parts) >= 3 and parts[1].isdigit():
            try:
                os.kill(int(parts[1]), 0)
            except ProcessLookupError:
                shutil.rmtree(os.path.join(base, name), ignore_errors=True)
            except PermissionError:
                pass
    return tempfile.mkdtemp(prefix=f"dockfactory-{os.getpid()}-", dir=base)


class _Replies:
    """Writes replies in request order; a frame's post-processing runs in a thread while the next
    frame renders (Cycles leaves some CPU idle in its serial phases), at most one at a time."""

    def __init__(self, proto):
        self.proto = proto
        self.lock = threading.Lock()
        self.post: threading.Thread | None = None

    def send(self, reply: dict) -> None:
        with self.lock:
            self.proto.write(json.dumps(reply) + "\n")

    def wait(self) -> None:
        if self.post is not None:
            self.post.join()
            self.post = None

    def start_post(self, target) -> None:
        self.wait()
        self.post = threading.Thread(target=target, daemon=True)
        self.post.start()


def _error(op, exc) -> dict:
    return {"ok": False, "op": op, "error": f"{type(exc).__name__}: {exc}", "traceback": traceback.format_exc()}


class _Session:
    """The worker's state: the renderer after init, the init request, two scratch EXRs (frame
    k + 1 renders into one while frame k is read from the other)."""

    def __init__(self, replies: _Replies, scratch: str, parent: int):
        self.replies, self.parent = replies, parent
        self.exr_paths = [os.path.join(scratch, "render0.exr"), os.path.join(scratch, "render1.exr")]
        self.renderer = self.static = self.init = None
        self.n_rendered = 0

    def handle_init(self, req: dict) -> None:
        from dockfactory.blender_scenes.render import BlenderRenderer, blender_version
        try:
            self.init = req
            self.static = from_dict(StaticScene, req["static"])
            t0 = time.perf_counter()
            self.renderer = BlenderRenderer(self.static, req["width"], req["height"], req["threads"],
                                            self.exr_paths[0], req.get("device", "cpu"))
            self.replies.send({"ok": True, "op": "init", "build_s": time.perf_counter() - t0,
                               "blender_version": blender_version(), "pid": os.getpid(),
                               "device": self.renderer.device})
        except Exception as exc:
            self.replies.send(_error("init", exc))

    def handle_render(self, req: dict) -> None:
        op = req.get("op")
        try:
            if op != "render":
                raise ValueError(f"unknown op {op!r}")
            if self.renderer is None:
                raise RuntimeError("render before init")
            frame = from_dict(FrameScene, req["frame"])
            _inject_fault(frame.spec.frame_id)
            exr_path = self.exr_paths[self.n_rendered % 2]
            self.n_rendered += 1
            regions = marker_regions(frame, self.static)
            t0, c0 = time.perf_counter(), time.process_time()
            timings, crop_paths = self.renderer.render(frame, exr_path, regions,
                                                       lambda paths: computed_coverage(frame, self.static, regions, paths))
            render_cpu = time.process_time() - c0
        except Exception as exc:  # reported to the job, which decides to retry or fail
            self.replies.wait()
            fid = (req.get("frame") or {}).get("spec", {}).get("frame_id")
            self.replies.send({**_error(op, exc), "frame_id": fid})
            return
        crops = tuple((r, colour, cover) for r, (colour, cover) in zip(regions, crop_paths))
        self.replies.start_post(lambda: self.post_process(frame, exr_path, t0, timings, render_cpu, crops))

    def handle_state(self, req: dict) -> None:
        """Apply a frame without rendering and report the resulting Blender state (tests check
        that it does not depend on the frames applied before)."""
        self.replies.wait()   # replies stay in request order
        try:
            if self.renderer is None:
                raise RuntimeError("state before init")
            frame = from_dict(FrameScene, req["frame"])
            state = self.renderer.state(frame)
            text = json.dumps(state, sort_keys=True)
            reply = {"ok": True, "op": "state", "frame_id": frame.spec.frame_id,
                     "digest": hashlib.sha256(text.encode()).hexdigest()}
            if req.get("full"):
                reply["state"] = state
            self.replies.send(reply)
        except Exception as exc:
            self.replies.send(_error("state", exc))

    def post_process(self, frame, exr_path: str, t0: float, timings: dict, render_cpu: float, crops=()) -> None:
        """Sensor model, labels and writes of a rendered frame (runs beside the next render);
        ``crops``: (marker region, its cropped EXR, its coverage EXR or None) of label-aware sampling."""
        init = self.init
        try:
            p0 = time.thread_time()
            _exit_if_orphaned(self.parent)      # the last moment before any write
            done = finish_frame(frame, self.static, exr_path, init["root"], init["keep_exr"],
                                init["visible_threshold"], timings, init["min_chroma"], init.get("keep_raw", False),
                                crops)
            done["timings_s"]["total"] = time.perf_counter() - t0
            # CPU seconds: the render's (whole process, all threads; it includes the previous
            # frame's post-processing that ran alongside) and this thread's
            done["timings_s"]["cycles_cpu"] = render_cpu
            done["timings_s"]["post_cpu"] = time.thread_time() - p0
            done["rss_mb"] = _rss_mb()
            done["finished_at"] = time.time()
            self.replies.send({"ok": True, "op": "render", "frame_id": frame.spec.frame_id, **done})
        except Exception as exc:
            self.replies.send({**_error("render", exc), "frame_id": frame.spec.frame_id})


PARENT_ENV = "DOCKFACTORY_WORKER_PARENT"   # the pid of the process that started the worker
PARENT_POLL_S = 0.5


def _parent_pid() -> int:
    """The pid of the worker's starter (``PARENT_ENV``, else the parent at start-up)."""
    text = os.environ.get(PARENT_ENV, "")
    return int(text) if text.isdigit() else os.getppid()


def _exit_if_orphaned(parent: int) -> None:
    """End the worker at once when its starter is gone: the starter held the dataset folder's
    lock, which went with it, so this worker may write nothing more (a frame written now could
    collide with a new run's)."""
    if os.getppid() != parent:
        os._exit(3)


def _watch_parent(parent: int) -> None:
    """A daemon thread that ends the worker within PARENT_POLL_S of its starter's death (a
    killed ``dockfactory render`` leaves no worker rendering on)."""
    def watch() -> None:
        while True:
            _exit_if_orphaned(parent)
            time.sleep(PARENT_POLL_S)
    threading.Thread(target=watch, daemon=True, name="parent-watch").start()


def main() -> int:
    parent = _parent_pid()
    _exit_if_orphaned(parent)
    _watch_parent(parent)
    replies = _Replies(_protocol_stream())
    scratch = _scratch_dir()
    session = _Session(replies, scratch, parent)
    try:
        for line in sys.stdin:
            req = json.loads(line)
            if req.get("op") == "quit":
                break
            if req.get("op") == "init":
                session.handle_init(req)
            elif req.get("op") == "state":
                session.handle_state(req)
            else:
                session.handle_render(req)
        replies.wait()
    finally:
        replies.wait()
        shutil.rmtree(scratch, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
