"""``dockfactory measure``: the pose of B in A from real images, without labels.

PNG/JPEG/TIFF/BMP images (files or folders) -> detector -> identification -> solve (the chosen camera
model, per frame, or self-calibrated over the whole set as one docking run of one camera) ->
OUT/measurements.json, OUT/measurements.csv and one overlay PNG per image in OUT/overlays/.
Every pose carries its uncertainty budget (U = 2 u); with an acceptance spec each image is judged
IN / OUT / UNDECIDED against its tolerances (dockfactory.measure.verdict).

Why and how: docs/measure.md, "Measure: records and batches".
"""
from __future__ import annotations

import csv
import os
import io
import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from dockfactory.core.calibration_files import Calibration, ideal_pixels
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.io import sha256_file, write_bytes_atomic, write_json_atomic
from dockfactory.core.layout_file import read_layout_file, read_layout_sigmas
from dockfactory.core.names import MIN_SCORE, POSE_NAMES
from dockfactory.detector.noise_card import card_figures
from dockfactory.measure.overlay import draw_measurement
from dockfactory.measure.pool import MeasurePool
from dockfactory.measure.selfcal import kept_from_frame
from dockfactory.measure.read import (
    DEFAULT_MAX_MEGAPIXELS,
    MAX_MEGAPIXELS,
    CameraInput,
    max_pixels_of,
    probe_image,
    read_image,
)
from dockfactory.measure.store import WRITE_ERROR, MeasureStore, image_identity
from dockfactory.measure.verdict import add_conformity, add_uncertainty
from dockfactory.eval.acceptance import load_acceptance
from dockfactory.eval.conformity import COVERAGE_K, pose_tolerances
from dockfactory.eval.uncertainty_budget import TERMS
from dockfactory.eval.camera_classes import (
    CAMERA_CLASS_FACTORS,
    camera_class,
    class_section_shift,
    classes_factor,
    classes_section_shift,
)
from dockfactory.solver.options import LensPrior
from dockfactory.eval.solve_frames import (
    detection_arrays,
    docking_options,
    name_camera_classes,
    resolve_camera_model,
    solve_frame,
    solve_run,
    with_class_prior,
)
from dockfactory.generator.datasets.folder import writer_lock
from dockfactory.generator.version import package_version

__all__ = ["CameraInput", "MeasureOptions", "collect_images", "measure", "read_image"]

MEASURE_FORMAT = "dockfactory.measure/1"
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")   # a one-channel 16-bit PNG is a raw frame
MAX_WORKERS = 16   # measure's worker processes (each holds a detector: about 0.3 GB)
NO_MARKERS = "no markers detected"   # the category of a frame without one detection
CALIBRATED_LENS = LensPrior(marginalise=False)   # a calibrated camera's lens: known, nothing marginalised


def calibration_lens(cal: Calibration) -> LensPrior:
    """What the solve takes for the lens of calibrated camera ``cal``: known (nothing marginalised)
    when its file states no uncertainty; else the stated 1-sigma of the principal point, k1, k2
    and p1 / p2 as the uniform half-ranges of the same std (sqrt(3) sigma; the principal point's
    the larger of cx's and cy's), marginalised into the pose's covariance. The focal is solved,
    so its own uncertainty does not enter; k3 has no term in the prior."""
    if cal.std is None:
        return CALIBRATED_LENS
    root3 = 3.0 ** 0.5
    _, _, s_cx, s_cy, s_k1, s_k2, s_p1, s_p2, _ = cal.std
    return LensPrior(pp_fraction=root3 * max(s_cx, s_cy) / (2.0 * cal.cx + 1.0), k1=root3 * s_k1, k2=root3 * s_k2,
                     p=root3 * max(s_p1, s_p2), marginalise=True)


@dataclass
class Frame:
    """One image on its way through measure: its record and what the overlay needs."""
    index: int
    path: Path
    record: dict
    image: np.ndarray | None = None
    detections: list = field(default_factory=list)
    principal_point: tuple = (0.0, 0.0)
    used_points: dict = field(default_factory=dict)   # marker id -> (u, v) the frame's fit used


