"""Render jobs: plan -> skip finished frames -> render the rest on worker processes -> manifest.

Resumable (finished frames are never touched), sharded (``shard=(k, n)`` renders frames whose
index % n == k - 1), fault tolerant (a crashed or hung worker is restarted and its frame retried
up to ``retries`` times; frames that still fail are listed and make the job fail) and memory
bounded (workers are recycled after ``recycle_after`` frames).
"""
from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from dockfactory.core.blas import check_label_blas
from dockfactory.core.config import Config
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.io import remove_stale_temps
from dockfactory.core.scene import FrameSpec, to_dict
from dockfactory.generator.datasets.folder import check_target, dataset_lock, frame_done, prepare, write_manifest
from dockfactory.generator.datasets.check import inspect
from dockfactory.generator.datasets.card import write_card
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.datasets.tools import export_complete, write_export
from dockfactory.generator.datasets.dvc_links import outside_note
from dockfactory.generator.exports import check_export_formats
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.render_device import check_render_device
from dockfactory.generator.executors import LocalExecutor, RayExecutor
from dockfactory.core.progress import Progress
from dockfactory.generator.sampler import frame_plan, sample_frame


@dataclass(frozen=True)
class JobOptions:
    workers: int = 1
    shard: tuple[int, int] = (1, 1)
    frame_ids: tuple[str, ...] | None = None   # render only these (still resumable)
    retries: int = 2
    recycle_after: int = 100
    threads: int = 0                           # per worker; 0 = cores // workers
    progress: bool = True
    executor: str = "local"                    # local | ray
    ray_address: str | None = None             # None: start a local Ray instance
    env: dict | None = None                    # worker environment (tests inject faults)


