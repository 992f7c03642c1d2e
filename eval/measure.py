"""``dockfactory measure``: the pose of B in A from real images, without labels.

PNG/JPEG images (files or folders) -> detector -> identification -> solve (the chosen camera
model, per frame, or self-calibrated over the whole set as one docking run of one camera) ->
OUT/measurements.json, OUT/measurements.csv and one overlay PNG per image in OUT/overlays/.

Every image given gets a record: a file that is missing or unreadable, or a frame without a pose,
is reported with its reason and category, never dropped; the exit status is 1 when any image has
no pose. The principal point assumed (and the start of an estimated one) is each image's centre.
With ``--self-calibrate sequence`` the images are one camera unit (one docking run: the camera,
its zoom and A fixed, B moving): each frame is identified on its own, then every identified frame
is solved jointly with shared intrinsics (solver.solve_sequence).
"""
from __future__ import annotations

import csv
import io
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np

from dockfactory.core.camera_chain import develop_raw
from dockfactory.core.cfa import PATTERNS
from dockfactory.core.demosaic import DEMOSAICS
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.io import folder_lock, sha256_file, write_json_atomic, write_text_atomic
from dockfactory.core.layout_file import read_layout_file
from dockfactory.core.names import MIN_SCORE, POSE_NAMES
from dockfactory.detector.noise_card import centre_noise_px
from dockfactory.eval.measure_overlay import draw_measurement
from dockfactory.eval.measure_pool import MeasurePool
from dockfactory.eval.solve_frames import (
    detection_arrays,
    docking_options,
    resolve_camera_model,
    solve_frame,
    solve_run,
)

MEASURE_FORMAT = "dockfactory.measure/1"
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")   # a one-channel 16-bit PNG is a raw frame


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
    """The images named by ``items`` (files, or folders whose PNG/JPEG files are taken in name
    order), each once; a path that does not exist stays in the list (reported per image)."""
    out, seen = [], set()
    for item in map(Path, items):
        if item.is_dir():
            found = sorted(p for p in item.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())
            if not found:
                raise DockfactoryError(f"{item}: no PNG or JPEG images in this folder")
        else:
            found = [item]
        for p in found:
            key = p.resolve()
            if key not in seen:
                seen.add(key)
                out.append(p)
    if not out:
        raise DockfactoryError("measure: no images given")
    return out


@dataclass(frozen=True)
class CameraInput:
    """What the user knows of the camera behind the images. ``cfa``: its Bayer pattern (RGGB,
    BGGR, GRBG, GBRG; None: a three-chip camera or unknown): the centre refinement then fits the
    samples the sensor took, and raw frames can be read. A raw frame is a one-channel 16-bit PNG
    of the mosaic in DN (BayerRG12 and the like): ``raw_black_dn`` is subtracted, ``raw_white_dn`` is
    full scale (the sensor's white level: a 16-bit PNG does not say its ADC depth, and a level
    guessed from each frame's brightest pixel would develop a dark frame brighter; None: raw
    frames are refused), then grey-world white balance, ``demosaic`` and the sRGB curve."""
    cfa: str | None = None
    raw_black_dn: float = 0.0
    raw_white_dn: float | None = None
    demosaic: str = "mhc"

    def __post_init__(self):
        if self.cfa is not None and self.cfa not in PATTERNS:
            raise DockfactoryError(f"--cfa: expected one of {', '.join(PATTERNS)}, got {self.cfa!r}")
        if self.demosaic not in DEMOSAICS:
            raise DockfactoryError(f"--demosaic: expected one of {', '.join(DEMOSAICS)}, got {self.demosaic!r}")
        if not (np.isfinite(self.raw_black_dn) and 0 <= self.raw_black_dn < 65535):
            raise DockfactoryError(f"--raw-black: expected a level in [0, 65535) DN, got {self.raw_black_dn}")
        if self.raw_white_dn is not None and not (np.isfinite(self.raw_white_dn)
                                                  and self.raw_black_dn < self.raw_white_dn <= 65535):
            raise DockfactoryError(f"--raw-white: expected a level above --raw-black and at most 65535 DN, "
                                   f"got {self.raw_white_dn}")

    def develop(self, raw: np.ndarray) -> np.ndarray:
        """A raw frame (H, W) uint16 as 8-bit sRGB (core.camera_chain.develop_raw)."""
        return develop_raw(raw, self.cfa, self.raw_black_dn, self.raw_white_dn, self.demosaic)


