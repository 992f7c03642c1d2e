"""ultralytics on dockfactory's ``--format yolo-pose`` export: where its loader puts our keypoints,
and one epoch of a YOLOv8n-pose trained from its yaml (no pretrained weights).

    .venv/bin/python -m bench.solver.pose_train DATASET POSE_EXPORT WORK --ultralytics DIR [--deps DIR]
        [--epochs 1] [--imgsz 640] [--batch 8]  -> log on stdout, WORK/pose_train.json

- DATASET: the dockfactory dataset (read only: its labels give the marker centres);
  POSE_EXPORT: ``dockfactory dataset export DATASET --format yolo-pose --out X`` -> X/yolo-pose.
- ``--ultralytics DIR``: an unpacked ``pip download ultralytics --no-deps`` wheel; ``--deps DIR``:
  ultralytics' own dependencies missing from our venv (``pip install --target DIR polars``; the
  trainer reads its results.csv with polars). ultralytics-thop and scipy are optional (FLOPs are
  then reported as 0; a pure-python assignment replaces scipy's).
- torchvision: the PyPI wheels do not import beside our CPU torch, so ``bench/solver/ultralytics_shim``
  (a stand-in with ``ops.nms`` in plain torch; its docstring says what and why) goes first on the
  path, with a metadata-only ``torchvision-0.28.0.dist-info`` written to WORK.
- Nothing is downloaded: settings and fonts live in WORK (``YOLO_CONFIG_DIR``, empty font files,
  ``YOLO_OFFLINE=1``), ``amp=False`` (its check fetches weights), ``plots=False``, and every
  socket connection raises, so an attempted download stops the run instead of passing unseen.

The loader check builds ultralytics' own evaluation dataset (``build_yolo_dataset``, letterbox, no
augmentation) of every split and maps each keypoint it returns back to the original image: the
distance to the label's marker centre (OpenCV px, + 0.5 in ultralytics' continuous coordinates)
must be below ``KEYPOINT_TOL_PX``; the box centre's offset from the keypoint is reported (it is not
zero: the box bounds the projected disc, whose centre is not the projected centre).
"""
import argparse
import json
import os
import socket
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SHIM = HERE / "ultralytics_shim"
TORCHVISION_STAND_IN = "0.28.0"   # the torchvision release ultralytics pairs with torch 2.13
KEYPOINT_TOL_PX = 0.01


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("dataset", type=Path)
    p.add_argument("pose_export", type=Path)
    p.add_argument("work", type=Path)
    p.add_argument("--ultralytics", type=Path, required=True)
    p.add_argument("--deps", type=Path)
    p.add_argument("--epochs", type=int, default=1)
    p.add_argument("--imgsz", type=int, default=640)
    p.add_argument("--batch", type=int, default=8)
    args = p.parse_args(argv)
    if not (args.ultralytics / "ultralytics" / "__init__.py").is_file():
        p.error(f"--ultralytics {args.ultralytics}: no ultralytics/__init__.py there")
    if not (args.pose_export / "data.yaml").is_file():
        p.error(f"{args.pose_export}: no data.yaml (a --format yolo-pose export)")
    return args


def refuse_network(*_args, **_kwargs):
    raise RuntimeError("pose_train.py: a network connection was attempted (nothing may be downloaded)")


