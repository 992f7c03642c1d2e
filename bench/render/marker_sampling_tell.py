"""Can the marker regions of label-aware sampling be told from the image's noise? A paired test.

    python -m bench.render.marker_sampling_tell PLAIN CANDIDATE [CANDIDATE ...] [--boot 2000] [--out tell.json]

PLAIN: a dataset rendered without label-aware sampling; each CANDIDATE the same config rendered
with ``[render] marker_samples`` > 0 (the same frames: checked on the labels' poses). Per test
frame and per marker region of the candidate (``generator.marker_regions``), on the delivered 8-bit
image's luma at three scales (fine: the image less its Gaussian blur of sigma 1 px; mid: sigma 1
less sigma 3; coarse: sigma 3 less sigma 8):

    ratio = mean |band-pass| over the markers' halos where the crop is blended in (weight > 0;
            the markers' discs and rings, grown by RING_KEEPOUT_PX, left out: they are the markers) /
            mean |band-pass| over the OUTER_PX pixels just beyond (weight 0; other halos left out).

The same pixels of the PLAIN image give the ratio without sampling. A tell is a candidate whose
log ratios differ from the plain ones: printed per scale, the median ratio of each, and the mean
paired difference of the log ratios (candidate - plain) with its 95 % bootstrap interval over
frames (seeded). An interval that holds 0 finds no tell at that scale; the size of the
difference says how strong one is (log 0.1: the region's texture 10 % weaker than around it).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

from dockfactory.core.io import write_json_atomic
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.core.geometry import project_points
from dockfactory.core.layout import RING_EXTRA_MM
from dockfactory.generator.marker_regions import halo_points, halo_weights, marker_halos, marker_regions
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.sampler import frame_plan, sample_frame

SCALES = {"fine": (0.0, 1.0), "mid": (1.0, 3.0), "coarse": (3.0, 8.0)}
OUTER_PX = 6        # the band beyond the blend compared with it
RING_KEEPOUT_PX = 2  # the rings grown by this much are the marker (its edge blurred by the pixel filter), not texture


def band_passes(path: Path) -> dict[str, np.ndarray]:
    """|band-pass| of the image's luma (float32) at each of SCALES."""
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    luma = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY).astype(np.float32)
    blur = {s: luma if s == 0.0 else cv2.GaussianBlur(luma, (0, 0), s) for s in {0.0, 1.0, 3.0, 8.0}}
    return {name: np.abs(blur[a] - blur[b]) for name, (a, b) in SCALES.items()}


def ring_hulls(frame, static) -> list[np.ndarray]:
    """Each marker's disc and ring (the ring's outline at the disc's top and the base's bottom) in
    canvas pixels, (k, 2) each."""
    cam = frame.camera
    out = []
    for m in static.markers:
        pose = frame.d_from_b_array() if m.section == "B" else np.eye(4)
        ring = halo_points(m, radius_mm=m.diameter_mm / 2 + RING_EXTRA_MM)
        uv, _ = project_points(cam.k(), cam.cam_from_d_array() @ pose, ring)
        out.append(uv - np.array(cam.canvas()[:2]))
    return out


def _fill(hulls, shape) -> np.ndarray:
    mask = np.zeros(shape, np.uint8)
    for uv in hulls:
        if np.all(np.isfinite(uv)):
            cv2.fillConvexPoly(mask, cv2.convexHull(np.round(uv * 8).astype(np.int32)), 1, shift=3)
    return mask.astype(bool)


