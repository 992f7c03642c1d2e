"""Render worker process: ``python -m blender_scenes.worker``.

Builds the Blender scene once, then renders frame after frame by updating it. Requests arrive as
JSON lines on stdin; replies go as JSON lines to the original stdout, while everything Blender
prints is sent to stderr (the job's log). Requests:
  {"op": "init", "static": ..., "width": W, "height": H, "threads": T, "root": DIR,
   "keep_exr": bool, "visible_threshold": x}
  {"op": "render", "frame": <FrameScene dict>}
  {"op": "quit"}
Replies: {"ok": true, ...} or {"ok": false, "error": "..."}.
Fault injection for tests: DOCKFACTORY_FAULT="crash:<frame_id>" or "hang:<frame_id>" acts once per
frame (a marker file in DOCKFACTORY_FAULT_DIR remembers it); "crash-always:<frame_id>" every time.
"""
from __future__ import annotations

import json
import os
import shutil
import sys
import tempfile
import threading
import time
import traceback


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


def main() -> int:
    replies = _Replies(_protocol_stream())
    scratch = _scratch_dir()
    # two scratch EXRs: frame k+1 renders into one while frame k is read from the other
    exr_paths = [os.path.join(scratch, "render0.exr"), os.path.join(scratch, "render1.exr")]
    handles = static = init = None
    n_rendered = 0
    try:
        import bpy  # noqa: F401  (only ever imported in this process)

        from blender_scenes.frame_update import apply_frame
        from blender_scenes.scene_builder import build_scene
        from generator.frame_output import finish_frame
        from generator.scene import FrameScene, StaticScene, from_dict

        for line in sys.stdin:
            req = json.loads(line)
            op = req.get("op")
            if op == "quit":
                break
            if op == "init":
                try:
                    init = req
                    static = from_dict(StaticScene, req["static"])
                    t0 = time.perf_counter()
                    handles = build_scene(static, req["width"], req["height"], req["threads"], exr_paths[0])
                    replies.send({"ok": True, "op": "init", "build_s": time.perf_counter() - t0,
                                  "blender_version": bpy.app.version_string, "pid": os.getpid()})
                except Exception as exc:
                    replies.send(_error(op, exc))
                continue
            try:
                if op != "render":
                    raise ValueError(f"unknown op {op!r}")
                if handles is None:
                    raise RuntimeError("render before init")
                frame = from_dict(FrameScene, req["frame"])
                _inject_fault(frame.spec.frame_id)
                exr_path = exr_paths[n_rendered % 2]
                n_rendered += 1
                t0, c0 = time.perf_counter(), time.process_time()
                handles.scene.render.filepath = exr_path
                apply_frame(handles, frame)
                t1 = time.perf_counter()
                bpy.ops.render.render(write_still=True)
                t2, c2 = time.perf_counter(), time.process_time()
            except Exception as exc:  # reported to the job, which decides to retry or fail
                replies.wait()
                fid = (req.get("frame") or {}).get("spec", {}).get("frame_id")
                replies.send({**_error(op, exc), "frame_id": fid})
                continue

            def post(frame=frame, exr_path=exr_path, t0=t0, t1=t1, t2=t2, render_cpu=c2 - c0):
                try:
                    p0 = time.thread_time()
                    done = finish_frame(frame, static, exr_path, init["root"], init["keep_exr"],
                                        init["visible_threshold"],
                                        {"scene_update": t1 - t0, "cycles": t2 - t1},
                                        init.get("min_chroma", 0.03))
                    done["timings_s"]["total"] = time.perf_counter() - t0
                    # CPU seconds: the render's (whole process, all threads; it includes the
                    # previous frame's post-processing that ran alongside) and this thread's
                    done["timings_s"]["cycles_cpu"] = render_cpu
                    done["timings_s"]["post_cpu"] = time.thread_time() - p0
                    done["rss_mb"] = _rss_mb()
                    done["finished_at"] = time.time()
                    replies.send({"ok": True, "op": "render", "frame_id": frame.spec.frame_id, **done})
                except Exception as exc:
                    replies.send({**_error("render", exc), "frame_id": frame.spec.frame_id})

            replies.start_post(post)
        replies.wait()
    finally:
        replies.wait()
        shutil.rmtree(scratch, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
