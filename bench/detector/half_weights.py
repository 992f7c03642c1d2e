"""fp16 copy of detector weights, checked against the fp32 original on a dataset's test split.

    python -m bench.detector.half_weights WEIGHTS.pt OUT.pt DATASET [--threads 2]

Writes OUT.pt (the same weights file with every floating-point tensor in fp16; loading casts back
to fp32) and prints both files' size and sha256 and their figures on the test split: mAP50,
mAP50:95 (pycocotools), median centre error per condition and the largest change of a refined
centre between the two (px). "Unchanged" means the figures a model card quotes: mAP50 and
mAP50:95 equal to 3 decimals and every condition's median centre error within 0.001 px; the script
exits 1 otherwise and removes OUT.pt. (A single centre may move by more: fp16 moves the box a
little, and the refinement window with it.)
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np


def half_weights(src, dst) -> Path:
    """``dst``: the weights file ``src`` with its floating-point tensors in fp16 (atomic write)."""
    from dockfactory.detector.checkpoint import WEIGHTS_FORMAT, load_file, save_atomic
    obj = load_file(src, expect=(WEIGHTS_FORMAT,))
    sd = {k: (v.half() if v.is_floating_point() else v) for k, v in obj["state_dict"].items()}
    prov = {**obj.get("provenance", {}), "half": True}
    return save_atomic({**obj, "state_dict": sd, "provenance": prov}, dst)


def _figures(dataset, weights: Path, tmp: Path) -> tuple[dict, dict]:
    from dockfactory.detector.infer import detect_dataset
    from dockfactory.eval.detection_metrics import evaluate_detections
    doc = detect_dataset(dataset, weights, tmp / f"{weights.stem}.json", split="test", conf_threshold=0.001,
                         progress=False)
    return evaluate_detections(dataset, doc), doc


def largest_centre_change(doc_a: dict, doc_b: dict, min_score: float = 0.25) -> float:
    """Largest distance between a refined centre of ``doc_a`` and the nearest same-class one of
    ``doc_b`` (detections with score >= ``min_score``), px."""
    worst = 0.0
    for fid, dets in doc_a["frames"].items():
        other = [d for d in doc_b["frames"].get(fid, []) if d["score"] >= min_score]
        for d in (d for d in dets if d["score"] >= min_score):
            same = [np.hypot(*(np.subtract(d["center_px"], o["center_px"]))) for o in other
                    if o["class_id"] == d["class_id"]]
            worst = max(worst, min(same) if same else float("inf"))
    return worst


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("weights", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("dataset")
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    args = ap.parse_args(argv)
    import torch
    torch.set_num_threads(args.threads)
    from dockfactory.core.io import sha256_file
    from dockfactory.generator.datasets.reader import Dataset
    half_weights(args.weights, args.out)
    dataset = Dataset.open(args.dataset)
    with tempfile.TemporaryDirectory() as tmp:
        (m32, d32), (m16, d16) = (_figures(dataset, w, Path(tmp)) for w in (args.weights, args.out))
    shift = max(largest_centre_change(d32, d16), largest_centre_change(d16, d32))
    for name, path, m in (("fp32", args.weights, m32), ("fp16", args.out, m16)):
        ce = {k: round(v["median_px"], 4) for k, v in m["centre_error_by_condition"].items()}
        print(f"{name}: {path} {path.stat().st_size / 1e6:.2f} MB sha256 {sha256_file(path)}; mAP50 {m['mAP50']:.4f} "
              f"mAP50:95 {m['mAP50_95']:.4f}; median centre error {ce}")
    medians = [(m32["centre_error_by_condition"][k]["median_px"], v["median_px"])
               for k, v in m16["centre_error_by_condition"].items()]
    same = (round(m32["mAP50"], 3) == round(m16["mAP50"], 3) and round(m32["mAP50_95"], 3) == round(m16["mAP50_95"], 3)
            and all(abs(a - b) <= 0.001 for a, b in medians))
    print(f"largest refined-centre change {shift:.5f} px; metrics {'unchanged' if same else 'CHANGED'}")
    if not same:
        args.out.unlink()
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
