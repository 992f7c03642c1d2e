"""The YOLO-pose export: ultralytics' pose layout, one keypoint per marker at its continuous centre;
and ultralytics' own converter and label verifier run on the COCO and YOLO-pose exports.

The dataset is test_exports' painted one (no render): a frame with a marker centre outside the
image, crowd (mostly hidden) and washed-out markers, every split.
"""
import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from test_exports import THRESHOLD, ultralytics_dataset, write_dataset

from dockfactory.core.layout import CLASS_NAMES
from dockfactory.generator.datasets import tools as dt
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.exports.coco import KEYPOINTS_TO_CONTINUOUS
from dockfactory.generator.exports.yolo import parse_yolo_line
from dockfactory.generator.exports.yolo_pose import parse_pose_keypoint

HERE = Path(__file__).resolve().parent
CENTRE_TOL_PX = 1e-6          # our file: 10 decimals of a normalised coordinate
CONVERTER_TOL_PX = 1e-3       # ultralytics writes "%g" (6 significant digits) of normalised values
VERIFIER_TOL_PX = 1e-3        # ultralytics' verifier holds labels as float32


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    root = write_dataset(tmp_path_factory.mktemp("pose") / "ds")
    for fmt in ("coco", "yolo-pose"):
        dt.export(root, fmt)
    labels = {lab["frame_id"]: lab for lab in Dataset.open(root).labels_of()}
    return root / "exports", labels


def expected_markers(lab):
    return [m for m in lab["markers"] if m["bbox_px"] and m["visible_fraction"] >= THRESHOLD and m["legible"]]


def test_pose_layout_and_keypoints_are_the_continuous_centres(exported):
    root, labels = exported
    data = yaml.safe_load((root / "yolo-pose" / "data.yaml").read_text())
    assert data["kpt_shape"] == [1, 3] and data["flip_idx"] == [0]
    assert data["kpt_names"] == {i: ["centre"] for i in range(len(CLASS_NAMES))}
    names, splits = ultralytics_dataset(root / "yolo-pose" / "data.yaml")
    assert names == list(CLASS_NAMES) and set(splits) == {"train", "val", "test"}
    n = n_outside = 0
    for pairs in splits.values():
        for img, txt in pairs:
            lab = labels[os.path.basename(img)[:-4]]
            w, h = lab["image"]["width"], lab["image"]["height"]
            lines = Path(txt).read_text().splitlines()
            assert len(lines) == len(expected_markers(lab))
            for line, m in zip(lines, expected_markers(lab)):
                values = [float(v) for v in line.split()]
                assert len(values) == 8 and all(0.0 <= v <= 1.0 for v in values[1:7])
                c, box = parse_yolo_line(" ".join(line.split()[:5]), w, h)
                assert c == m["class_id"] and np.allclose(box, m["bbox_px"], rtol=0, atol=1e-5)
                u, v, vis = parse_pose_keypoint(line, w, h)
                if m["in_frame"]:
                    # continuous: (kx * W) is the label's OpenCV centre + 0.5
                    assert vis == m["visibility"] == 2
                    assert abs(u - m["center_px"][0]) < CENTRE_TOL_PX and abs(v - m["center_px"][1]) < CENTRE_TOL_PX
                else:
                    assert line.split()[5:] == ["0", "0", "0"]
                    n_outside += 1
                n += 1
    assert n > 50 and n_outside >= 1


def test_coco_info_says_how_to_convert_keypoints(exported):
    root, _ = exported
    for path in (root / "coco" / "annotations").glob("*.json"):
        info = json.loads(path.read_text())["info"]
        assert info["keypoints_to_continuous"] == KEYPOINTS_TO_CONTINUOUS
        assert "add 0.5" in KEYPOINTS_TO_CONTINUOUS and "convert_coco" in KEYPOINTS_TO_CONTINUOUS


# ----------------------------------------------------------------------------- ultralytics' own code

def ultralytics_source() -> str | None:
    """Where ultralytics can be imported from: the installed package, or DOCKFACTORY_ULTRALYTICS."""
    folder = os.environ.get("DOCKFACTORY_ULTRALYTICS")
    if folder and (Path(folder) / "ultralytics" / "__init__.py").is_file():
        return folder
    return "installed" if importlib.util.find_spec("ultralytics") else None


@pytest.fixture(scope="module")
def ultralytics_run(exported, tmp_path_factory):
    if ultralytics_source() is None:
        pytest.skip("ultralytics absent (it cannot be installed beside our torch: `pip download ultralytics "
                    "--no-deps`, unpack the wheel and set DOCKFACTORY_ULTRALYTICS to its folder)")
    root, _ = exported
    work = tmp_path_factory.mktemp("ultralytics")
    proc = subprocess.run([sys.executable, str(HERE / "ultralytics_check.py"), str(root / "coco" / "annotations"),
                           str(root / "yolo-pose"), str(work)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def converter_keypoints(rows, lab):
    """(marker record, ultralytics' keypoint in OpenCV px) of each converted row of one frame: the
    converter keeps the COCO export's non-crowd annotations with a labelled keypoint, in order."""
    w, h = lab["image"]["width"], lab["image"]["height"]
    kept = [m for m in lab["markers"] if m["visible_pixels"] and m["bbox_px"] is not None
            and m["visible_fraction"] >= THRESHOLD and m["legible"] and m["in_frame"]]
    assert len(rows) == len(kept)
    return [(m, np.array([r[5] * w - 0.5, r[6] * h - 0.5])) for m, r in zip(kept, rows)]


def test_ultralytics_convert_coco_needs_the_documented_half_pixel(exported, ultralytics_run):
    _, labels = exported
    errors = {"as_given": [], "shifted": []}
    for kind in errors:
        for key, rows in ultralytics_run[kind].items():
            for m, kp in converter_keypoints(rows, labels[key.split("/")[1]]):
                errors[kind].append(kp - np.asarray(m["center_px"]))
    as_given, shifted = np.array(errors["as_given"]), np.array(errors["shifted"])
    assert len(as_given) > 50 and len(shifted) == len(as_given)
    # as given, every keypoint comes out half a pixel up and left of the centre
    assert np.abs(as_given + 0.5).max() < CONVERTER_TOL_PX
    # with the + 0.5 of info.keypoints_to_continuous, on the centre
    assert np.abs(shifted).max() < CONVERTER_TOL_PX


def test_ultralytics_verifies_the_pose_labels(exported, ultralytics_run):
    root, labels = exported
    assert ultralytics_run["data"]["kpt_shape"] == [1, 3] and ultralytics_run["data"]["nc"] == len(CLASS_NAMES)
    assert list(ultralytics_run["names"].values()) == list(CLASS_NAMES)
    checked = 0
    for rec in ultralytics_run["verified"]:
        lab = labels[rec["image"]]
        w, h = lab["image"]["width"], lab["image"]["height"]
        expected = expected_markers(lab)
        assert rec["corrupt"] == 0 and rec["missing"] == 0 and rec["msg"] == "", rec
        assert rec["shape"] == [h, w] and len(rec["boxes"]) == len(expected)
        for box, kp, m in zip(rec["boxes"], rec["keypoints"], expected):
            assert box[0] == m["class_id"]
            if m["in_frame"]:
                u, v, vis = kp[0]
                assert vis == 2
                assert abs(u * w - 0.5 - m["center_px"][0]) < VERIFIER_TOL_PX
                assert abs(v * h - 0.5 - m["center_px"][1]) < VERIFIER_TOL_PX
            else:
                assert kp[0] == [0.0, 0.0, 0.0]
            checked += 1
    assert checked > 50
