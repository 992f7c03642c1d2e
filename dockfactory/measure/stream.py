"""``dockfactory measure --video PATH | --camera INDEX``: the pose of B in A from a stream of frames,
one JSON line per frame written (and flushed) as soon as the frame is measured.

Frames come from OpenCV's ``cv2.VideoCapture``: a video file (any container and codec its FFmpeg
reads), an image-sequence pattern (``frames/%06d.png``) or a capture device (``--camera INDEX``,
mapped to what VideoCapture opens by :func:`camera_source`). A reader thread decodes the next frame
while the current one is measured (decoding releases the interpreter lock, so it overlaps the
network and the solve). Each frame goes through measure's per-image path
(``dockfactory.measure.images.solve_image``: detect, identify, solve with its own camera model fit,
principal point assumed at the image centre).

Why and how: docs/measure.md, "The stream's lines".
"""
from __future__ import annotations

import fcntl
import json
import os
import queue
import sys
import threading
import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.calibration_files import Calibration
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.histogram import LogHistogram
from dockfactory.core.layout_file import read_layout_file
from dockfactory.core.names import MIN_SCORE, POSE_NAMES
from dockfactory.eval.acceptance import load_acceptance
from dockfactory.eval.camera_classes import camera_class, class_section_shift
from dockfactory.eval.conformity import UNDECIDED, coverage_k, pose_conformity, pose_tolerances
from dockfactory.eval.solve_frames import docking_options, resolve_camera_model
from dockfactory.solver.options import LensPrior
from dockfactory.measure.image_header import image_size
from dockfactory.measure.images import MAX_WORKERS, solve_image
from dockfactory.measure.chroma import source_chroma
from dockfactory.measure.kalman import PoseKalman
from dockfactory.measure.roi import RoiTracker
from dockfactory.measure.selfcal import WindowCalibration
from dockfactory.measure.stream_pool import StreamPool
from dockfactory.measure.read import captured_stderr
from dockfactory.measure.store import plain

STREAM_FORMAT = "dockfactory.measure_stream/1"
FILTERS = ("kalman",)
PREFETCH = 1       # frames decoded ahead of the one being measured (more only adds latency)
MAX_PREFETCH = 8


def camera_source(index: int):
    """What ``cv2.VideoCapture`` opens for ``--camera INDEX``: the device index itself. Tests
    replace this mapping to back a "camera" by a file (a camera-less machine has no device)."""
    return index


