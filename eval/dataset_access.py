"""JSON files made for a dataset (poses, detections): read, matched to the dataset version, and
their shapes checked. The dataset itself is read through ``Dataset.open`` (generator.datasets.reader)."""
from __future__ import annotations

import json
import math
from pathlib import Path

from dockfactory.core.names import CLASS_NAMES, POSE_NAMES, SECTIONS
from dockfactory.generator.datasets.folder import DatasetError
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.solver.checks import MAX_SIGMA_PX
from dockfactory.core.user_files import check_regular_file


MAX_POSE_MM = 1.0e6      # 1 km: no docking pose or camera is further away
MAX_FOCAL_PX = 1.0e7


def read_json_for(path, what: str, dataset: Dataset) -> dict:
    """Load a JSON file made for ``dataset``; refuse one made for another dataset version and one
    of the wrong shape (``what``: "poses" or "detections"): a one-line DatasetError naming the
    file and the key."""
    path = Path(path)
    data = read_json_file(path, what)
    if not isinstance(data, dict):
        raise DatasetError(f"{path}: not a {what} file: expected a JSON object, got {json_kind(data)}")
    if "dataset_version" not in data:
        raise DatasetError(f"{path}: dataset_version: missing (not a dockfactory {what} file?)")
    version = data["dataset_version"]
    if version != dataset.version_id:
        raise DatasetError(f"{path}: {what} were made for dataset version {_short(version)}, but "
                           f"{dataset.root} is version {dataset.version_id}; refusing to mix them")
    if what == "poses":
        validate_poses(data, path)
    elif what == "detections":
        validate_detections(data, path)
    else:
        raise ValueError(f"unknown JSON kind {what!r}")   # programming error
    return data


def read_json_file(path, what: str):
    """The parsed JSON of ``path``; a DatasetError naming the file when it is missing, unreadable
    or not JSON."""
    path = Path(path)
    check_regular_file(path, what)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DatasetError(f"{path}: {what} file not found") from None
    except IsADirectoryError:
        raise DatasetError(f"{path}: {what} file is a directory") from None
    except OSError as exc:
        raise DatasetError(f"{path}: cannot read {what} file: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise DatasetError(f"{path}: {what} file is not UTF-8 text") from None
    except json.JSONDecodeError as exc:
        raise DatasetError(f"{path}: {what} file is not valid JSON ({exc})") from None
    except RecursionError:
        raise DatasetError(f"{path}: {what} file is nested too deeply") from None


# ----------------------------------------------------------------------------- JSON shapes
# Every check raises DatasetError("FILE: KEY: problem") in one line; KEY is a dotted path
# (frames.000001.pose.x_mm, frames.000001[3].center_px).

def json_kind(value) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, dict):
        return "an object"
    return type(value).__name__


def _short(value) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _bad(path, key: str, msg: str):
    raise DatasetError(f"{path}: {key}: {msg}")


def check_object(value, path, key: str) -> dict:
    if not isinstance(value, dict):
        _bad(path, key, f"expected an object, got {json_kind(value)}")
    return value


def check_list(value, path, key: str, length: int | None = None) -> list:
    if not isinstance(value, list):
        _bad(path, key, f"expected a list, got {json_kind(value)}")
    if length is not None and len(value) != length:
        _bad(path, key, f"expected {length} values, got {len(value)}")
    return value


def check_bool(value, path, key: str) -> bool:
    if not isinstance(value, bool):
        _bad(path, key, f"expected true or false, got {json_kind(value)} {_short(value)}")
    return value


def check_str(value, path, key: str) -> str:
    if not isinstance(value, str):
        _bad(path, key, f"expected a string, got {json_kind(value)}")
    return value


