"""Where the markers' render noise sits: edge pixels against flat ones, and how each converges.

    python -m bench.render.crop_noise REFERENCE CANDIDATE [CANDIDATE ...] [--frames 20] [--out noise.json]

REFERENCE: a dataset rendered with label-aware sampling at many samples (the converged reference
of bench/results/marker_sampling, e.g. 256 samples, no denoiser); each CANDIDATE the same config
at fewer samples (``[render] marker_samples``, read from its dataset.json). Every dataset must
have kept its EXR renders (``[render] keep_exr``), which are the renderer's own linear light
before any camera effect. Per whole marker (in frame, visible fraction >= 0.99) of every other
test frame (up to ``--frames``), in the marker's own colour channel (red for section A, blue for
B), inside the ellipse of 1.3x its label box (disc, ring and a margin):

    contrast  = 95th less 5th percentile of the reference there;
    g         = |Sobel gradient| of the reference / contrast (per pixel: 1 = a full step per pixel);
    classes   = edge (g > 0.25), slope (0.08 < g <= 0.25), flat (g <= 0.08);
    noise     = (candidate - reference)^2 / contrast^2, averaged per class (median over markers);
    weight    = share of sum(g^2 noise) per class: what a least-squares edge fit, whose
                sensitivity to a pixel goes with the reference's gradient there, takes from it.

The reference's own noise is in every figure: a candidate at N samples measures
c_N / N + c_ref / N_ref. ``own`` removes it, taking the reference's c as the candidate of most
samples' (measured / (1 / N_max + 1 / N_ref)): c falls with N where the pattern stratifies, so
this removes at most the reference's share. Between two candidates the printed exponent p is
log(own noise ratio) / log(samples ratio): 1 for independent samples (the light's Monte Carlo
noise), above 1 where the sample pattern stratifies (a pixel's footprint split between a disc and
its ring: antialiasing noise).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np

from dockfactory.core.io import write_json_atomic
from dockfactory.generator.exr import read_compact

CLASSES = (("edge", 0.25, np.inf), ("slope", 0.08, 0.25), ("flat", -np.inf, 0.08))
HALO = 1.3           # the ellipse measured, in half label boxes
MIN_VISIBLE = 0.99


def marker_pixels(m: dict) -> tuple[np.ndarray, np.ndarray] | None:
    """Rows and columns (int arrays) of the ellipse of HALO half label boxes around a whole marker."""
    if not m["in_frame"] or m["visible_fraction"] < MIN_VISIBLE:
        return None
    x0, y0, x1, y1 = m["bbox_px"]
    cx, cy, hw, hh = (x0 + x1) / 2, (y0 + y1) / 2, (x1 - x0) / 2 * HALO, (y1 - y0) / 2 * HALO
    ys, xs = np.mgrid[int(cy - hh):int(cy + hh) + 2, int(cx - hw):int(cx + hw) + 2]
    inside = ((xs - cx) / hw) ** 2 + ((ys - cy) / hh) ** 2 < 1
    return ys[inside], xs[inside]


def marker_noise(ref: np.ndarray, cands: list[np.ndarray], m: dict) -> dict | None:
    """Per class: mean normalised noise of each candidate and its gradient-weighted share."""
    px = marker_pixels(m)
    if px is None:
        return None
    ch = 0 if m["section"] == "A" else 2
    r = np.ascontiguousarray(ref[..., ch], dtype=np.float64)
    ys, xs = px
    if ys.min() < 1 or xs.min() < 1 or ys.max() >= r.shape[0] - 1 or xs.max() >= r.shape[1] - 1:
        return None
    vals = r[ys, xs]
    contrast = np.percentile(vals, 95) - np.percentile(vals, 5)
    if contrast <= 0:
        return None
    y0, x0 = ys.min() - 1, xs.min() - 1          # the marker's box and the Sobel kernel's 1 px reach
    box = r[y0:ys.max() + 2, x0:xs.max() + 2]
    gx, gy = (cv2.Sobel(box, cv2.CV_64F, dx, dy, ksize=3) / 8 for dx, dy in ((1, 0), (0, 1)))
    g = np.hypot(gx, gy)[ys - y0, xs - x0] / contrast
    out = {}
    for ci, cand in enumerate(cands):
        d2 = ((cand[..., ch][ys, xs] - vals) / contrast) ** 2
        total = np.sum(g ** 2 * d2)
        for name, lo, hi in CLASSES:
            sel = (g > lo) & (g <= hi)
            out[(ci, name)] = (float(d2[sel].mean()) if sel.any() else np.nan,
                               float(np.sum(g[sel] ** 2 * d2[sel]) / total) if total > 0 else np.nan,
                               int(sel.sum()))
    return out


def marker_samples(root: Path) -> int:
    """``[render] marker_samples`` of a dataset (its dataset.json)."""
    cfg = json.loads((root / "dataset.json").read_text())["config"]
    return int(cfg["render"]["marker_samples"])


def collect(ref_root: Path, cand_roots: list[Path], frames: int) -> dict:
    """Median over markers of each candidate's per-class figures, with the marker count."""
    rows: dict = {}
    ids = sorted(p.stem for p in (ref_root / "exr").glob("*.exr"))[::2][:frames]
    if not ids:
        sys.exit(f"crop_noise: {ref_root / 'exr'}: no EXR renders (render with keep_exr = true)")
    for fid in ids:
        ref = read_compact(ref_root / "exr" / f"{fid}.exr").rgb
        cands = [read_compact(c / "exr" / f"{fid}.exr").rgb for c in cand_roots]
        labels = json.loads((ref_root / "labels" / f"{fid}.json").read_text())
        for m in labels["markers"]:
            got = marker_noise(ref, cands, m)
            for key, value in (got or {}).items():
                rows.setdefault(key, []).append(value)
    summary = {}
    for ci, root in enumerate(cand_roots):
        per = {name: {"noise": float(np.nanmedian([v[0] for v in rows[(ci, name)]])),
                      "weight": float(np.nanmedian([v[1] for v in rows[(ci, name)]])),
                      "pixels": int(np.median([v[2] for v in rows[(ci, name)]]))} for name, _, _ in CLASSES}
        summary[str(root)] = {"marker_samples": marker_samples(root), "markers": len(rows[(ci, "edge")]),
                              "classes": per}
    return summary


