"""Which part of a re-rendered label differs from the published one, when `dataset verify
--manifest` says "differs beyond its image measurements".

The published fingerprints hold, per frame, the sha256 of the label without chroma and
auto-exposure (generator/datasets/published.py). The published labels themselves are not shipped, so this
searches for the smallest change of what the label reads from Cycles' index pass that gives the
published digest back: one section's ``pixels_visible`` moved by +-1..4 px (its
``visible_fraction`` recomputed), then one marker's ``visible_pixels`` by +-1..3 (its fraction
and visibility recomputed, with or without its section's count). A frame it explains differs from
the published one only in that index-pass pixel count; "unexplained" means something else differs.

With ``--derive-v2 OUT`` (a complete re-render only) it writes fingerprint v2 of the published
labels (generator/datasets/label_prints.py) to OUT: each re-rendered label, with the index-pass change that
gives the published v1 digest back applied where one is needed. Every label it uses thus has the
published v1 digest, so its v2 fingerprint is the published label's; it refuses (exit 1, nothing
written) if any frame is unexplained or missing.

Run: python -m bench.render.explain_label_diffs RERENDER [--published results/paper] [--frames a,b,...]
     [--derive-v2 results/paper/fingerprints_v2.npz]
(default: every frame of RERENDER whose label geometry differs from the published digest)
"""
from __future__ import annotations

import argparse
import copy
import json
from pathlib import Path

import os

import dockfactory

dockfactory.pin_label_arithmetic(os.environ)   # before numpy loads: labels as the command computes them

import numpy as np

from dockfactory.core.io import write_bytes_atomic
from dockfactory.generator.datasets.fingerprints import FINGERPRINTS_NAME, fingerprints_v2
from dockfactory.generator.datasets.label_prints import label_geometry_sha256


def _digest(label: dict) -> str:
    return label_geometry_sha256(json.dumps(label).encode())


def _set_section(label, idx, delta):
    s = label["sections"][idx]
    s["pixels_visible"] += delta
    s["visible_fraction"] = min(1.0, s["pixels_visible"] / s["pixels_all"]) if s.get("pixels_all") else 0.0


def _set_marker(label, idx, delta, threshold=0.5):
    m = label["markers"][idx]
    m["visible_pixels"] += delta
    a = m["area_in_frame_px"]
    m["visible_fraction"] = min(1.0, m["visible_pixels"] / a) if a > 0 else 0.0
    m["visibility"] = 0 if not m["in_frame"] else (2 if m["visible_fraction"] >= threshold else 1)


def explain(label: dict, published: str) -> tuple[str, dict] | None:
    """(a description of the index-pass change that gives the published digest back, the label
    with it applied), or None."""
    for i, s in enumerate(label["sections"]):
        for d in (-1, 1, -2, 2, -3, 3, -4, 4):
            if "pixels_visible" in s:
                trial = copy.deepcopy(label)
                _set_section(trial, i, d)
                if _digest(trial) == published:
                    return f"section {s['section']} pixels_visible {d:+d}", trial
    for i, m in enumerate(label["markers"]):
        for d in (-1, 1, -2, 2, -3, 3):
            for with_section in (False, True):
                if not m.get("visible_pixels"):
                    continue
                trial = copy.deepcopy(label)
                _set_marker(trial, i, d)
                if with_section:
                    _set_section(trial, [s["section"] for s in label["sections"]].index(m["section"]), d)
                if _digest(trial) == published:
                    return (f"marker {m['id']} visible_pixels {d:+d}" + (" (and its section)" if with_section else ""),
                            trial)
    return None


def compare(paths, pub: dict) -> tuple[dict, int, int]:
    """({frame id: the label with the published v1 digest, or None}, frames with it as re-rendered,
    frames unexplained), printing each frame that differs."""
    labels, same, unexplained = {}, 0, 0
    for path in paths:
        label = json.loads(path.read_text())
        if path.stem not in pub:
            print(f"{path.stem}: not a published frame")
            labels[path.stem], unexplained = None, unexplained + 1
        elif _digest(label) == pub[path.stem]:
            labels[path.stem], same = label, same + 1
        else:
            found = explain(label, pub[path.stem])
            print(f"{path.stem}: {found[0] if found else 'unexplained'}")
            labels[path.stem], unexplained = (found[1] if found else None), unexplained + (found is None)
    return labels, same, unexplained


def derive_v2(labels: dict, ids: list, out: Path) -> None:
    """Write fingerprint v2 of the published labels (``labels`` must hold every id of ``ids``)."""
    missing = [fid for fid in ids if labels.get(fid) is None]
    if missing:
        raise SystemExit(f"--derive-v2: {len(missing)} published frames missing or unexplained (first {missing[0]}); "
                         "nothing written")
    texts = [json.dumps(labels[fid]).encode() for fid in ids]
    write_bytes_atomic(out, fingerprints_v2(ids, texts))
    print(f"wrote fingerprint v2 of {len(ids)} published labels to {out}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rerender", type=Path)
    ap.add_argument("--published", type=Path, default=Path("results/paper"))
    ap.add_argument("--frames")
    ap.add_argument("--derive-v2", type=Path)
    args = ap.parse_args(argv)
    with np.load(args.published / FINGERPRINTS_NAME, allow_pickle=False) as z:
        ids = [str(f) for f in z["frame_ids"]]
        pub = dict(zip(ids, (str(g) for g in z["label_geometry"])))
    paths = sorted((args.rerender / "labels").glob("*.json"))
    if args.frames:
        wanted = set(args.frames.split(","))
        paths = [p for p in paths if p.stem in wanted]
    labels, same, unexplained = compare(paths, pub)
    print(f"{len(paths)} labels: {same} with the published geometry, {len(paths) - same - unexplained} "
          f"explained by one index-pass pixel count, {unexplained} unexplained")
    if args.derive_v2:
        derive_v2(labels, ids, args.derive_v2)
    return 1 if unexplained else 0


if __name__ == "__main__":
    raise SystemExit(main())