def prepare(work: Path, ultralytics_dir: Path, deps: Path | None) -> None:
    """Settings, fonts and torchvision's metadata in ``work``; the shim, ultralytics and ``deps``
    first on sys.path; sockets refuse to connect."""
    settings = work / "settings" / "Ultralytics"
    settings.mkdir(parents=True, exist_ok=True)
    os.environ.update(YOLO_CONFIG_DIR=str(work / "settings"), YOLO_OFFLINE="1")
    for font in ("Arial.ttf", "Arial.Unicode.ttf"):
        (settings / font).write_bytes(b"")
    info = work / "metadata" / f"torchvision-{TORCHVISION_STAND_IN}.dist-info"
    info.mkdir(parents=True, exist_ok=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: torchvision\nVersion: {TORCHVISION_STAND_IN}\n")
    for path in (deps, work / "metadata", ultralytics_dir, SHIM):
        if path is not None:
            sys.path.insert(0, str(path))
    socket.socket.connect = refuse_network
    socket.create_connection = refuse_network


def label_centres(dataset: Path) -> dict:
    """{frame id: [(class id, (u, v) OpenCV px)] of every marker} from the dataset's labels."""
    out = {}
    for path in sorted((dataset / "labels").glob("*.json")):
        lab = json.loads(path.read_text())
        out[path.stem] = [(m["class_id"], tuple(m["center_px"])) for m in lab["markers"]]
    return out


def original_px(xy_norm: np.ndarray, item: dict) -> np.ndarray:
    """Points (N, 2) normalised to ultralytics' letterboxed image -> OpenCV px of the original image
    (ultralytics' continuous coordinates scale with the resize; minus 0.5 for OpenCV's centres)."""
    h, w = item["img"].shape[1:]
    (gain_h, gain_w), (pad_x, pad_y) = item["ratio_pad"]
    cont = (xy_norm * [w, h] - [pad_x, pad_y]) / [gain_w, gain_h]
    return cont - 0.5


def check_split(dataset_obj, centres: dict) -> dict:
    """Per instance: the keypoint's distance to the label's marker centre of its class, and the box
    centre's distance to the keypoint, both in original pixels."""
    kp_err, box_off, n_hidden, n_items = [], [], 0, 0
    for i in range(len(dataset_obj)):
        item = dataset_obj[i]
        markers = centres[Path(item["im_file"]).stem]
        kps = original_px(item["keypoints"][:, 0, :2].numpy().astype(np.float64), item)
        boxes = original_px(item["bboxes"][:, :2].numpy().astype(np.float64), item)
        for cls, kp, vis, box_c in zip(item["cls"][:, 0].tolist(), kps, item["keypoints"][:, 0, 2].tolist(), boxes):
            n_items += 1
            if vis == 0:   # the marker's centre is outside the image: no keypoint
                n_hidden += 1
                continue
            same = np.array([c for k, c in markers if k == int(cls)])
            kp_err.append(float(np.min(np.hypot(*(same - kp).T))))
            box_off.append(float(np.hypot(*(box_c - kp))))
    kp_err, box_off = np.array(kp_err), np.array(box_off)
    return {"instances": n_items, "without_keypoint": n_hidden, "keypoint_err_max_px": float(kp_err.max()),
            "keypoint_err_mean_px": float(kp_err.mean()), "box_centre_offset_median_px": float(np.median(box_off)),
            "box_centre_offset_p99_px": float(np.percentile(box_off, 99)), "box_centre_offset_max_px": float(box_off.max())}


def loader_check(data_yaml: Path, dataset: Path, imgsz: int) -> dict:
    """ultralytics' evaluation dataset of every split against the labels' marker centres."""
    from ultralytics.cfg import get_cfg
    from ultralytics.data import build_yolo_dataset
    from ultralytics.data.utils import check_det_dataset
    data = check_det_dataset(str(data_yaml))
    cfg = get_cfg(overrides={"task": "pose", "imgsz": imgsz, "data": str(data_yaml)})
    centres = label_centres(dataset)
    out = {}
    for split in ("train", "val", "test"):
        ds = build_yolo_dataset(cfg, data[split], 1, data, mode="val", stride=32)
        out[split] = check_split(ds, centres)
    return out


def results_csv(path: Path) -> list[dict]:
    """The trainer's results.csv as one dict per epoch (plain csv: no polars needed to read it)."""
    import csv
    with path.open(newline="") as f:
        return [{k.strip(): float(v) for k, v in row.items()} for row in csv.DictReader(f)]


def train(data_yaml: Path, work: Path, args: argparse.Namespace) -> dict:
    """YOLOv8n-pose from its yaml, ``args.epochs`` epochs on the train split, validated on val."""
    from ultralytics import YOLO
    model = YOLO("yolov8n-pose.yaml", task="pose")
    t0 = time.perf_counter()
    metrics = model.train(data=str(data_yaml), epochs=args.epochs, imgsz=args.imgsz, batch=args.batch,
                          workers=0, device="cpu", amp=False, plots=False, pretrained=False, seed=0,
                          deterministic=True, project=str(work), name="train", exist_ok=True, verbose=True)
    seconds = time.perf_counter() - t0
    trainer = model.trainer
    return {"seconds": round(seconds, 1), "metrics": {k: float(v) for k, v in metrics.results_dict.items()},
            "val_instances_per_class": metrics.nt_per_class.tolist(), "epochs": results_csv(trainer.csv),
            "best": str(trainer.best), "train_images": len(trainer.train_loader.dataset)}


def prediction_check(best: Path, data_yaml: Path, imgsz: int) -> dict:
    """The trained model's predictions on the val images: how many, their confidences, and whether
    each keypoint lies inside its own box (what the head was trained to output)."""
    from ultralytics import YOLO
    from ultralytics.data.utils import check_det_dataset
    images = sorted(Path(check_det_dataset(str(data_yaml))["val"]).glob("*.png"))
    model = YOLO(str(best), task="pose")
    confs, inside = [], []
    for res in model.predict([str(p) for p in images], imgsz=imgsz, conf=0.001, device="cpu", verbose=False,
                             stream=True):
        xyxy = res.boxes.xyxy.numpy()
        kp = res.keypoints.xy.numpy()[:, 0, :]
        confs += res.boxes.conf.tolist()
        inside += ((kp[:, 0] >= xyxy[:, 0]) & (kp[:, 0] <= xyxy[:, 2]) &
                   (kp[:, 1] >= xyxy[:, 1]) & (kp[:, 1] <= xyxy[:, 3])).tolist()
    confs = np.array(confs)
    return {"images": len(images), "predictions_conf_0.001": len(confs),
            "max_conf": float(confs.max()) if len(confs) else None,
            "predictions_conf_0.25": int((confs >= 0.25).sum()),
            "keypoint_inside_own_box": float(np.mean(inside)) if inside else None}


def main(argv=None) -> int:
    args = parse_args(argv)
    args.work.mkdir(parents=True, exist_ok=True)
    prepare(args.work, args.ultralytics, args.deps)
    import torch
    import ultralytics
    data_yaml = args.pose_export / "data.yaml"
    report = {"ultralytics": ultralytics.__version__, "torch": torch.__version__, "threads": torch.get_num_threads(),
              "torchvision": "bench/solver/ultralytics_shim (stand-in, not torchvision)",
              "dataset": json.loads((args.dataset / "dataset.json").read_text())["version_id"],
              "imgsz": args.imgsz, "batch": args.batch}
    report["loader"] = loader_check(data_yaml, args.dataset, args.imgsz)
    print(json.dumps({"loader": report["loader"]}, indent=1), flush=True)
    report["train"] = train(data_yaml, args.work, args)
    report["predictions"] = prediction_check(Path(report["train"]["best"]), data_yaml, args.imgsz)
    tmp = args.work / "pose_train.json.tmp"
    tmp.write_text(json.dumps(report, indent=1) + "\n")
    os.replace(tmp, args.work / "pose_train.json")
    print(json.dumps(report, indent=1))
    worst = max(s["keypoint_err_max_px"] for s in report["loader"].values())
    return 0 if worst < KEYPOINT_TOL_PX else 1


if __name__ == "__main__":
    sys.exit(main())
