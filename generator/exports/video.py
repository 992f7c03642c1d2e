"""Video export: each docking run of a dataset as one video, with its per-frame labels, so the stream
path of measure (``measure --video``) is tested on real video decoding against exact ground truth.

A run is the frames of one camera unit and one run of the labels (generator.docking_runs: the
camera and zoom fixed, B approaching A); repeatability captures (run -1) are not runs and are left
out. A dataset without docking runs ([runs] frames_per_run = 0) is refused (DatasetError): its
frames share no camera, so they are no video. The run's time is not simulated: frames are spaced
1 / VIDEO_FPS s apart. Needs OpenCV's FFmpeg video I/O (opencv-python-headless ships it): a codec
it cannot open is a DatasetError naming it.

Why and how: docs/datasets.md, "The video export's files".
"""
from __future__ import annotations

import json
from pathlib import Path

from dockfactory.core.cv import cv2

from dockfactory.core.io import write_json_atomic
from dockfactory.generator.datasets.folder import DatasetError
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.exports.files import source_image
from dockfactory.generator.exports.registry import ExportFormat

VIDEO_FPS = 10.0
CODECS = {"video": ("mp4v", ".mp4", True), "video_lossless": ("FFV1", ".mkv", False)}   # fourcc, suffix, lossy
VIDEO_FORMAT = "dockfactory.video_export/1"


def video_runs(ds: Dataset) -> list[list[str]]:
    """The frame ids of each docking run (unit, run) in run order; DatasetError without runs."""
    if ds.config.runs.frames_per_run == 0:
        raise DatasetError(f"{ds.root}: no docking runs ([runs] frames_per_run = 0): a video export needs runs")
    groups: dict = {}
    for fid in ds.frames():
        spec = ds.labels[fid]["spec"]
        if spec.get("run", -1) >= 0:
            groups.setdefault((spec.get("unit", 0), spec["run"]), []).append((spec["run_frame"], fid))
    return [[fid for _, fid in sorted(groups[k])] for k in sorted(groups)]


def frame_label(k: int, label: dict) -> dict:
    """The JSON line of video frame ``k`` from its dataset label (see the module docstring)."""
    spec, cam = label["spec"], label["camera"]
    return {"frame": k, "timestamp_ms": round(1000.0 * k / VIDEO_FPS, 3), "frame_id": label["frame_id"],
            "split": spec["split"], "condition": spec["condition"], "unit": spec.get("unit", 0), "run": spec["run"],
            "run_frame": spec["run_frame"], "pose": label["pose_b_in_d"], "d_from_b": label["d_from_b"],
            "focal_px": cam["focal_px"], "principal_point": cam["principal_point"],
            "distortion": cam.get("distortion") or [0.0] * 5,
            **_pixel_aspect(cam), "image_size": [label["image"]["width"], label["image"]["height"]]}


def _pixel_aspect(cam: dict) -> dict:
    """{"pixel_aspect": fy / fx} of a label's camera with non-square pixels, else {}."""
    (fx, _, _), (_, fy, _) = cam["K"][0], cam["K"][1]
    return {} if fy == fx else {"pixel_aspect": fy / fx}


def write_run_video(ds: Dataset, frame_ids: list[str], path: Path, fourcc: str) -> None:
    """The frames ``frame_ids`` (their PNGs, one size) as one video at ``path``."""
    w, h = ds.config.image.width, ds.config.image.height
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), VIDEO_FPS, (w, h))
    try:
        if not writer.isOpened():
            raise DatasetError(f"{path}: OpenCV cannot write {fourcc!r} video here (no such encoder in its FFmpeg)")
        for fid in frame_ids:
            bgr = cv2.imread(str(source_image(ds.root, fid)), cv2.IMREAD_COLOR)
            if bgr is None or bgr.shape[:2] != (h, w):
                raise DatasetError(f"{source_image(ds.root, fid)}: not a {w}x{h} colour image")
            writer.write(bgr)
    finally:
        writer.release()


def export_video_as(ds: Dataset, out, fmt: str) -> Path:
    """Write the video export ``fmt`` ("video" or "video_lossless") of ``ds`` into ``out``."""
    fourcc, suffix, lossy = CODECS[fmt]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    runs = []
    for frame_ids in video_runs(ds):
        first = ds.labels[frame_ids[0]]["spec"]
        stem = f"unit{first.get('unit', 0)}_run{first['run']:02d}"
        write_run_video(ds, frame_ids, out / f"{stem}{suffix}", fourcc)
        lines = [json.dumps(frame_label(k, ds.labels[fid])) for k, fid in enumerate(frame_ids)]
        (out / f"{stem}.jsonl").write_text("".join(f"{ln}\n" for ln in lines), encoding="utf-8")
        runs.append({"video": f"{stem}{suffix}", "labels": f"{stem}.jsonl", "unit": first.get("unit", 0),
                     "run": first["run"], "frames": len(frame_ids)})
    write_json_atomic(out / "videos.json", {"format": VIDEO_FORMAT, "dataset_version": ds.version_id,
                                            "codec": fourcc, "lossy": lossy, "fps": VIDEO_FPS,
                                            "pixel_convention": "opencv: (0,0) is the centre of the top-left pixel",
                                            "runs": runs})
    return out


def export_video(ds: Dataset, out) -> Path:
    """exports/video: MPEG-4 part 2 ('mp4v') in .mp4, lossy.

    Parameters
    ----------
    ds : Dataset
        The opened dataset (its frames in runs: a config with ``[runs]``).
    out : path
        The export's folder (created; files in it are replaced).

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    DatasetError
        When an image of the dataset is not a colour image of the dataset's size.
    """
    return export_video_as(ds, out, "video")


def export_video_lossless(ds: Dataset, out) -> Path:
    """exports/video_lossless: FFV1 in .mkv, the PNGs' pixels exactly.

    Parameters
    ----------
    ds : Dataset
        The opened dataset (its frames in runs: a config with ``[runs]``).
    out : path
        The export's folder (created; files in it are replaced).

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    DatasetError
        When an image of the dataset is not a colour image of the dataset's size.
    """
    return export_video_as(ds, out, "video_lossless")


FORMATS = (   # written by `dataset export` only: a dataset with [runs] has one video per docking run
    ExportFormat("video", export_video, "each docking run as an MP4 with its labels", on_demand=True),
    ExportFormat("video_lossless", export_video_lossless, "each docking run as FFV1 .mkv, the PNGs' pixels exactly",
                 on_demand=True),
)