def collect_images(items) -> list[Path]:
    """The images named by ``items`` (files, or folders whose entries named like images are taken
    in name order), each once; a path that does not exist, or an entry that is no file (a FIFO or
    a folder called x.png), stays in the list (reported per image, never dropped)."""
    out, seen = [], set()
    if any(not str(item).strip() for item in items):
        raise DockfactoryError("measure: an image path is empty (Path('') would be the current folder)")
    for item in map(Path, items):
        if item.is_dir():
            found = sorted(p for p in item.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
            if not found:
                raise DockfactoryError(f"{item}: no PNG, JPEG, TIFF or BMP images in this folder")
        else:
            found = [item]
        for p in found:
            key = os.path.realpath(p)   # never raises (a symlink loop is reported per image)
            if key not in seen:
                seen.add(key)
                out.append(p)
    if not out:
        raise DockfactoryError("measure: no images given")
    return out


DEFAULT_MAX_PIXELS = max_pixels_of(DEFAULT_MAX_MEGAPIXELS)


def measure_frame(detector, markers, index: int, path: Path, camera_model: str, min_score: float,
                  camera: CameraInput = CameraInput(), max_pixels: int = DEFAULT_MAX_PIXELS) -> Frame:
    """Read, detect and solve one image (its own camera model fit). A frame without a detection
    scoring ``min_score`` is "no markers detected"; the messages of the decoder and the warnings
    raised on the way are kept in the record (``notes``), not printed."""
    notes: list = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        frame = _detect_and_solve(detector, markers, index, path, camera_model, min_score, camera, max_pixels, notes)
    notes += [f"{w.category.__name__}: {w.message}" for w in caught]
    if notes:
        frame.record["notes"] = sorted(set(notes))[:20]
    return frame


def _detect_and_solve(detector, markers, index, path, camera_model, min_score, camera, max_pixels, notes) -> Frame:
    image, failed = read_image(path, camera, max_pixels, notes)
    if failed is not None:
        return Frame(index, path, failed)
    return solve_image(detector, markers, index, path, image, camera_model, min_score, camera.cfa,
                       path.suffix.lower() in (".jpg", ".jpeg"), lens=camera.lens, calibration=camera.calibration)


def detect_in(detector, image: np.ndarray, roi: tuple | None = None, cfa: str | None = None,
              jpeg: bool = False) -> list[dict]:
    """The detections of ``image`` (detector.MarkerDetector.detect), or of its region ``roi`` =
    (x0, y0, x1, y1) only (pixel indices, x1 and y1 excluded; x0 and y0 even, so a Bayer pattern
    keeps its phase), in the whole image's pixels either way."""
    if roi is None:
        return detector.detect(image, cfa=cfa, jpeg=jpeg)
    x0, y0, x1, y1 = roi
    if x0 % 2 or y0 % 2 or not (0 <= x0 < x1 <= image.shape[1] and 0 <= y0 < y1 <= image.shape[0]):
        raise ValueError(f"roi {roi} is not an even-cornered region of a {image.shape[1]}x{image.shape[0]} image")
    dets = detector.detect(np.ascontiguousarray(image[y0:y1, x0:x1]), cfa=cfa, jpeg=jpeg)
    for d in dets:
        for key in ("bbox_px", "bbox_detector_px"):
            d[key] = [v + (x0, y0)[i % 2] for i, v in enumerate(d[key])]
        d["center_px"] = [d["center_px"][0] + x0, d["center_px"][1] + y0]
    return dets


def solve_image(detector, markers, index: int, path: Path, image: np.ndarray, camera_model: str, min_score: float,
                cfa: str | None = None, jpeg: bool = False, roi: tuple | None = None,
                lens: LensPrior | None = None, calibration: Calibration | None = None) -> Frame:
    """Detect and solve one decoded image ``(H, W, 3) uint8`` RGB (its own camera model fit; the
    principal point assumed is its centre): the per-image path of measure, shared with the stream
    path (dockfactory.measure.stream). ``path`` names the frame in a failure's reason; ``cfa`` and
    ``jpeg`` steer the centre refinement (detector.MarkerDetector.detect); ``roi``: detect in this
    region only (:func:`detect_in`); ``lens`` the lens prior marginalised into the covariance (None:
    an uncalibrated camera's, eval.solve_frames.UNCALIBRATED_LENS); ``calibration`` the camera's
    (:func:`calibrated_solve`). The record carries ``image_size``, ``timing_ms`` (detect, solve)
    and ``camera_class`` (eval.camera_classes.camera_class of ``cfa`` and ``jpeg``: its section
    shift is the pose's, and a fit the card's noise does not explain may pass at the class's,
    eval.fit_gate.class_test)."""
    h, w = image.shape[:2]
    cls = camera_class(cfa, jpeg)
    frame = Frame(index, path, {}, image, principal_point=((w - 1) / 2.0, (h - 1) / 2.0))
    t0 = time.perf_counter()
    frame.detections = detect_in(detector, image, roi, cfa, jpeg)
    t1 = time.perf_counter()
    centres = detection_arrays(frame.detections, min_score)
    if len(centres[0]) == 0:
        why = f"{NO_MARKERS} (none scoring {min_score:g} or more of {len(frame.detections)})"
        frame.record = {"ok": False, "category": NO_MARKERS, "reason": f"{path}: {why}"}
    elif calibration is not None:
        frame.record, frame.used_points = calibrated_solve(detector, markers, path, (w, h), centres, calibration, cls)
    else:
        frame.record, frame.used_points = solve_frame(
            markers, frame.principal_point, centres, None, camera_model,
            class_docking_options(detector, lens, cls), CAMERA_CLASS_FACTORS[cls])
    if frame.record["ok"]:
        frame.record.setdefault("camera_model", "pinhole")
    frame.record["camera_class"] = cls
    t2 = time.perf_counter()
    frame.record["image_size"] = [w, h]
    frame.record["timing_ms"] = {"detect": round(1000 * (t1 - t0), 2), "solve": round(1000 * (t2 - t1), 2)}
    return frame


def class_docking_options(detector, lens, cls: str):
    """The solver's options for an image of camera class ``cls`` (eval.camera_classes) seen
    through ``detector`` (its noise card's figures: the floor, the section shift and the noise
    prior, each the class's) and the lens prior ``lens``."""
    options = docking_options(detector.centre_noise_px, lens, class_section_shift(cls, detector.section_shift_px),
                              detector.noise_core_px)
    return with_class_prior(options, CAMERA_CLASS_FACTORS[cls])


def calibrated_solve(detector, markers, path: Path, size: tuple, centres, cal: Calibration,
                     camera: str = "three-chip"):
    """(record, used points) of one image of a calibrated camera: its centres (and
    boxes) taken to the ideal square-pixel pinhole camera (core.calibration_files.ideal_pixels),
    solved with the calibration's principal point, the lens known (nothing marginalised) and the
    pinhole model (the file's stated uncertainty marginalised: :func:`calibration_lens`); the focal
    is solved and the record's ``calibration`` gives the calibrated one; ``camera`` the frame's
    camera class (eval.camera_classes: its section shift and its factor for the gate).
    An image of another size than the calibration's is not ok (category "calibration size")."""
    if tuple(size) != (cal.width, cal.height):
        why = f"{path}: the image is {size[0]}x{size[1]}, the calibration is for {cal.width}x{cal.height}"
        return {"ok": False, "category": "calibration size", "reason": why}, {}
    cls, uv, boxes, refined = centres
    ideal, focal = ideal_pixels(cal, uv)
    if boxes is not None:
        lo, hi = ideal_pixels(cal, boxes[:, :2])[0], ideal_pixels(cal, boxes[:, 2:])[0]
        boxes = np.column_stack([np.minimum(lo, hi), np.maximum(lo, hi)])
    options = class_docking_options(detector, calibration_lens(cal), camera)
    record, used = solve_frame(markers, (cal.cx, cal.cy), (cls, ideal, boxes, refined), None,
                               "pinhole", options, CAMERA_CLASS_FACTORS[camera])
    record["calibration"] = {"focal_px": focal, "fx": cal.fx, "fy": cal.fy, "principal_point": [cal.cx, cal.cy],
                             "distortion": list(cal.dist),
                             **({"std": list(cal.std)} if cal.std is not None else {})}
    return record, used


def self_calibrate_sequence(frames: list[Frame], markers, camera_model: str, sigma_floor_px=None,
                            lens: LensPrior | None = None, section_shift_px=None) -> dict:
    """Solve the identified frames jointly (one camera unit); their records are replaced by the
    joint ones (``sigma_floor_px``, ``section_shift_px``: the weights' noise card), each keeping
    what dockfactory.measure.selfcal.kept_from_frame keeps (its size, timings with the joint
    solve's share added, ``notes`` and ``camera_class``, whose factor the run gate takes: the
    largest of the frames', eval.camera_classes.classes_factor). Returns the run's record
    (shared intrinsics or the reason it failed)."""
    solved = [f for f in frames if f.record["ok"]]
    if not solved:
        return {"ok": False, "reason": "no frame was identified", "frames": 0}
    sizes = {tuple(f.record["image_size"]) for f in solved}
    if len(sizes) > 1:
        raise DockfactoryError(f"--self-calibrate sequence: the images are one camera's, but their sizes differ "
                               f"({', '.join(f'{w}x{h}' for w, h in sorted(sizes))})")
    t0 = time.perf_counter()
    keys = [str(f.index) for f in solved]
    classes = {str(f.index): f.record.get("camera_class", "three-chip") for f in solved}
    records = solve_run(markers, solved[0].principal_point, keys, {str(f.index): f.record for f in solved},
                        {str(f.index): f.used_points for f in solved}, None, camera_model,
                        docking_options(sigma_floor_px, lens, section_shift_px), classes_factor(classes.values()))
    name_camera_classes(records, classes)
    ms = 1000 * (time.perf_counter() - t0) / len(solved)
    for f in solved:
        timing = {**f.record["timing_ms"], "solve": round(f.record["timing_ms"]["solve"] + ms, 2)}
        f.record = {**records[str(f.index)], **kept_from_frame(f.record), "timing_ms": timing}
    first = records[keys[0]]
    if not first["ok"]:
        return {"ok": False, "reason": first["reason"], "category": first["category"], "frames": len(solved)}
    return {"ok": True, "frames": len(solved), "camera_model": first["camera_model"], "focal_px": first["focal_px"],
            "intrinsics": first["intrinsics"], "intrinsics_std": first["intrinsics_std"]}


CSV_FIELDS = (["image", "ok", "category", "reason", "conformity"] + list(POSE_NAMES)
              + [f"{p}_{n}" for p in ("std", "u", "U") for n in POSE_NAMES]
              + [f"conformity_{n}" for n in POSE_NAMES]
              + ["focal_px", "camera_model", "cx", "cy", "k1", "k2", "p1", "p2", "rmse_px_a", "rmse_px_b",
                 "n_detections", "detect_ms", "solve_ms"])


CSV_DECIMALS = {"mm": 4, "deg": 5, "px": 3, "ms": 1}   # 0.1 um, 0.01 mdeg, 0.001 px: below any noise


def _csv_value(name: str, value):
    """A CSV cell at a sensible precision: mm 4 decimals, deg 5, px and intrinsics 3 (k, p: 6
    significant digits), milliseconds 1; text and counts as they are."""
    if isinstance(value, bool) or not isinstance(value, float):
        return value
    for unit, decimals in CSV_DECIMALS.items():
        if name.endswith(unit) or name in ("cx", "cy") and unit == "px":
            return f"{value:.{decimals}f}"
    return f"{value:.6g}"


def _uncertainty_cells(r: dict) -> dict:
    """The CSV cells of a record's budget (u_*: combined standard uncertainty, U_*: expanded,
    k = 2) and conformity decisions (the image's and each gated component's)."""
    row = {}
    budget = r.get("uncertainty") or {}
    if budget and "error" not in budget:
        row.update({f"u_{n}": budget[n]["combined"] for n in POSE_NAMES})
        row.update({f"U_{n}": budget[n]["expanded"] for n in POSE_NAMES})
    conf = r.get("conformity")
    if conf is not None:
        row["conformity"] = conf["decision"]
        row.update({f"conformity_{n}": c["decision"] for n, c in conf["components"].items()})
    return row


def csv_text(frames: list[Frame]) -> str:
    """measurements.csv: one row per image (pose, its 1-sigma standard deviations std_*, the
    budget's combined u_* and expanded U_* (k = 2), conformity decisions with an acceptance spec,
    intrinsics, reprojection RMS, timings), numbers at the precision of :data:`CSV_DECIMALS`."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, CSV_FIELDS, lineterminator="\n")
    w.writeheader()
    for f in frames:
        r = f.record
        row = {"image": str(f.path), "ok": r["ok"], "category": r.get("category", ""), "reason": r.get("reason", "")}
        if r["ok"]:
            std = np.sqrt(np.diag(np.array(r["covariance"])))
            row.update({n: r["pose"][n] for n in POSE_NAMES})
            row.update({f"std_{n}": float(s) for n, s in zip(POSE_NAMES, std)})
            row.update(focal_px=r["focal_px"], camera_model=r["camera_model"], rmse_px_a=r["rmse_px"]["A"],
                       rmse_px_b=r["rmse_px"]["B"], n_detections=r["n_detections"])
            row.update({k: v for k, v in r.get("intrinsics", {}).items() if k in CSV_FIELDS})
        row.update(_uncertainty_cells(r))
        if "timing_ms" in r:
            row.update(detect_ms=r["timing_ms"]["detect"], solve_ms=r["timing_ms"]["solve"])
        w.writerow({k: _csv_value(k, v) for k, v in row.items()})
    return buf.getvalue()


def overlay_path(out: Path, frame: Frame) -> Path:
    return out / "overlays" / f"{frame.index:05d}_{frame.path.stem}.png"


@dataclass(frozen=True)
class MeasureOptions:
    """How measure runs: the detector's network ``backend`` (auto, torch or onnx), the frames in
    flight at once (``workers``, at most ``MAX_WORKERS`` and never more than the images to
    measure: each a process reading, detecting, solving and drawing one image), the overlays'
    ``overlay_size`` (a fraction of the image's resolution; None: no overlays) and the largest
    image measured, ``max_megapixels`` by its header (a larger one is refused undecoded)."""
    backend: str = "auto"
    workers: int = 2
    overlay_size: float | None = 0.5
    camera: CameraInput = CameraInput()
    max_megapixels: float = DEFAULT_MAX_MEGAPIXELS

    def __post_init__(self):
        if self.backend not in ("auto", "torch", "onnx"):
            raise DockfactoryError(f"backend must be auto, torch or onnx, got {self.backend!r}")
        if not 1 <= self.workers <= MAX_WORKERS:
            raise DockfactoryError(f"workers must be in [1, {MAX_WORKERS}], got {self.workers}")
        if self.overlay_size is not None and not 0.1 <= self.overlay_size <= 1:
            raise DockfactoryError(f"overlay size must be in [0.1, 1], got {self.overlay_size}")
        if not 0 < self.max_megapixels <= MAX_MEGAPIXELS:
            raise DockfactoryError(f"--max-megapixels: must be in (0, {MAX_MEGAPIXELS:g}], got {self.max_megapixels}")

    @property
    def max_pixels(self) -> int:
        return max_pixels_of(self.max_megapixels)


def measure_and_draw(detector, markers, i: int, path: Path, model: str, min_score: float, out: Path,
                     size: float | None, camera: CameraInput = CameraInput(),
                     max_pixels: int = DEFAULT_MAX_PIXELS) -> Frame:
    """Read, detect, solve and (with ``size``) draw one image; the image is not kept. An error on
    the way becomes the image's failure record ("measure error", with the exception's words); an
    OSError writing its overlay (a full disk, a read-only folder) is a "write error", which a
    rerun measures again (dockfactory.measure.store.RETRIED): the image is fine, the disk was not."""
    try:
        frame = measure_frame(detector, markers, i, path, model, min_score, camera, max_pixels)
        if size is not None and frame.image is not None:
            try:
                draw_measurement(frame.image, frame.detections, frame.record, markers, overlay_path(out, frame), size)
            except OSError as exc:
                return Frame(i, path, {"ok": False, "category": WRITE_ERROR, "reason": f"{path}: {_words(exc)}"})
    except Exception as exc:   # noqa: BLE001 -- one image's failure is recorded, the batch goes on
        return Frame(i, path, {"ok": False, "category": "measure error", "reason": f"{path}: {_words(exc)}"})
    frame.image = None
    return frame


def _words(exc: BaseException) -> str:
    """``Type: message`` of an exception on one line, at most 300 characters of message."""
    return f"{type(exc).__name__}: {' '.join(str(exc).split())[:300] or 'no message'}"


def measure_all(weights, markers, jobs, model: str, min_score: float, out: Path, size: float | None,
                options: MeasureOptions, on_done) -> tuple[float, int]:
    """Measure every job ``(index, path)``: in this process with one worker (or one job), else by
    worker processes (dockfactory.measure.pool, at most one per job). ``on_done(job, frame, error)`` is
    called as each finishes. Returns the wall time after the detector(s) were loaded and the
    number of workers used."""
    workers = max(1, min(options.workers, len(jobs)))
    if workers == 1:
        from dockfactory.detector.infer import MarkerDetector
        detector = MarkerDetector(weights, conf_threshold=min_score, backend=options.backend)
        t0 = time.perf_counter()
        for i, p in jobs:
            on_done((i, p), measure_and_draw(detector, markers, i, p, model, min_score, out, size, options.camera,
                                             options.max_pixels), None)
        return time.perf_counter() - t0, workers
    from dockfactory.detector.checkpoint import load_model
    load_model(weights, fuse=False)   # a bad weights file is named here, not in every worker
    with MeasurePool(measure_and_draw, workers, weights, min_score, options.backend, markers, model, out, size,
                     options.camera, options.max_pixels) as pool:
        t0 = time.perf_counter()
        pool.run(jobs, on_done)
        return time.perf_counter() - t0, workers


def draw_overlays(frames: list[Frame], markers, out: Path, size: float, camera: CameraInput = CameraInput(),
                  max_pixels: int = DEFAULT_MAX_PIXELS) -> None:
    """The overlays of frames whose records changed after they were measured (a docking run's
    joint solve): each image is read again rather than kept in memory."""
    for f in frames:
        image, failed = read_image(f.path, camera, max_pixels)
        if failed is None:
            draw_measurement(image, f.detections, f.record, markers, overlay_path(out, f), size)


def write_records(out: Path, frames: list[Frame], header: dict) -> None:
    """measurements.json and measurements.csv (each written atomically)."""
    records = [{"image": str(f.path), **f.record} for f in frames]
    write_json_atomic(out / "measurements.json", {**header, "images": records}, indent=None)
    # a file name that is not UTF-8 (surrogate escapes) is written as \udcff rather than refused
    write_bytes_atomic(out / "measurements.csv", csv_text(frames).encode("utf-8", "backslashreplace"))


def check_one_size(paths, probes) -> None:
    """--self-calibrate sequence: the images (by their headers) must share one size; one line
    naming the sizes and an image of each otherwise."""
    sizes: dict = {}
    for p, (header, _) in zip(paths, probes):
        if header is not None:
            sizes.setdefault((header[1], header[2]), p)
    if len(sizes) > 1:
        raise DockfactoryError("--self-calibrate sequence: the images are one camera's, but their sizes differ ("
                               + ", ".join(f"{w}x{h} e.g. {p}" for (w, h), p in sorted(sizes.items())) + ")")


def _entry(frame: Frame) -> dict:
    return {"record": frame.record, "detections": frame.detections, "principal_point": list(frame.principal_point),
            "used_points": [[mid, *uv] for mid, uv in frame.used_points.items()]}


def _frame(index: int, path: Path, entry: dict) -> Frame:
    return Frame(index, path, entry["record"], detections=entry["detections"],
                 principal_point=tuple(entry["principal_point"]),
                 used_points={mid: (u, v) for mid, u, v in entry["used_points"]})


def _died(path: Path, error: BaseException) -> dict:
    category = "worker died" if type(error).__name__ == "WorkerDied" else "measure error"
    return {"ok": False, "category": category, "reason": f"{path}: {' '.join(str(error).split())[:300]}"}


def _made_with(paths, layout_path, weights, model, self_calibrate, min_score, options, card) -> dict:
    """What the results depend on (the run's key in dockfactory.measure.store); not the worker count."""
    from dockfactory.detector.onnx_runtime import resolve_backend
    return {"dockfactory": package_version("dockfactory"), "images": [image_identity(p) for p in paths],
            "layout_sha256": sha256_file(layout_path), "weights_sha256": sha256_file(weights),
            "camera_model": model, "self_calibrate": self_calibrate, "min_score": min_score,
            "backend": resolve_backend(options.backend), "overlay_size": options.overlay_size,
            "max_pixels": options.max_pixels, "camera": asdict(options.camera), "sigma_floor_px": card.centre_noise_px,
            "section_shift_px": card.section_shift_px and list(card.section_shift_px)}


def measure(images, layout_path, weights, out, camera_model: str | None = None,
            self_calibrate: str | None = None, min_score: float = MIN_SCORE, progress=None,
            options: MeasureOptions = MeasureOptions(), acceptance=None) -> dict:
    """Measure the pose of B in A on every image (the pipeline: the module docstring).

    Parameters
    ----------
    images : sequence of paths
        PNG/JPEG/TIFF/BMP files or folders of them.
    layout_path, weights : path, path
        The marker layout file (its sigmas, when given, feed the uncertainty budget) and the detector's weights
        (their noise card: the centre-noise floor, section shift and bias).
    out : path
        The output folder, held under its writer lock for the whole run; a rerun with the same images and options
        measures only what is missing.
    camera_model, self_calibrate : str or None, {None, "frame", "sequence"}
        A solver camera model or "auto" (default: "auto" when self-calibrating, else "pinhole"); "sequence" solves
        the images as one docking run of one camera with shared intrinsics (their sizes must agree).
    min_score : float
        The detection score threshold.
    progress : callable(done, total) or None
        Called after each image.
    options : MeasureOptions
        Backend, workers, overlay size, camera input, largest image (megapixels).
    acceptance : path or None
        An acceptance spec: adds the conformity decisions (dockfactory.measure.verdict; the summary's ``conformity``).

    Returns
    -------
    dict
        The summary written to OUT/measurements.json (without the per-image records). ``frames_per_s`` counts the
        images measured by this run over everything after the detector is loaded: reading, detection, solve,
        overlays. Every pose gets its uncertainty budget.

    Raises
    ------
    DockfactoryError
        One line, before anything is measured: an empty image path, a folder without images, a bad camera model or
        ``self_calibrate``, sizes that differ under "sequence", a bad layout file or acceptance spec, a busy OUT.
    """
    return _measure(images, layout_path, weights, out, camera_model, self_calibrate, min_score, progress, options,
                    acceptance)


def _measure(images, layout_path, weights, out, camera_model, self_calibrate, min_score, progress,
             options: MeasureOptions, acceptance) -> dict:
    """:func:`measure`'s work."""
    paths = collect_images(images)
    markers, sigmas = read_layout_file(layout_path), read_layout_sigmas(layout_path)
    spec = _spec(acceptance)
    model = resolve_camera_model(camera_model, self_calibrate)
    sequence = self_calibrate == "sequence"
    with writer_lock(out, "measure") as out:
        probes = [probe_image(p, options.max_pixels) for p in paths]
        if sequence:
            check_one_size(paths, probes)
        card = card_figures(weights)   # hashes the weights: once
        store = MeasureStore(out, _made_with(paths, layout_path, weights, model, self_calibrate, min_score, options,
                                             card))
        frames = {i: _frame(i, paths[i], e) for i, e in store.open(paths).items()}
        resumed = len(frames)
        frames.update({i: Frame(i, p, probe[1]) for i, (p, probe) in enumerate(zip(paths, probes))
                       if probe[1] is not None})
        jobs = [(i, p) for i, p in enumerate(paths) if i not in frames]
        wall, workers = _measure_jobs(weights, markers, jobs, "pinhole" if sequence else model, min_score, out,
                                      options, store, frames, lambda: progress and progress(len(frames), len(paths)),
                                      sequence)
        frames = [frames[i] for i in range(len(paths))]
        run, seconds = _run_of(frames, markers, model, card, out, options) if sequence else (None, 0.0)
        header = _header(paths, frames, layout_path, weights, model, self_calibrate, min_score, wall + seconds, run,
                         len(jobs))
        header.update(backend=store.made_with["backend"], workers=workers, overlay_size=options.overlay_size,
                      sigma_floor_px=card.centre_noise_px,
                      section_shift_px=card.section_shift_px and list(card.section_shift_px),
                      camera=asdict(options.camera), max_megapixels=options.max_megapixels,
                      resumed=resumed, earlier_run_discarded=store.discarded,
                      **_assess(frames, markers, sigmas, card.bias_px, spec, acceptance))
        if spec is not None and options.overlay_size is not None:   # the overlays show each decision and U
            draw_overlays(frames, markers, out, options.overlay_size, options.camera, options.max_pixels)
        write_records(out, frames, header)
    return header


def _spec(acceptance):
    """The acceptance spec of ``acceptance`` (a path) checked for a single pose's tolerances, or
    None (bad input is a one-line DockfactoryError before anything is measured)."""
    if acceptance is None:
        return None
    spec = load_acceptance(acceptance)
    pose_tolerances(spec, str(acceptance))
    return spec


def _assess(frames: list[Frame], markers, sigmas, bias, spec, acceptance) -> dict:
    """Every record's uncertainty budget (``bias``: the detector's measured centre offset, px, or
    None) and, with a spec, its conformity; the header's keys."""
    records = [f.record for f in frames]
    add_uncertainty(records, markers, sigmas, bias)
    extra = {"uncertainty": {"k": COVERAGE_K, "layout_sigma_mm": None if sigmas is None else
                             {"min": min(sigmas.values()), "max": max(sigmas.values())},
                             "detector_bias_px": None if bias is None else list(bias), "terms": list(TERMS)}}
    if spec is not None:
        extra["conformity"] = add_conformity(records, spec, str(acceptance))
    return extra


def _frames_section_shift(frames: list[Frame], card_shift_px) -> tuple[float, float] | None:
    """The section shift of a run of ``frames``: per axis the largest of their camera classes'
    (eval.camera_classes.classes_section_shift); None when none has one."""
    return classes_section_shift([f.record.get("camera_class", "three-chip") for f in frames], card_shift_px)


def _run_of(frames: list[Frame], markers, model, card, out, options) -> tuple[dict, float]:
    """--self-calibrate sequence: the joint solve of the identified frames and their overlays
    (the run's record with its warnings; the seconds it took); ``card`` the weights' noise card
    (detector.noise_card.CardFigures)."""
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:   # kept with the run, not printed
        warnings.simplefilter("always")
        run = self_calibrate_sequence(frames, markers, model, card.centre_noise_px, options.camera.lens,
                                      _frames_section_shift(frames, card.section_shift_px))
    if caught:
        run["notes"] = sorted({f"{w.category.__name__}: {w.message}" for w in caught})[:20]
    if options.overlay_size is not None:
        draw_overlays(frames, markers, out, options.overlay_size, options.camera, options.max_pixels)
    return run, time.perf_counter() - t0


def _measure_jobs(weights, markers, jobs, model, min_score, out, options, store, frames, tick, sequence):
    """Measure ``jobs`` into ``frames`` (index -> Frame), saving each entry as it finishes."""
    def on_done(job, frame, error):
        index, path = job
        frame = frame if error is None else Frame(index, path, _died(path, error))
        frames[index] = frame
        store.save(index, path, _entry(frame))
        tick()
    tick()
    if not jobs:
        return 0.0, 0
    return measure_all(weights, markers, jobs, model, min_score, out, None if sequence else options.overlay_size,
                       options, on_done)


def _header(paths, frames, layout_path, weights, model, self_calibrate, min_score, wall, run, measured) -> dict:
    n_ok = sum(f.record["ok"] for f in frames)
    return {"format": MEASURE_FORMAT, "layout": str(layout_path), "layout_sha256": sha256_file(layout_path),
            "weights": str(weights), "weights_sha256": sha256_file(weights), "camera_model": model,
            "self_calibrate": self_calibrate, "min_score": min_score,
            "pixel_convention": "opencv: (0,0) is the centre of the top-left pixel",
            "principal_point": "each image's centre ((W - 1) / 2, (H - 1) / 2), the start of an estimated one",
            "images_total": len(paths), "images_with_pose": n_ok, "images_measured": measured,
            "failures": {c: sum(f.record.get("category") == c for f in frames if not f.record["ok"])
                         for c in sorted({f.record.get("category") for f in frames if not f.record["ok"]})},
            "sequence": run, "wall_s": round(wall, 3), "frames_per_s": round(measured / max(wall, 1e-9), 2)}