@dataclass(frozen=True)
class StreamOptions:
    """How the stream is measured: the detector's ``backend`` (auto, torch, onnx), the solver's
    ``camera_model`` (pinhole, k1, k1k2, pp_k1, pp_k1_p, auto), ``min_score``, the camera's Bayer
    pattern ``cfa`` (steers the centre refinement; None: unknown), ``filter`` (None or "kalman"),
    ``max_frames`` (None: until the source ends), ``jpeg`` (the frames' colour is subsampled, as
    JPEG and lossy video keep it: the centre's edge fitted on the luma; also set when the source
    says so, dockfactory.measure.chroma), ``prefetch`` (frames decoded ahead by a reader thread, 0: none;
    :class:`FrameReader`) and ``input_scale`` (network px per image px; None: the weights' own,
    smaller is faster and sees smaller markers worse) and ``roi_refresh`` (None: every frame
    detected whole; N: a window around the previous frame's markers, the full frame every N
    frames and whenever the window loses a marker: dockfactory.measure.roi), ``window`` (None, or
    N: intrinsics self-calibrated over the last N frames, dockfactory.measure.selfcal) and
    ``freeze_after`` (with a window: freeze them after this many joint solves), ``workers``
    (processes measuring frames at once: dockfactory.measure.stream_pool; 1: this process),
    ``lens`` (the lens prior marginalised into every pose's uncertainty, solver.options.LensPrior;
    None: an uncalibrated camera's), ``calibration`` (the camera's, core.calibration_files:
    every frame solved as ``measure --calibration`` solves an image; not with a camera model, a
    lens prior or a self-calibrating window, which estimate what it states)."""
    backend: str = "auto"
    camera_model: str | None = None
    min_score: float = MIN_SCORE
    cfa: str | None = None
    filter: str | None = None
    max_frames: int | None = None
    jpeg: bool = False
    prefetch: int = PREFETCH
    input_scale: float | None = None
    roi_refresh: int | None = None
    window: int | None = None
    freeze_after: int | None = None
    workers: int = 1
    lens: LensPrior | None = None
    calibration: Calibration | None = None

    def __post_init__(self):
        if self.calibration is not None and (self.lens is not None or self.window
                                             or self.camera_model not in (None, "pinhole")):
            raise DockfactoryError("--calibration: the camera is calibrated; --lens-prior, --camera-model and "
                                   "--self-calibrate estimate what it states")
        if not 1 <= self.workers <= MAX_WORKERS:
            raise DockfactoryError(f"--workers: expected 1 to {MAX_WORKERS} for a stream, got {self.workers}")
        if self.workers > 1 and (self.roi_refresh or self.window):
            raise DockfactoryError("--workers: a stream is measured by several processes only frame by frame, "
                                   "not with --roi or --self-calibrate window:N (they carry state between frames)")
        if self.filter is not None and self.filter not in FILTERS:
            raise DockfactoryError(f"--filter: expected one of {', '.join(FILTERS)}, got {self.filter!r}")
        if self.max_frames is not None and self.max_frames < 1:
            raise DockfactoryError(f"--max-frames: expected an integer >= 1, got {self.max_frames}")
        if not 0 <= self.prefetch <= MAX_PREFETCH:
            raise DockfactoryError(f"prefetch: expected 0 to {MAX_PREFETCH} frames, got {self.prefetch}")
        if self.freeze_after is not None and (self.window is None or self.freeze_after < 1):
            raise DockfactoryError("--freeze-after: needs --self-calibrate window:N and an integer >= 1")
        if self.roi_refresh is not None and self.roi_refresh < 1:
            raise DockfactoryError(f"--roi: expected a refresh interval >= 1 frame, got {self.roi_refresh}")
        if self.input_scale is not None and not 0.1 <= self.input_scale <= 2.0:
            raise DockfactoryError(f"--input-scale: expected a number in [0.1, 2], got {self.input_scale}")
        resolve_camera_model(self.camera_model, None)


def open_capture(video=None, camera: int | None = None) -> tuple[cv2.VideoCapture, str]:
    """(an opened capture, its name for messages) of exactly one of ``video`` (a path or pattern)
    and ``camera`` (an index); DockfactoryError naming the source when it cannot be opened."""
    if (video is None) == (camera is None):
        raise DockfactoryError("measure: give exactly one of --video PATH and --camera INDEX")
    if video is not None:
        name, source = f"--video {video}", str(video)
        if "%" not in source and not Path(source).is_file():
            raise DockfactoryError(f"{name}: no such video file")
    else:
        name, source = f"--camera {camera}", camera_source(camera)
    notes: list = []
    with captured_stderr(notes):   # OpenCV's warnings about a source it cannot open
        cap = cv2.VideoCapture(source)
        opened = cap.isOpened()
    if not opened:
        cap.release()
        why = f" ({'; '.join(notes)[:200]})" if notes else ""
        raise DockfactoryError(f"{name}: OpenCV's VideoCapture cannot open it{why}")
    return cap, name


SEQUENCE_FIRST_MAX = 1000   # an image sequence's first frame is looked for from index 0 to this (as OpenCV does)
FRAME_SIZE = "frame size"   # the failure category of a sequence frame of another size than the first


def sequence_frame_check(video):
    """For an image-sequence pattern (``frames/%06d.png``): ``check(index)``, the one-line reason
    why frame ``index`` of the sequence is refused (its file's header states another size than the
    first frame's, or none), else None; OpenCV's reader decodes every frame at the first one's size,
    so a frame of another size would be measured garbled. None for a video file, a camera, or a
    pattern without a first file."""
    pattern = str(video) if video is not None else ""
    if "%" not in pattern:
        return None
    try:
        names = (pattern % i for i in range(SEQUENCE_FIRST_MAX + 1))
        first = next((i for i, name in enumerate(names) if Path(name).is_file()), None)
    except (TypeError, ValueError):
        return None
    try:
        size = image_size(pattern % first)[1:] if first is not None else None
    except (OSError, ValueError):   # OpenCV names an unreadable first frame
        size = None
    if size is None:
        return None

    def check(index: int) -> str | None:
        path = pattern % (first + index)
        try:
            got = image_size(path)[1:]
        except (OSError, ValueError) as exc:
            return f"{path}: {' '.join(str(exc).split())[:200]}"
        if got != size:
            return (f"{path}: {got[0]}x{got[1]}, the sequence's frames are {size[0]}x{size[1]} (its first, "
                    f"{pattern % first}): refused, OpenCV would decode it garbled at the first frame's size")
        return None
    return check


