"""Run ultralytics' own data code on dockfactory exports (a script the YOLO-pose tests start in a
subprocess, so ultralytics' imports and settings never touch the test process).

    python ultralytics_check.py COCO_ANNOTATIONS_DIR YOLO_POSE_DIR WORK_DIR  -> JSON on stdout

- ``convert_coco(COCO_ANNOTATIONS_DIR, use_keypoints=True, cls91to80=False)`` as a user runs it,
  then again on a copy of the COCO files whose keypoints (v > 0) were moved by + 0.5 px as the
  COCO export's ``info.keypoints_to_continuous`` says: the rows of both, per label file;
- ``check_det_dataset(YOLO_POSE_DIR/data.yaml)``: the keys it resolves;
- ``verify_image_label`` (keypoint mode, kpt_shape from data.yaml) on every image/label pair of
  the pose export: its boxes, keypoints, counts and message per pair.

Where ultralytics comes from: the installed package, or the folder named by
``DOCKFACTORY_ULTRALYTICS`` (e.g. ``pip download ultralytics --no-deps`` unpacked). ultralytics
cannot be installed beside this project's torch (it needs torchvision, whose PyPI build does not
import here); its data modules never import torchvision, but ``ultralytics.utils`` reads
torchvision's version string from package metadata at import, so without torchvision this script
puts a metadata-only record (no code) on the path first. Settings go to WORK_DIR
(``YOLO_CONFIG_DIR``), with an empty font file so that ``check_det_dataset`` downloads nothing.
"""
import copy
import importlib.metadata
import json
import os
import sys
from pathlib import Path

TORCHVISION_STAND_IN = "0.28.0"   # the torchvision release paired with torch 2.13 (ultralytics' check)


def prepare(work: Path) -> None:
    work.mkdir(parents=True, exist_ok=True)
    os.environ["YOLO_CONFIG_DIR"] = str(work / "settings")
    os.environ["YOLO_OFFLINE"] = "1"
    os.environ["YOLO_VERBOSE"] = "False"
    (work / "settings" / "Ultralytics").mkdir(parents=True, exist_ok=True)
    for font in ("Arial.ttf", "Arial.Unicode.ttf"):
        (work / "settings" / "Ultralytics" / font).write_bytes(b"")
    if os.environ.get("DOCKFACTORY_ULTRALYTICS"):
        sys.path.insert(0, os.environ["DOCKFACTORY_ULTRALYTICS"])
    try:
        importlib.metadata.version("torchvision")
    except importlib.metadata.PackageNotFoundError:
        info = work / "metadata" / f"torchvision-{TORCHVISION_STAND_IN}.dist-info"
        info.mkdir(parents=True, exist_ok=True)
        (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: torchvision\nVersion: {TORCHVISION_STAND_IN}\n")
        sys.path.insert(0, str(work / "metadata"))


def shifted_copy(src: Path, dst: Path) -> Path:
    """The COCO files of ``src`` with every labelled keypoint moved by + 0.5 px (the documented fix)."""
    dst.mkdir(parents=True, exist_ok=True)
    for path in sorted(src.glob("*.json")):
        coco = json.loads(path.read_text())
        for ann in coco["annotations"]:
            kp = copy.copy(ann["keypoints"])
            for i in range(0, len(kp), 3):
                if kp[i + 2] > 0:
                    kp[i], kp[i + 1] = kp[i] + 0.5, kp[i + 1] + 0.5
            ann["keypoints"] = kp
        (dst / path.name).write_text(json.dumps(coco))
    return dst


def converted_rows(coco_dir: Path, out: Path) -> dict:
    from ultralytics.data.converter import convert_coco
    convert_coco(str(coco_dir), save_dir=str(out), use_keypoints=True, cls91to80=False)
    return {f"{p.parent.name}/{p.stem}": [[float(v) for v in line.split()] for line in p.read_text().splitlines()]
            for p in sorted((out / "labels").rglob("*.txt"))}


def verified_pairs(data: dict) -> list:
    from ultralytics.data.utils import img2label_paths, verify_image_label
    nkpt, ndim = data["kpt_shape"]
    rows = []
    for split in ("train", "val", "test"):
        images = sorted(str(p) for p in Path(data[split]).glob("*.png"))
        for im, lb in zip(images, img2label_paths(images)):
            res = verify_image_label((im, lb, "", True, len(data["names"]), nkpt, ndim, False))
            _, boxes, shape, _, kpts, nm, nf, ne, nc, msg = res
            rows.append({"split": split, "image": Path(im).stem, "boxes": None if boxes is None else boxes.tolist(),
                         "keypoints": None if kpts is None else kpts.tolist(), "shape": list(shape or ()),
                         "missing": nm, "found": nf, "empty": ne, "corrupt": nc, "msg": msg})
    return rows


def main(coco_dir: str, pose_dir: str, work_dir: str) -> None:
    work = Path(work_dir)
    prepare(work)
    import ultralytics
    from ultralytics.data.utils import check_det_dataset
    data = check_det_dataset(str(Path(pose_dir) / "data.yaml"), autodownload=False)
    result = {"ultralytics": ultralytics.__version__,
              "data": {k: data.get(k) for k in ("kpt_shape", "flip_idx", "nc", "train", "val", "test")},
              "names": {int(k): v for k, v in data["names"].items()},
              "as_given": converted_rows(Path(coco_dir), work / "as_given"),
              "shifted": converted_rows(shifted_copy(Path(coco_dir), work / "shifted_json"), work / "shifted"),
              "verified": verified_pairs(data)}
    print(json.dumps(result))


if __name__ == "__main__":
    main(*sys.argv[1:4])