def check_int(value, path, key: str, lo: int | None = None, hi: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        _bad(path, key, f"expected an integer, got {json_kind(value)} {_short(value)}")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        _bad(path, key, f"must be in [{lo}, {hi}], got {value}")
    return value


def check_number(value, path, key: str, lo: float | None = None, hi: float | None = None,
                 positive: bool = False) -> float:
    """A finite JSON number (not a boolean) in [lo, hi] (> 0 with ``positive``)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        _bad(path, key, f"expected a number, got {json_kind(value)} {_short(value)}")
    if not math.isfinite(value):
        _bad(path, key, f"must be finite, got {value}")
    if positive and not value > 0:
        _bad(path, key, f"must be positive, got {value}")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        _bad(path, key, f"must be in [{lo}, {hi}], got {value}")
    return float(value)


def check_numbers(value, path, key: str, length: int) -> list:
    for i, v in enumerate(check_list(value, path, key, length)):
        check_number(v, path, f"{key}[{i}]")
    return value


def check_matrix(value, path, key: str, rows: int, cols: int, bound: float | None = None) -> list:
    """A ``rows`` x ``cols`` list of finite numbers, each within +-``bound`` when given."""
    for i, row in enumerate(check_list(value, path, key, rows)):
        for j, v in enumerate(check_numbers(row, path, f"{key}[{i}]", cols)):
            if bound is not None and abs(v) > bound:
                _bad(path, f"{key}[{i}][{j}]", f"must be within +-{bound:g}, got {v}")
    return value


def _frames(data: dict, path) -> dict:
    if "frames" not in data:
        _bad(path, "frames", "missing")
    frames = check_object(data["frames"], path, "frames")
    for fid in frames:
        if not fid:
            _bad(path, "frames", "an empty frame id")
    return frames


def validate_poses(data, path) -> dict:
    """Check the shape of a poses file (see dockfactory.eval.solve_frames): what evaluate and report
    read is present, typed (``ok`` a JSON boolean: ``"false"`` is refused, never taken as solved),
    finite and of a physical size (translations within MAX_POSE_MM, angles within 360 deg, focal
    lengths within MAX_FOCAL_PX: a 1e200 mm pose overflowed the report's statistics)."""
    check_object(data, path, "(top level)")
    if data.get("source") is not None:
        check_str(data["source"], path, "source")
    if data.get("oracle_sigma_px") is not None:
        check_number(data["oracle_sigma_px"], path, "oracle_sigma_px", lo=0.0)
    if data.get("principal_point") is not None:
        check_numbers(data["principal_point"], path, "principal_point", 2)
    for fid, rec in _frames(data, path).items():
        key = f"frames.{fid}"
        check_object(rec, path, key)
        if "ok" not in rec:
            _bad(path, f"{key}.ok", "missing")
        ok = check_bool(rec["ok"], path, f"{key}.ok")
        for k in ("reason", "category"):
            if rec.get(k) is not None:
                check_str(rec[k], path, f"{key}.{k}")
        if not ok:
            continue
        for k in ("pose", "focal_px", "rmse_px"):
            if k not in rec:
                _bad(path, f"{key}.{k}", "missing (ok is true)")
        pose = check_object(rec["pose"], path, f"{key}.pose")
        for name in POSE_NAMES:
            if name not in pose:
                _bad(path, f"{key}.pose.{name}", "missing")
            bound = MAX_POSE_MM if name.endswith("_mm") else 360.0
            check_number(pose[name], path, f"{key}.pose.{name}", -bound, bound)
        check_number(rec["focal_px"], path, f"{key}.focal_px", hi=MAX_FOCAL_PX, positive=True)
        if rec.get("covariance") is not None:
            check_matrix(rec["covariance"], path, f"{key}.covariance", 6, 6, MAX_POSE_MM ** 2)
        rmse = check_object(rec["rmse_px"], path, f"{key}.rmse_px")
        for s in SECTIONS:
            if s not in rmse:
                _bad(path, f"{key}.rmse_px.{s}", "missing")
            check_number(rmse[s], path, f"{key}.rmse_px.{s}", lo=0.0)
        for k in ("d_from_b", "cam_from_a"):
            if rec.get(k) is not None:
                check_matrix(rec[k], path, f"{key}.{k}", 4, 4, MAX_POSE_MM)
        if rec.get("marker_ids") is not None:
            for i, m in enumerate(check_list(rec["marker_ids"], path, f"{key}.marker_ids")):
                check_str(m, path, f"{key}.marker_ids[{i}]")
    return data


def validate_detections(data, path, required: tuple[str, ...] = ()) -> dict:
    """Check the shape of a detections file (dockfactory detect): frames -> list of detections,
    each with an integer ``class_id`` of a known class and a finite ``center_px``; ``score``,
    ``bbox_px`` and ``refined`` typed when present (and present when named in ``required``)."""
    check_object(data, path, "(top level)")
    if data.get("weights_sha256") is not None:   # the detector a report names (provenance)
        check_str(data["weights_sha256"], path, "weights_sha256")
    if data.get("centre_noise_px") is not None:   # the weights' noise card: the covariance floor
        check_number(data["centre_noise_px"], path, "centre_noise_px", hi=MAX_SIGMA_PX, positive=True)
    if data.get("centre_noise_core_px") is not None:   # the card's robust core: the noise prior
        check_number(data["centre_noise_core_px"], path, "centre_noise_core_px", hi=MAX_SIGMA_PX, positive=True)
    if data.get("section_shift_px") is not None:   # the card's common offset of a section's centres
        for a, v in enumerate(check_list(data["section_shift_px"], path, "section_shift_px", 2)):
            check_number(v, path, f"section_shift_px[{a}]", 0.0, MAX_SIGMA_PX)
    for fid, dets in _frames(data, path).items():
        key = f"frames.{fid}"
        for i, d in enumerate(check_list(dets, path, key)):
            k = f"{key}[{i}]"
            check_object(d, path, k)
            for name in ("class_id", "center_px") + tuple(required):
                if name not in d:
                    _bad(path, f"{k}.{name}", "missing")
            check_int(d["class_id"], path, f"{k}.class_id", 0, len(CLASS_NAMES) - 1)
            check_numbers(d["center_px"], path, f"{k}.center_px", 2)
            if "score" in d:
                check_number(d["score"], path, f"{k}.score", 0.0, 1.0)
            for box in ("bbox_px", "bbox_detector_px"):
                if box in d:
                    check_numbers(d[box], path, f"{k}.{box}", 4)
            if "refined" in d:
                check_bool(d["refined"], path, f"{k}.refined")
            if d.get("edge_px") is not None:
                check_number(d["edge_px"], path, f"{k}.edge_px", 0.0, 100.0)
    return data