class FrameReader:
    """Iterates ``(index, t_start, read_ms, timestamp_ms, rgb)`` over the frames of an open capture;
    ``t_start`` is the ``time.perf_counter()`` at which the frame's read began (the start of its
    latency). With ``prefetch`` > 0 a thread reads (decodes) up to that many frames ahead of the
    one being measured: the read of frame k + 1 overlaps the measurement of frame k, and a frame
    read ahead waits for the consumer (which counts in its latency). 0: each frame is read when
    the consumer asks for it. Stops after ``max_frames`` (None: at the end of the source). ``check``
    (:func:`sequence_frame_check`): a frame it refuses comes with its reason (a str) in place of rgb."""

    def __init__(self, cap: cv2.VideoCapture, max_frames: int | None = None, prefetch: int = PREFETCH,
                 check=None):
        self.cap, self.max_frames, self.prefetch, self.check = cap, max_frames, prefetch, check
        self.fps = cap.get(cv2.CAP_PROP_FPS) or 0.0
        self.frames: queue.Queue = queue.Queue()
        self.slots = threading.Semaphore(max(prefetch, 1))
        self.stop = threading.Event()
        self.t0 = time.perf_counter()

    def _timestamp_ms(self, index: int) -> float:
        pos = self.cap.get(cv2.CAP_PROP_POS_MSEC)
        if pos > 0 or index == 0 and self.fps > 0:
            return round(float(pos), 3)
        if self.fps > 0:
            return round(1000.0 * index / self.fps, 3)
        return round(1000.0 * (time.perf_counter() - self.t0), 3)

    def read(self, index: int):
        """Frame ``index`` (the next one) as the iteration's tuple, or None at the end."""
        if self.max_frames is not None and index >= self.max_frames:
            return None
        t_start = time.perf_counter()
        ok, bgr = self.cap.read()
        if not ok or bgr is None:
            return None
        refused = self.check(index) if self.check is not None else None
        rgb = refused or cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB, dst=bgr)
        return index, t_start, 1000.0 * (time.perf_counter() - t_start), self._timestamp_ms(index), rgb

    def _read_ahead(self) -> None:
        index = 0
        while True:
            while not self.slots.acquire(timeout=0.1):   # a free slot: the consumer took a frame
                if self.stop.is_set():
                    return
            item = None if self.stop.is_set() else self.read(index)
            self.frames.put(item)
            if item is None:
                return
            index += 1

    def __iter__(self):
        try:
            if self.prefetch == 0:
                index = 0
                while (item := self.read(index)) is not None:
                    yield item
                    index += 1
                return
            thread = threading.Thread(target=self._read_ahead, daemon=True)
            thread.start()
            while (item := self.frames.get()) is not None:
                self.slots.release()
                yield item
        finally:
            self.stop.set()
            if self.prefetch:
                thread.join()
            self.cap.release()


def frame_line(index: int, timestamp_ms: float, record: dict) -> dict:
    """The JSON line of one measured frame (the module docstring) from its measure record; its
    ``camera_class`` (eval.camera_classes) when the record names one, as every record of
    :meth:`StreamMeasurer.line` does."""
    line = {"type": "frame", "frame": index, "timestamp_ms": timestamp_ms, "ok": bool(record["ok"])}
    if "camera_class" in record:
        line["camera_class"] = record["camera_class"]
    if record["ok"]:
        std = np.sqrt(np.clip(np.diag(np.asarray(record["covariance"], float)), 0.0, None))
        line.update(pose=record["pose"], std=dict(zip(POSE_NAMES, std.tolist())), focal_px=record["focal_px"],
                    camera_model=record.get("camera_model", "pinhole"))
        for key in ("intrinsics", "intrinsics_std", "calibration"):
            if key in record:
                line[key] = record[key]
        line.update(rmse_px=record["rmse_px"], n_detections=record["n_detections"], marker_ids=record["marker_ids"])
    else:
        line.update(category=record.get("category"), reason=record.get("reason"))
    for key in ("roi", "self_calibrated", "run_frames", "run_bias_px", "frozen_intrinsics", "self_calibration",
                "notes"):
        if key in record:
            line[key] = record[key]
    return line