def _unreadable(path: Path, why: str) -> tuple[None, dict]:
    return None, {"ok": False, "reason": f"{path}: {why}", "category": "unreadable image"}


def read_image(path: Path, camera: CameraInput = CameraInput()) -> tuple[np.ndarray | None, dict | None]:
    """(RGB image, None) or (None, failure record) for a missing or unreadable file. A one-channel
    16-bit PNG is a raw frame: developed with ``camera`` (its Bayer pattern is needed)."""
    if not path.is_file():
        return _unreadable(path, "no such image file")
    data = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if data is None:
        return _unreadable(path, "not a readable PNG or JPEG image")
    if data.ndim == 2 and data.dtype == np.uint16:
        if camera.cfa is None:
            return _unreadable(path, "a raw frame (one 16-bit channel): give its Bayer pattern with --cfa")
        if camera.raw_white_dn is None:
            return _unreadable(path, "a raw frame: give the sensor's white level with --raw-white "
                                     "(e.g. 4095 for 12 bit)")
        if data.shape[0] % 2 or data.shape[1] % 2 or min(data.shape) < 4:
            return _unreadable(path, f"a raw frame must have an even size of at least 4x4, got {data.shape[1]}x{data.shape[0]}")
        return camera.develop(data), None
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        return _unreadable(path, "not a readable PNG or JPEG image")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), None


def measure_frame(detector, markers, index: int, path: Path, camera_model: str, min_score: float,
                  camera: CameraInput = CameraInput()) -> Frame:
    """Read, detect and solve one image (its own camera model fit)."""
    image, failed = read_image(path, camera)
    if failed is not None:
        return Frame(index, path, failed)
    h, w = image.shape[:2]
    frame = Frame(index, path, {}, image, principal_point=((w - 1) / 2.0, (h - 1) / 2.0))
    t0 = time.perf_counter()
    frame.detections = detector.detect(image, cfa=camera.cfa, jpeg=path.suffix.lower() in (".jpg", ".jpeg"))
    t1 = time.perf_counter()
    frame.record, frame.used_points = solve_frame(markers, frame.principal_point,
                                                  detection_arrays(frame.detections, min_score), None, camera_model,
                                                  docking_options(detector.centre_noise_px))
    if frame.record["ok"]:
        frame.record.setdefault("camera_model", "pinhole")
    t2 = time.perf_counter()
    frame.record["image_size"] = [w, h]
    frame.record["timing_ms"] = {"detect": round(1000 * (t1 - t0), 2), "solve": round(1000 * (t2 - t1), 2)}
    return frame