def remove_reference_noise(summary: dict, ref_samples: int) -> None:
    """Add ``own`` (the noise less the reference's, see the module's docstring) and ``own_per_sample``
    (own x N) to every class of every candidate, in place."""
    top = max(summary.values(), key=lambda s: s["marker_samples"])
    for name, _, _ in CLASSES:
        c_ref = top["classes"][name]["noise"] / (1 / top["marker_samples"] + 1 / ref_samples)
        for s in summary.values():
            own = s["classes"][name]["noise"] - c_ref / ref_samples
            s["classes"][name].update(own=own, own_per_sample=own * s["marker_samples"])


def exponents(summary: dict) -> dict:
    """Per class, log(own noise ratio) / log(samples ratio) between consecutive candidates by
    samples (candidates of equal samples, e.g. adaptive ones beside a uniform one, give none)."""
    items = sorted(summary.values(), key=lambda s: s["marker_samples"])
    out = {}
    for a, b in zip(items, items[1:]):
        if a["marker_samples"] == b["marker_samples"]:
            continue
        ratio = np.log(b["marker_samples"] / a["marker_samples"])
        out[f"{a['marker_samples']}->{b['marker_samples']}"] = {
            name: float(np.log(a["classes"][name]["own"] / b["classes"][name]["own"]) / ratio)
            for name, _, _ in CLASSES}
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("reference", type=Path)
    ap.add_argument("candidates", type=Path, nargs="+")
    ap.add_argument("--frames", type=int, default=20, help="every other test frame, up to this many")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args()
    summary = collect(a.reference, a.candidates, a.frames)
    ref_samples = marker_samples(a.reference)
    remove_reference_noise(summary, ref_samples)
    result = {"reference": str(a.reference), "reference_samples": ref_samples, "candidates": summary,
              "exponents": exponents(summary)}
    print("| candidate | samples | markers | edge: noise / share / px | slope | flat | edge / flat noise "
          "| own noise x N: edge / flat |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for root, s in summary.items():
        c = s["classes"]
        cells = [f"{c[n]['noise']:.2e} / {c[n]['weight']:.2f} / {c[n]['pixels']}" for n, _, _ in CLASSES]
        print(f"| {root} | {s['marker_samples']} | {s['markers']} | " + " | ".join(cells)
              + f" | {c['edge']['noise'] / c['flat']['noise']:.1f} | {c['edge']['own_per_sample']:.4f} / "
              f"{c['flat']['own_per_sample']:.4f} |")
    for pair, e in result["exponents"].items():
        print(f"exponent p {pair}: " + ", ".join(f"{k} {v:.2f}" for k, v in e.items()))
    if a.out:
        write_json_atomic(a.out, result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