class LineSink:
    """Where the JSON lines go: ``"-"`` (standard output) or a file, checked at once (a folder, a
    missing parent, or a file another process is writing is a DockfactoryError) but opened at the
    first line, so a source that fails leaves no file. The file is held under an exclusive
    ``flock`` from its first line to the end (two streams into one file would interleave; the
    second is refused in one line, the first's file untouched) and emptied only once held. Every
    line is one write and one flush: a stream stopped at any point leaves whole lines."""

    def __init__(self, target: str):
        self.target, self.handle = target, None
        if target != "-":
            path = Path(target)
            if path.is_dir() or not path.parent.is_dir():
                raise DockfactoryError(f"--jsonl {target}: not a file in an existing folder")
            if path.is_file():
                os.close(self._locked_fd(os.O_RDONLY))

    def _locked_fd(self, flags: int) -> int:
        """A descriptor of the target under an exclusive lock; DockfactoryError when another
        process holds it."""
        fd = os.open(self.target, flags)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise DockfactoryError(f"--jsonl {self.target}: another process is writing it (a stream "
                                   "already running into it); give another file") from None
        return fd

    def write(self, obj: dict) -> None:
        if self.handle is None:
            self.handle = sys.stdout if self.target == "-" else self._open()
        self.handle.write(json.dumps(plain(obj), allow_nan=False) + "\n")
        self.handle.flush()

    def _open(self):
        fd = self._locked_fd(os.O_WRONLY | os.O_CREAT)
        os.ftruncate(fd, 0)
        return os.fdopen(fd, "w", encoding="utf-8")

    def close(self) -> None:
        if self.handle is not None and self.target != "-":
            self.handle.close()


def _percentile(hist: LogHistogram | None, q: float) -> float | None:
    v = None if hist is None else hist.percentile(q)
    return None if v is None else round(float(v), 2)


@dataclass
class StreamStats:
    """What the summary counts, frame by frame, in constant memory (a stream may run for days):
    counts, and per quantity a log-spaced histogram whose percentiles are within 1 % of the exact
    ones (core.histogram)."""
    frames: int = 0
    with_pose: int = 0
    failures: dict | None = None
    latency_ms: LogHistogram | None = None
    timing_ms: dict | None = None

    def add(self, line: dict, latency_ms: float) -> None:
        self.failures = self.failures or {}
        self.latency_ms = self.latency_ms or LogHistogram()
        self.latency_ms.add(latency_ms)
        self.timing_ms = self.timing_ms or {}
        self.frames += 1
        self.with_pose += line["ok"]
        if not line["ok"]:
            self.failures[line["category"]] = self.failures.get(line["category"], 0) + 1
        for k, v in line["timing_ms"].items():
            self.timing_ms.setdefault(k, LogHistogram()).add(v)

    def summary(self, wall_s: float) -> dict:
        lat = self.latency_ms
        return {"frames": self.frames, "frames_with_pose": self.with_pose, "failures": self.failures or {},
                "wall_s": round(wall_s, 3), "frames_per_s": round(self.frames / max(wall_s, 1e-9), 2),
                "latency_ms": {"p50": _percentile(lat, 50), "p95": _percentile(lat, 95),
                               "max": _percentile(lat, 100)},
                "timing_ms_median": {k: _percentile(v, 50) for k, v in (self.timing_ms or {}).items()}}