def self_calibrate_sequence(frames: list[Frame], markers, camera_model: str, sigma_floor_px=None) -> dict:
    """Solve the identified frames jointly (one camera unit); their records are replaced by the
    joint ones. Returns the run's record (shared intrinsics or the reason it failed)."""
    solved = [f for f in frames if f.record["ok"]]
    if not solved:
        return {"ok": False, "reason": "no frame was identified", "frames": 0}
    sizes = {tuple(f.record["image_size"]) for f in solved}
    if len(sizes) > 1:
        raise DockfactoryError(f"--self-calibrate sequence: the images are one camera's, but their sizes differ "
                               f"({', '.join(f'{w}x{h}' for w, h in sorted(sizes))})")
    t0 = time.perf_counter()
    keys = [str(f.index) for f in solved]
    records = solve_run(markers, solved[0].principal_point, keys, {str(f.index): f.record for f in solved},
                        {str(f.index): f.used_points for f in solved}, None, camera_model,
                        docking_options(sigma_floor_px))
    ms = 1000 * (time.perf_counter() - t0) / len(solved)
    for f in solved:
        timing = {**f.record["timing_ms"], "solve": round(f.record["timing_ms"]["solve"] + ms, 2)}
        f.record = {**records[str(f.index)], "image_size": f.record["image_size"], "timing_ms": timing}
    first = records[keys[0]]
    if not first["ok"]:
        return {"ok": False, "reason": first["reason"], "category": first["category"], "frames": len(solved)}
    return {"ok": True, "frames": len(solved), "camera_model": first["camera_model"], "focal_px": first["focal_px"],
            "intrinsics": first["intrinsics"], "intrinsics_std": first["intrinsics_std"]}


CSV_FIELDS = (["image", "ok", "category", "reason"] + list(POSE_NAMES) + [f"std_{n}" for n in POSE_NAMES]
              + ["focal_px", "camera_model", "cx", "cy", "k1", "k2", "p1", "p2", "rmse_px_a", "rmse_px_b",
                 "n_detections", "detect_ms", "solve_ms"])


def csv_text(frames: list[Frame]) -> str:
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
        if "timing_ms" in r:
            row.update(detect_ms=r["timing_ms"]["detect"], solve_ms=r["timing_ms"]["solve"])
        w.writerow(row)
    return buf.getvalue()


def overlay_path(out: Path, frame: Frame) -> Path:
    return out / "overlays" / f"{frame.index:05d}_{frame.path.stem}.png"


@dataclass(frozen=True)
class MeasureOptions:
    """How measure runs: the detector's network ``backend`` (auto, torch or onnx), the frames in
    flight at once (``workers``: each one thread reading, detecting, solving and drawing one image)
    and the overlays' ``overlay_size`` (a fraction of the image's resolution; None: no overlays)."""
    backend: str = "auto"
    workers: int = 2
    overlay_size: float | None = 0.5
    camera: CameraInput = CameraInput()

    def __post_init__(self):
        if self.backend not in ("auto", "torch", "onnx"):
            raise DockfactoryError(f"backend must be auto, torch or onnx, got {self.backend!r}")
        if not 1 <= self.workers <= 16:
            raise DockfactoryError(f"workers must be in [1, 16], got {self.workers}")
        if self.overlay_size is not None and not 0.1 <= self.overlay_size <= 1:
            raise DockfactoryError(f"overlay size must be in [0.1, 1], got {self.overlay_size}")


def measure_and_draw(detector, markers, i: int, path: Path, model: str, min_score: float, out: Path,
                     size: float | None, camera: CameraInput = CameraInput()) -> Frame:
    """Read, detect, solve and (with ``size``) draw one image; the image is not kept."""
    frame = measure_frame(detector, markers, i, path, model, min_score, camera)
    if size is not None and frame.image is not None:
        draw_measurement(frame.image, frame.detections, frame.record, markers, overlay_path(out, frame), size)
    frame.image = None
    return frame


def measure_all(weights, markers, paths, model: str, min_score: float, out: Path, size: float | None,
                options: MeasureOptions, progress=None) -> tuple[list[Frame], float]:
    """Every image measured, in input order: in this process with one worker, else by worker
    processes (eval.measure_pool). Returns the frames and the wall time after the detector(s)
    were loaded."""
    if options.workers == 1:
        from dockfactory.detector.infer import MarkerDetector
        detector = MarkerDetector(weights, conf_threshold=min_score, backend=options.backend)
        t0, frames = time.perf_counter(), []
        for i, p in enumerate(paths):
            frames.append(measure_and_draw(detector, markers, i, p, model, min_score, out, size, options.camera))
            if progress:
                progress(i + 1, len(paths))
        return frames, time.perf_counter() - t0
    from dockfactory.detector.checkpoint import load_model
    load_model(weights, fuse=False)   # a bad weights file is named here, not in every worker
    with MeasurePool(measure_and_draw, options.workers, weights, min_score, options.backend, markers, model, out, size,
                     options.camera) as pool:
        t0 = time.perf_counter()
        frames = pool.run(paths, progress)
        return frames, time.perf_counter() - t0