@dataclass
class JobSummary:
    root: str
    version_id: str
    planned: int = 0
    skipped: int = 0
    rendered: int = 0
    recovered: int = 0   # completed by a worker that died before it could answer
    retried: int = 0
    failed: dict = field(default_factory=dict)
    seconds: float = 0.0
    complete: bool = False
    damaged: list = field(default_factory=list)   # problems of a complete dataset (datasets.check)
    notes: list = field(default_factory=list)     # what was left undone on purpose (an export refused)
    timings: list = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not (self.failed or self.damaged)

    def text(self) -> str:
        lines = [f"dataset {self.root} (version {self.version_id})",
                 f"  frames in this run: {self.planned}, already done: {self.skipped}, "
                 f"rendered: {self.rendered}, retried: {self.retried}, failed: {len(self.failed)}"
                 + (f", recovered after a crash: {self.recovered}" if self.recovered else ""),
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
        if self.damaged:
            lines.append(f"  but DAMAGED ({len(self.damaged)} problems; no export written; "
                         f"`dockfactory dataset verify {self.root}` lists them all):")
            lines += [f"    {p}" for p in self.damaged[:5]]
        lines += [f"  note: {n}" for n in self.notes]
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
        raise DockfactoryError(f"--shard {k}/{n}: expected K/N with 1 <= K <= N")
    chosen = [s for s in plan if s.index % n == k - 1]
    if opts.frame_ids is not None:
        known = {s.frame_id for s in plan}
        unknown = sorted(set(opts.frame_ids) - known)
        if unknown:
            raise DockfactoryError(f"frame {unknown[0]!r} is not in this dataset's plan")
        wanted = set(opts.frame_ids)
        chosen = [s for s in chosen if s.frame_id in wanted]
    return chosen


def run_render(cfg: Config, root, config_text: str, opts: JobOptions = JobOptions()) -> JobSummary:
    """Render (the missing frames of) a dataset into ``root``.

    Resumable (finished frames are never touched), sharded, fault tolerant (a crashed or hung worker is restarted and
    its frame retried up to ``opts.retries`` times) and memory bounded (module docstring). The export formats are
    checked, every scene is sampled, the render device and the target folder are checked before anything is written.

    Parameters
    ----------
    cfg, config_text : Config, str
        The dataset config and its resolved TOML text (stored with the dataset, which it reproduces alone).
    root : path
        The dataset folder: new, empty, or holding this very config's version.
    opts : JobOptions
        Workers, shard (k, n), frame ids, retries, worker recycling, threads, progress, executor (local | ray).

    Returns
    -------
    JobSummary
        Frames planned, skipped, rendered, retried, failed (with why), completeness, damage found, wall time; its
        ``ok`` is False when a frame failed or the complete dataset is damaged.

    Raises
    ------
    DockfactoryError
        ``workers`` < 1, a bad shard, a frame id outside the plan, an executor other than local or ray, numpy's
        arithmetic not the labels' (core.blas), a GPU device without a GPU, another writer holding the dataset's
        lock (core.io.FolderBusy).
    ConfigError
        A frame the config cannot sample (its markers do not fit the image, a rolling shutter that does not fit), a
        name of ``[export] formats`` that is no format of the export registry or one written on demand only.
    DatasetError
        ``root`` is not a directory, or holds something else or another dataset version.
    """
    t_start = time.monotonic()
    if opts.workers < 1:
        raise DockfactoryError(f"--workers must be >= 1, got {opts.workers}")
    check_export_formats(cfg)   # the exports written when it completes: refused before any work
    check_label_blas()   # the plan's geometry is computed here, in this process
    frames = select_frames(cfg, opts)
    # sample every scene up front: a bad frame fails before anything is written
    scenes = {s.frame_id: sample_frame(cfg, s) for s in frames}
    check_render_device(cfg, opts.executor, opts.env)   # "gpu" without one: refused before anything is written
    check_target(root)   # a foreign folder is refused before the lock file is made in it
    with dataset_lock(root, "render"):   # one writer per dataset: a second render fails at once
        summary = _run_locked(cfg, Path(root), config_text, opts, frames, scenes)
    summary.seconds = time.monotonic() - t_start
    return summary


def _run_locked(cfg: Config, root: Path, config_text: str, opts: JobOptions, frames, scenes) -> JobSummary:
    ident = prepare(root, cfg, config_text)
    stale_s = cfg.render.frame_timeout_s + 60.0
    remove_stale_temps(root, max_age_s=stale_s)  # left by a killed run
    summary = JobSummary(root=str(root), version_id=ident["version_id"], planned=len(frames))
    todo = [s for s in frames if not frame_done(root, s.frame_id, cfg.render.keep_exr, cfg.sensor.raw_output)]
    summary.skipped = len(frames) - len(todo)

    if todo:
        _render(cfg, root, todo, scenes, opts, summary)
    # temporaries of a killed worker (or of a killed earlier run whose writer had not yet exited
    # when this run started): removed before the dataset is declared complete
    remove_stale_temps(root, max_age_s=stale_s)
    summary.complete = all(frame_done(root, s.frame_id, cfg.render.keep_exr, cfg.sensor.raw_output)
                           for s in frame_plan(cfg))
    if summary.complete:
        write_manifest(root, cfg)
        # a file changed after its frame was finished (same size: frame_done cannot tell) or an
        # unlisted one: the dataset is complete but not intact, and it is said (exit 1)
        report, checked = inspect(root, hash_bulk=False)   # the bytes were hashed as they were written
        summary.damaged = report.problems()
        if summary.damaged:
            return summary
        ds = Dataset.of_checked(root, checked, full=False)
        _finish(ds, cfg, summary)
    return summary


def _finish(ds: Dataset, cfg: Config, summary: JobSummary) -> None:
    """The derived files of a complete, intact dataset: its exports (written once; not inside a
    DVC-tracked dataset whose project does not ignore ``exports/``: a note says where `dataset
    export` writes them) and its card."""
    outside = outside_note(ds.root)
    for fmt in cfg.export.formats:
        if export_complete(ds.root, fmt):        # written once, when the dataset completes
            continue
        if outside:
            summary.notes.append(f"export {fmt} not written: {outside}")
            continue
        write_export(ds.root, fmt, ds)           # (a partial export of a killed run is replaced)
    write_card(ds)                               # untouched when current (a DVC-tracked dataset stays clean)


def worker_init_request(cfg, root: Path, threads: int, keep_exr: bool | None = None) -> dict:
    """The init request of a render worker (generator.render_worker) for ``cfg``'s frames written
    under ``root`` with ``threads`` Cycles threads; ``keep_exr`` None: the config's."""
    return {"op": "init", "static": to_dict(static_scene(cfg)), "width": cfg.image.width,
            "height": cfg.image.height, "threads": threads, "root": str(Path(root).resolve()),
            "keep_exr": cfg.render.keep_exr if keep_exr is None else keep_exr,
            "keep_raw": cfg.sensor.raw_output, "visible_threshold": cfg.labels.visible_threshold,
            "min_chroma": cfg.labels.min_chroma, "device": cfg.render.device}


def _render(cfg, root: Path, todo, scenes, opts: JobOptions, summary: JobSummary) -> None:
    n_workers = min(opts.workers, len(todo))
    threads = opts.threads or max(1, cores() // n_workers)
    init = worker_init_request(cfg, root, threads)
    log_dir = root / "logs"
    log_dir.mkdir(parents=True, exist_ok=True)
    if opts.executor == "ray":
        executor = RayExecutor(n_workers, threads, opts.ray_address, log_dir, opts.env)
    elif opts.executor == "local":
        executor = LocalExecutor(n_workers, log_dir, opts.env,
                                 is_done=lambda fid: frame_done(root, fid, cfg.render.keep_exr, cfg.sensor.raw_output))
    else:
        raise DockfactoryError(f"--executor must be local or ray, got {opts.executor!r}")
    frames = [to_dict(scenes[s.frame_id]) for s in todo]
    progress = Progress(len(todo), "render", enabled=opts.progress)
    finished = 0
    try:
        with open(log_dir / "timings.jsonl", "a") as tlog:
            for kind, fid, info in executor.run(frames, init, cfg.render.frame_timeout_s, opts.retries,
                                                opts.recycle_after):
                if kind == "tick":
                    progress.refresh()
                    continue
                if kind == "done":
                    finished += 1
                    if info.get("recovered"):   # finished by a worker that died before answering
                        summary.recovered += 1
                    else:
                        summary.rendered += 1
                        summary.timings.append(info["timings_s"])
                        tlog.write(json.dumps({"frame_id": fid, **info["timings_s"], "rss_mb": info.get("rss_mb"),
                                               "finished_at": info.get("finished_at")}) + "\n")
                        tlog.flush()
                elif kind == "failed":
                    finished += 1
                    summary.failed[fid] = info
                elif kind == "retry":
                    summary.retried += 1
                    progress.note(f"retrying {fid}: {info}")
                progress.update(finished, failed=len(summary.failed))
    finally:
        progress.close()


def print_summary(summary: JobSummary, stream=None) -> None:
    print(summary.text(), file=stream if stream is not None else sys.stderr)