@dataclass
class StreamMeasurer:
    """Measures one frame after another: the loaded ``detector``, the ``markers`` of the layout,
    the options, the display filter (None or a PoseKalman), the acceptance hook ``decide``
    (None or a callable: frame line -> JSON value; see the module docstring) and the window
    tracker (None: every frame detected whole; dockfactory.measure.roi) and the online
    self-calibration (None, or dockfactory.measure.selfcal.WindowCalibration)."""
    detector: object
    markers: tuple
    options: StreamOptions
    kalman: PoseKalman | None = None
    decide: Callable[[dict], object] | None = None
    tracker: RoiTracker | None = None
    calibration: WindowCalibration | None = None

    def solve(self, index: int, image: np.ndarray) -> dict:
        """The measure record of one decoded frame (with ``roi``: the window the detector saw, or
        null for the full frame, when tracking); an error on the way is the frame's failure
        ("measure error"), warnings are kept in its ``notes``."""
        name = Path(f"frame {index}")
        if isinstance(image, str):   # refused by the reader (FrameReader's check)
            return {"ok": False, "category": FRAME_SIZE, "reason": f"{name}: {image}"}
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                frame = self._tracked(index, name, image)
                record = frame.record if self.calibration is None else self.calibration.apply(index, frame)
        except Exception as exc:   # noqa: BLE001 -- one frame's failure is recorded, the stream goes on
            words = " ".join(str(exc).split())[:300] or "no message"
            return {"ok": False, "category": "measure error", "reason": f"{name}: {type(exc).__name__}: {words}"}
        if caught:
            record["notes"] = sorted({f"{w.category.__name__}: {w.message}" for w in caught})[:20]
        return record

    def _tracked(self, index: int, name: Path, image: np.ndarray):
        """measure.solve_image (a measure.Frame) on the tracker's window (the full frame when it
        loses a marker); the pinhole model when the window self-calibrates afterwards."""
        o = self.options
        model = "pinhole" if self.calibration is not None else resolve_camera_model(o.camera_model, None)
        args = (self.detector, self.markers, index, name, image, model, o.min_score, o.cfa, o.jpeg)
        camera = {"lens": o.lens, "calibration": o.calibration}
        if self.tracker is None:
            return solve_image(*args, **camera)
        roi = self.tracker.region()
        frame = solve_image(*args, roi, **camera)
        if roi is not None and self.tracker.lost(frame.detections, roi):
            spent = frame.record["timing_ms"]
            frame = solve_image(*args, **camera)
            frame.record["timing_ms"] = {k: round(v + spent[k], 2) for k, v in frame.record["timing_ms"].items()}
            roi = None
        self.tracker.update(frame.detections, roi)
        frame.record["roi"] = None if roi is None else list(roi)
        return frame

    def line(self, item, record: dict | None = None) -> dict:
        """The JSON line of one frame ``(index, t_start, read_ms, timestamp_ms, rgb)`` of a
        :class:`FrameReader`, its timings and (with them) the filtered pose and the hook's answer;
        ``record``: the frame's measure record when a worker process made it (None: solved here).
        Every line names the frame's ``camera_class``: the record's, else (a frame refused or failed
        before its solve) the class of the options' ``cfa`` and ``jpeg`` (eval.camera_classes)."""
        index, t_start, read_ms, timestamp_ms, rgb = item
        record = self.solve(index, rgb) if record is None else record
        record.setdefault("camera_class", camera_class(self.options.cfa, self.options.jpeg))
        line = frame_line(index, timestamp_ms, record)
        if self.kalman is not None:
            line["filtered"] = self.kalman.step(timestamp_ms / 1000.0, line.get("pose"), line.get("std"))
        if self.decide is not None:
            line["acceptance"] = self.decide(line)
        spent = record.get("timing_ms", {})
        line["timing_ms"] = {"read": round(read_ms, 2), "detect": spent.get("detect", 0.0),
                             "solve": spent.get("solve", 0.0),
                             "total": round(1000.0 * (time.perf_counter() - t_start), 2)}
        return line


def load_detector(weights, options: StreamOptions, size: tuple[int, int] | None = None):
    """The marker detector of ``weights`` on the options' backend and input scale (torch is
    imported here), warmed up on a black frame of ``size`` (width, height; None or 0: not), so
    the first frame's latency is not the runtime's set-up."""
    from dockfactory.detector.infer import MarkerDetector
    detector = MarkerDetector(weights, conf_threshold=options.min_score, backend=options.backend)
    if options.input_scale is not None:
        detector.scale = float(options.input_scale)
    if size and min(size) > 0:
        detector.raw(np.zeros((size[1], size[0], 3), np.uint8))
    return detector


def worker_measurer(weights, options: StreamOptions, markers, size) -> StreamMeasurer:
    """A worker process's measurer (dockfactory.measure.stream_pool): the detector of ``weights``
    on one thread, warmed up at the frames' ``size``; frame by frame, no filter, hook or state."""
    detector = load_detector(weights, options, size)
    if detector.backend == "onnx":
        detector.network.threads = 1
    return StreamMeasurer(detector, tuple(markers), options)