def draw_overlays(frames: list[Frame], markers, out: Path, size: float, camera: CameraInput = CameraInput()) -> None:
    """The overlays of frames whose records changed after they were measured (a docking run's
    joint solve): each image is read again rather than kept in memory."""
    for f in frames:
        image, failed = read_image(f.path, camera)
        if failed is None:
            draw_measurement(image, f.detections, f.record, markers, overlay_path(out, f), size)


def write_records(out: Path, frames: list[Frame], header: dict) -> None:
    """measurements.json and measurements.csv (each written atomically)."""
    records = [{"image": str(f.path), **f.record} for f in frames]
    write_json_atomic(out / "measurements.json", {**header, "images": records}, indent=None)
    write_text_atomic(out / "measurements.csv", csv_text(frames))


def measure(images, layout_path, weights, out, camera_model: str | None = None,
            self_calibrate: str | None = None, min_score: float = MIN_SCORE, progress=None,
            options: MeasureOptions = MeasureOptions()) -> dict:
    """Measure every image (see the module docstring); returns the summary written to
    OUT/measurements.json (without the per-image records). ``frames_per_s`` counts everything
    after the detector is loaded: reading, detection, solve, overlays."""
    from dockfactory.detector.onnx_runtime import resolve_backend
    paths = collect_images(images)
    markers = read_layout_file(layout_path)
    model = resolve_camera_model(camera_model, self_calibrate)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    sequence = self_calibrate == "sequence"
    floor = centre_noise_px(weights)   # hashes the weights: once
    with folder_lock(out, "measure"):
        # per frame the pinhole when the run fits the intrinsics
        frames, wall = measure_all(weights, markers, paths, "pinhole" if sequence else model, min_score, out,
                                   None if sequence else options.overlay_size, options, progress)
        run = None
        if sequence:
            t0 = time.perf_counter()
            run = self_calibrate_sequence(frames, markers, model, floor)
            if options.overlay_size is not None:
                draw_overlays(frames, markers, out, options.overlay_size, options.camera)
            wall += time.perf_counter() - t0
        header = _header(paths, frames, layout_path, weights, model, self_calibrate, min_score, wall, run)
        header.update(backend=resolve_backend(options.backend), workers=options.workers,
                      overlay_size=options.overlay_size, sigma_floor_px=floor, camera=asdict(options.camera))
        write_records(out, frames, header)
    return header


def _header(paths, frames, layout_path, weights, model, self_calibrate, min_score, wall, run) -> dict:
    n_ok = sum(f.record["ok"] for f in frames)
    return {"format": MEASURE_FORMAT, "layout": str(layout_path), "layout_sha256": sha256_file(layout_path),
            "weights": str(weights), "weights_sha256": sha256_file(weights), "camera_model": model,
            "self_calibrate": self_calibrate, "min_score": min_score,
            "pixel_convention": "opencv: (0,0) is the centre of the top-left pixel",
            "principal_point": "each image's centre ((W - 1) / 2, (H - 1) / 2), the start of an estimated one",
            "images_total": len(paths), "images_with_pose": n_ok,
            "failures": {c: sum(f.record.get("category") == c for f in frames if not f.record["ok"])
                         for c in sorted({f.record.get("category") for f in frames if not f.record["ok"]})},
            "sequence": run, "wall_s": round(wall, 3), "frames_per_s": round(len(paths) / max(wall, 1e-9), 2)}
