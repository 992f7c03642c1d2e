"""Render jobs: plan -> skip finished frames -> render the rest on worker processes -> manifest.

Resumable (finished frames are never touched), sharded (``shard=(k, n)`` renders frames whose
index % n == k - 1), fault tolerant (a crashed or hung worker is restarted and its frame retried
up to ``retries`` times; frames that still fail are listed and make the job fail) and memory
bounded (workers are recycled after ``recycle_after`` frames).
"""
from __future__ import annotations

import json
import os
import queue
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from generator.config import Config
from generator.dataset import frame_done, prepare, write_manifest
from generator.progress import Progress
from generator.sampler import frame_plan, sample_frame, static_scene
from generator.scene import FrameSpec, to_dict
from generator.worker_pool import WorkerDied, WorkerProcess


@dataclass(frozen=True)
class JobOptions:
    workers: int = 1
    shard: tuple[int, int] = (1, 1)
    frame_ids: tuple[str, ...] | None = None   # render only these (still resumable)
    retries: int = 2
    recycle_after: int = 100
    threads: int = 0                           # per worker; 0 = cores // workers
    progress: bool = True
    env: dict | None = None                    # worker environment (tests inject faults)


@dataclass
class JobSummary:
    root: str
    version_id: str
    planned: int = 0
    skipped: int = 0
    rendered: int = 0
    retried: int = 0
    failed: dict = field(default_factory=dict)
    seconds: float = 0.0
    complete: bool = False
    timings: list = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.failed

    def text(self) -> str:
        lines = [f"dataset {self.root} (version {self.version_id})",
                 f"  frames in this run: {self.planned}, already done: {self.skipped}, "
                 f"rendered: {self.rendered}, retried: {self.retried}, failed: {len(self.failed)}",
                 f"  wall time: {self.seconds:.1f} s"]
        if self.timings:
            cyc = sorted(t["cycles"] for t in self.timings)
            tot = sorted(t["total"] for t in self.timings)
            lines.append(f"  per frame: median {tot[len(tot) // 2]:.2f} s "
                         f"(Cycles {cyc[len(cyc) // 2]:.2f} s)")
        for fid, why in sorted(self.failed.items()):
            lines.append(f"  FAILED {fid}: {why}")
        lines.append("  dataset complete: manifest.json written" if self.complete else
                     "  dataset incomplete: run the same command again to finish it")
        return "\n".join(lines)


def cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def select_frames(cfg: Config, opts: JobOptions) -> list[FrameSpec]:
    plan = frame_plan(cfg)
    k, n = opts.shard
    if not (n >= 1 and 1 <= k <= n):
        raise ValueError(f"--shard {k}/{n}: expected K/N with 1 <= K <= N")
    chosen = [s for s in plan if s.index % n == k - 1]
    if opts.frame_ids is not None:
        known = {s.frame_id for s in plan}
        unknown = sorted(set(opts.frame_ids) - known)
        if unknown:
            raise ValueError(f"frame {unknown[0]!r} is not in this dataset's plan")
        wanted = set(opts.frame_ids)
        chosen = [s for s in chosen if s.frame_id in wanted]
    return chosen


def run_render(cfg: Config, root, config_text: str, opts: JobOptions = JobOptions()) -> JobSummary:
    """Render (the missing frames of) a dataset into ``root``."""
    t_start = time.monotonic()
    if opts.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {opts.workers}")
    frames = select_frames(cfg, opts)
    # sample every scene up front: a bad frame fails before anything is written
    scenes = {s.frame_id: sample_frame(cfg, s) for s in frames}
    ident = prepare(root, cfg, config_text)
    root = Path(root)
    summary = JobSummary(root=str(root), version_id=ident["version_id"], planned=len(frames))
    todo = [s for s in frames if not frame_done(root, s.frame_id, cfg.render.keep_exr)]
    summary.skipped = len(frames) - len(todo)

    if todo:
        _render_local(cfg, root, todo, scenes, opts, summary)
    summary.complete = all(frame_done(root, s.frame_id, cfg.render.keep_exr) for s in frame_plan(cfg))
    if summary.complete:
        write_manifest(root, cfg)
    summary.seconds = time.monotonic() - t_start
    return summary


def _render_local(cfg, root: Path, todo, scenes, opts: JobOptions, summary: JobSummary) -> None:
    n_workers = min(opts.workers, len(todo))
    threads = opts.threads or max(1, cores() // n_workers)
    init = {"op": "init", "static": to_dict(static_scene(cfg)), "width": cfg.image.width,
            "height": cfg.image.height, "threads": threads, "root": str(root.resolve()),
            "keep_exr": cfg.render.keep_exr, "visible_threshold": cfg.labels.visible_threshold}
    work: queue.Queue = queue.Queue()
    for s in todo:
        work.put(s)
    events: queue.Queue = queue.Queue()
    stop = threading.Event()
    timeout = cfg.render.frame_timeout_s

    def run_slot(slot: int) -> None:
        worker = WorkerProcess(init, root / "logs" / f"worker-{slot}.log", opts.env)
        try:
            while not stop.is_set():
                try:
                    spec = work.get_nowait()
                except queue.Empty:
                    return
                attempt = 0
                while True:
                    try:
                        if worker.proc is None:
                            worker.start(timeout)
                        reply = worker.request({"op": "render", "frame": to_dict(scenes[spec.frame_id])}, timeout)
                        if reply.get("ok"):
                            events.put(("done", spec, reply))
                            worker.frames_done += 1
                            if worker.frames_done >= opts.recycle_after:
                                worker.close()
                            break
                        reason = reply.get("error", "unknown error")
                    except WorkerDied as exc:
                        reason = f"worker crashed or hung: {exc}"
                        worker.kill()
                    except Exception as exc:  # worker failed to start, broken reply ...
                        reason = f"{type(exc).__name__}: {exc}"
                        worker.kill()
                    attempt += 1
                    if attempt > opts.retries:
                        events.put(("failed", spec, reason))
                        break
                    events.put(("retry", spec, reason))
        finally:
            worker.close()

    pool = [threading.Thread(target=run_slot, args=(i,), daemon=True) for i in range(n_workers)]
    for t in pool:
        t.start()
    progress = Progress(len(todo), "render", enabled=opts.progress)
    timing_log = root / "logs" / "timings.jsonl"
    timing_log.parent.mkdir(parents=True, exist_ok=True)
    try:
        with open(timing_log, "a") as tlog:
            finished = 0
            while finished < len(todo):
                try:
                    kind, spec, info = events.get(timeout=0.5)
                except queue.Empty:
                    if not any(t.is_alive() for t in pool):
                        break
                    progress.refresh()
                    continue
                if kind == "done":
                    finished += 1
                    summary.rendered += 1
                    summary.timings.append(info["timings_s"])
                    tlog.write(json.dumps({"frame_id": spec.frame_id, **info["timings_s"]}) + "\n")
                    tlog.flush()
                elif kind == "failed":
                    finished += 1
                    summary.failed[spec.frame_id] = info
                else:
                    summary.retried += 1
                    progress.note(f"retrying {spec.frame_id}: {info}")
                progress.update(finished, failed=len(summary.failed))
    except KeyboardInterrupt:
        stop.set()
        raise
    finally:
        stop.set()
        for t in pool:
            t.join(timeout=1.0)
        progress.close()


def print_summary(summary: JobSummary, stream=sys.stderr) -> None:
    print(summary.text(), file=stream)