def stream_decider(acceptance) -> Callable[[dict], dict]:
    """The acceptance hook of ``measure --video/--camera --acceptance SPEC``: each frame's pose
    against the spec's single-pose tolerances (``eval.conformity``, the guard band U = k u of the
    frame's reported 1-sigma stds; no layout term: a stream carries no budget), as the still-image
    path judges an image; a frame without a pose is UNDECIDED. Bad spec: one-line DockfactoryError
    before anything is opened."""
    spec = load_acceptance(acceptance)
    tolerances, k = pose_tolerances(spec, str(acceptance)), coverage_k(spec)

    def decide(line: dict) -> dict:
        if not line.get("ok"):
            return {"components": {}, "decision": UNDECIDED, "k": k}
        return pose_conformity(line["pose"], line["std"], tolerances, k)
    return decide


def measure_stream(layout_path, weights, jsonl: str = "-", video=None, camera: int | None = None,
                   options: StreamOptions = StreamOptions(), decide: Callable[[dict], object] | None = None,
                   detector=None) -> dict:
    """Measure every frame of ``video`` or ``camera`` (see the module docstring), writing the lines
    to ``jsonl`` ("-": standard output); returns the summary (also the last line). ``detector``:
    an already loaded one (else loaded from ``weights``; with ``options.workers`` > 1 each worker
    process loads its own)."""
    markers = read_layout_file(layout_path)
    sink = LineSink(jsonl)
    cap, name = open_capture(video, camera)
    pool, chroma = None, source_chroma(cap, video)
    options = replace(options, jpeg=options.jpeg or chroma.subsampled)
    try:
        size = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        if options.workers > 1:
            pool = StreamPool(worker_measurer, options.workers, weights, options, markers, size)
        else:
            detector = detector if detector is not None else load_detector(weights, options, size)
    except BaseException:
        cap.release()
        raise
    measurer = _measurer(detector if pool is None else None, markers, options, decide, size)
    try:
        stats, stopped, t0 = _measure_lines(measurer, FrameReader(cap, options.max_frames, options.prefetch,
                                                                    sequence_frame_check(video)), pool, sink)
        if stats.frames == 0:
            raise DockfactoryError(f"{name}: no frame could be read")
        summary = {"type": "summary", "format": STREAM_FORMAT, "source": name, "stopped": stopped,
                   "camera_model": resolve_camera_model(options.camera_model, "sequence" if options.window else None),
                   "self_calibrate": f"window:{options.window}" if options.window else None,
                   "freeze_after": options.freeze_after, "backend": detector.backend if pool is None else pool.backend,
                   "workers": options.workers, "prefetch": options.prefetch, "filter": options.filter,
                   "roi_refresh": options.roi_refresh, "chroma": "subsampled" if options.jpeg else "full",
                   "chroma_source": chroma.why,
                   "acceptance": decide is not None, "layout": str(layout_path),
                   "weights": str(weights), **stats.summary(time.perf_counter() - t0)}
        sink.write(summary)
    finally:
        sink.close()
        if pool is not None:
            pool.__exit__(None, None, None)
    return summary


def _measurer(detector, markers, options: StreamOptions, decide, size) -> StreamMeasurer:
    """The parent's StreamMeasurer: the window tracker and online self-calibration as the options
    ask (never with worker processes, which ``StreamOptions`` refuses), the display filter, the hook."""
    tracker = (RoiTracker(*size, refresh=options.roi_refresh, min_score=options.min_score)
               if options.roi_refresh and min(size) > 1 else None)
    calibration = (WindowCalibration(markers, options.window, resolve_camera_model(options.camera_model, "sequence"),
                                     options.freeze_after,
                                     docking_options(detector.centre_noise_px, options.lens,
                                                     class_section_shift(camera_class(options.cfa, options.jpeg),
                                                                         detector.section_shift_px)))
                   if options.window else None)
    return StreamMeasurer(detector, markers, options, PoseKalman() if options.filter == "kalman" else None,
                          decide, tracker, calibration)


def _measure_lines(measurer: StreamMeasurer, reader: FrameReader, pool, sink: LineSink):
    """Measure (here, or by ``pool``'s workers) and write every frame's line; (stats, how the stream
    stopped, the clock's start)."""
    stats, stopped, t0 = StreamStats(), "end of stream", time.perf_counter()
    pairs = ((item, None) for item in reader) if pool is None else pool.measure(reader)
    try:
        for item, record in pairs:
            sink.write(line := measurer.line(item, record))
            stats.add(line, 1000.0 * (time.perf_counter() - item[1]))
    except KeyboardInterrupt:
        stopped = "interrupted"
    return stats, stopped, t0