def masks(frame, static, shape) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per region of ``frame``: (halo mask, outside band mask), boolean images of ``shape``."""
    h, w = shape
    halos = marker_halos(frame, static)
    weight = np.zeros(shape, np.float32)
    regions = marker_regions(frame, static)
    for r in regions:
        weight[r.y0:r.y1, r.x0:r.x1] = halo_weights(halos, r)
    grow = np.ones((2 * RING_KEEPOUT_PX + 1,) * 2, np.uint8)
    rings = cv2.dilate(_fill(ring_hulls(frame, static), shape).astype(np.uint8), grow) > 0
    blended = weight > 0
    dist = cv2.distanceTransform((~blended).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    out = []
    for r in regions:
        box = np.zeros(shape, bool)
        box[max(0, r.y0 - OUTER_PX):min(h, r.y1 + OUTER_PX), max(0, r.x0 - OUTER_PX):min(w, r.x1 + OUTER_PX)] = True
        inner = box & blended & ~rings
        band = box & (dist > 0) & (dist <= OUTER_PX)
        if inner.sum() >= 20 and band.sum() >= 20:
            out.append((inner, band))
    return out


def frame_ratios(plain: Path, cand: Path, frame, static) -> dict[str, list[tuple[float, float]]]:
    """Per scale: (plain log ratio, candidate log ratio) of each region of one frame."""
    fid = frame.spec.frame_id
    bp_p, bp_c = band_passes(plain / "images" / f"{fid}.png"), band_passes(cand / "images" / f"{fid}.png")
    shape = next(iter(bp_p.values())).shape
    out = {s: [] for s in SCALES}
    for inner, band in masks(frame, static, shape):
        for s in SCALES:
            out[s].append((float(np.log(bp_p[s][inner].mean() / bp_p[s][band].mean())),
                           float(np.log(bp_c[s][inner].mean() / bp_c[s][band].mean()))))
    return out


def tell(plain: Path, cand: Path, boot: int) -> dict:
    ds_p, ds_c = Dataset.open(plain), Dataset.open(cand)
    cfg = ds_c.config
    if cfg.render.marker_samples <= 0:
        raise SystemExit(f"{cand}: rendered without label-aware sampling")
    static = static_scene(cfg)
    per_frame = []
    for spec in frame_plan(cfg):
        if spec.split != "test":
            continue
        if ds_p.labels[spec.frame_id]["pose_b_in_d"] != ds_c.labels[spec.frame_id]["pose_b_in_d"]:
            raise SystemExit(f"{cand}: frame {spec.frame_id} is not the plain dataset's")
        frame = sample_frame(cfg, spec)
        if not frame.camera.is_pinhole():   # regions are in the render canvas; the bench reads the image
            raise SystemExit(f"{cand}: frame {spec.frame_id} has a distorted lens; the bench takes pinhole cameras")
        per_frame.append(frame_ratios(plain, cand, frame, static))
    rng = np.random.default_rng(0)
    result = {"candidate": str(cand), "version": ds_c.version_id, "marker_samples": cfg.render.marker_samples,
              "frames": len(per_frame), "scales": {}}
    for s in SCALES:
        diffs = [np.array([c - p for p, c in f[s]]) for f in per_frame]
        pooled = np.concatenate(diffs)
        idx = rng.integers(0, len(diffs), size=(boot, len(diffs)))
        means = [np.concatenate([diffs[j] for j in i]).mean() for i in idx]
        pairs = np.array([pc for f in per_frame for pc in f[s]])
        result["scales"][s] = {"regions": int(len(pooled)), "median_ratio_plain": float(np.exp(np.median(pairs[:, 0]))),
                               "median_ratio_candidate": float(np.exp(np.median(pairs[:, 1]))),
                               "mean_log_diff": [float(pooled.mean()), float(np.percentile(means, 2.5)),
                                                 float(np.percentile(means, 97.5))]}
    return result


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("plain")
    ap.add_argument("candidates", nargs="+")
    ap.add_argument("--boot", type=int, default=2000)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    rows = [tell(Path(args.plain), Path(c), args.boot) for c in args.candidates]
    print("| candidate | marker samples | scale | regions | median ratio plain | median ratio candidate | "
          "mean log difference [95 %] |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        for s, v in r["scales"].items():
            d = v["mean_log_diff"]
            print(f"| {Path(r['candidate']).name}@{r['version']} | {r['marker_samples']} | {s} | {v['regions']} | "
                  f"{v['median_ratio_plain']:.3f} | {v['median_ratio_candidate']:.3f} | "
                  f"{d[0]:+.3f} [{d[1]:+.3f}, {d[2]:+.3f}] |")
    if args.out:
        write_json_atomic(args.out, {"command": " ".join(sys.argv), "rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
