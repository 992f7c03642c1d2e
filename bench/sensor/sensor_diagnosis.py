"""Where a Bayer camera's centre error comes from: three experiments beside bench/sensor/sensor_effects.py.

    python -m bench.sensor.sensor_diagnosis synthetic [--blur 0.3,0.6,1.2]
    python -m bench.sensor.sensor_diagnosis noise DATASET [--frames N]
    python -m bench.sensor.sensor_diagnosis tail DATASET [--frames N]
    python -m bench.sensor.sensor_diagnosis boxes DATASET [--frames N] [--weights W.pt]

- ``synthetic``: clean discs drawn with exact area coverage (8 x 8 supersampling), a dark ring and
  grey paint, a Gaussian optical blur and no noise at all; each through a three-chip camera and an
  RGGB mosaic with the bilinear demosaic, refined by the shipped refinement (told the pattern for
  the Bayer frames), against the exact centres; per axis-ratio bin.
- ``noise``: a dataset's test frames through the bench's three-chip and Bayer cameras with the
  sensor's temporal noise (shot and dark noise) as configured and switched off; centre errors of
  the refined detections against the labels' outline centroids. Sensor noise that mattered would
  show as a difference between the two.
- ``tail``: the Bayer frames' pose error when the refined centres that are more than 0.2 or 0.3 px
  off, or every centre, are replaced by the three-chip camera's centre of the same marker, and
  when every refined centre's error is halved: which centres make the pose error.
- ``boxes``: the three-chip camera's frames, the shipped detector without its refinement: the
  size of each fully visible marker's box against the label's box, and the colour score where the
  refinement's coverage pass reads the ring level (the annulus at 1.08-1.22 radii) of the label's
  box against the disc's level: what a new marker design (``[markers] ring``) does to both.

Each prints a table; figures and their reading: bench/results/sensor_effects/README.md.
"""
from __future__ import annotations

import argparse
import copy
import sys

import cv2
import numpy as np

from bench.sensor.sensor_effects import COMPONENTS, EFFECTS, delivered

from dockfactory.core.camera_chain.cfa import mosaic
from dockfactory.core.camera_chain.demosaic import demosaic
from dockfactory.core.camera_chain.isp import tone_map
SUPERSAMPLE = 8
PAINT, RING = np.array([0.35, 0.35, 0.33]), np.array([0.03, 0.03, 0.03])
DISC = {0: np.array([0.55, 0.02, 0.02]), 1: np.array([0.02, 0.06, 0.45])}
RING_SCALE = 1.2        # ring radius over disc radius
RHO_BINS = ((0.25, 0.45), (0.45, 0.7), (0.7, 1.0))


def ellipse_coverage(size: int, cx: float, cy: float, a: float, b: float, theta: float) -> np.ndarray:
    """(size, size) share of each pixel inside the ellipse (semi-axes a, b px, angle theta rad,
    OpenCV pixel convention), by SUPERSAMPLE x SUPERSAMPLE point samples per pixel."""
    off = (np.arange(SUPERSAMPLE) + 0.5) / SUPERSAMPLE - 0.5
    ys = np.arange(size)[:, None, None, None] + off[None, None, :, None] - cy
    xs = np.arange(size)[None, :, None, None] + off[None, None, None, :] - cx
    u, v = np.cos(theta) * xs + np.sin(theta) * ys, -np.sin(theta) * xs + np.cos(theta) * ys
    return ((u / a) ** 2 + (v / b) ** 2 <= 1).mean(axis=(2, 3))


def synthetic_disc(rng: np.random.Generator, cls: int, rho: float, blur_px: float):
    """(linear image (64, 64, 3) float32, exact centre (2,), detector-like box (4,))."""
    a = rng.uniform(7.0, 14.0)
    cx, cy, theta = 32 + rng.uniform(-1, 1), 32 + rng.uniform(-1, 1), rng.uniform(-0.2, 0.2)
    img = np.ones((64, 64, 3)) * PAINT
    for k, colour in ((RING_SCALE, RING), (1.0, DISC[cls])):
        cov = ellipse_coverage(64, cx, cy, k * a, k * a * rho, theta)[..., None]
        img = img * (1 - cov) + colour * cov
    img = cv2.GaussianBlur(img.astype(np.float32), (0, 0), blur_px)
    box = np.array([cx - a, cy - a * rho, cx + a, cy + a * rho]) + rng.normal(0, 0.5, 4)
    return img, np.array([cx, cy]), box


def run_synthetic(blurs, per_bin: int = 60) -> None:
    from dockfactory.detector.centre import refine_centre
    from dockfactory.detector.centre_camera import refine_centre_camera
    print("| blur px | axis ratio | three-chip refined | RMS x / y px | Bayer refined | RMS x / y px |")
    print("| --- | --- | --- | --- | --- | --- |")
    for blur in blurs:
        rng = np.random.default_rng([26, int(blur * 100)])
        for lo, hi in RHO_BINS:
            three, bayer = [], []
            for t in range(per_bin):
                img, centre, box = synthetic_disc(rng, t % 2, rng.uniform(lo, hi), blur)
                r3 = refine_centre(tone_map(img, "srgb"), box, t % 2)
                rb = refine_centre_camera(tone_map(demosaic(mosaic(img, "RGGB"), "RGGB", "bilinear"), "srgb"),
                                          box, t % 2, cfa="RGGB")
                three += [r3.center - centre] if r3.refined else []
                bayer += [rb.center - centre] if rb.refined else []
            r3s, rbs = (np.sqrt(np.mean(np.square(e), axis=0)) for e in (three, bayer))
            print(f"| {blur:g} | {lo:.2f}-{hi:.2f} | {len(three)}/{per_bin} | {r3s[0]:.3f} / {r3s[1]:.3f} | "
                  f"{len(bayer)}/{per_bin} | {rbs[0]:.3f} / {rbs[1]:.3f} |")


def matched(dets: list[dict], label: dict) -> dict:
    """{marker id: (detection index, outline centroid (2,))} of the fully visible, legible markers
    (the detection of the marker's class nearest to its centroid, inside its box)."""
    out = {}
    for m in label["markers"]:
        if m.get("visibility") != 2 or not m.get("legible", True):
            continue
        truth = np.array(m["outline_centroid_px"])
        x0, y0, x1, y1 = m["bbox_px"]
        near = [i for i, d in enumerate(dets) if d["class_id"] == m["class_id"]
                and x0 <= d["center_px"][0] <= x1 and y0 <= d["center_px"][1] <= y1]
        if near:
            out[m["id"]] = (min(near, key=lambda i: np.hypot(*(np.array(dets[i]["center_px"]) - truth))), truth)
    return out


def detections(detector, ds, frames, effect: str) -> dict:
    """{frame id: detections} of ``effect``'s camera (told its pattern, no JPEG)."""
    out = {}
    from dockfactory.generator.exr import read_passes
    for fid in frames:
        cam = EFFECTS[effect][0](ds.labels[fid]["spec"]["index"])
        cfa = cam.cfa if cam is not None and cam.cfa != "none" else None
        image = delivered(read_passes(ds.root / "exr" / f"{fid}.exr").rgb, ds.labels[fid], effect)
        out[fid] = detector.detect(image, cfa=cfa, jpeg=False)
    return out


def centre_row(name: str, dets: dict, ds) -> str:
    """A table row: refined centres of ``dets`` ({frame id: detections}) against the labels."""
    errs = np.array([np.array(found[i]["center_px"]) - truth for fid, found in dets.items()
                     for i, truth in matched(found, ds.labels[fid]).values() if found[i]["refined"]])
    h = np.hypot(errs[:, 0], errs[:, 1])
    rx, ry = np.sqrt(np.mean(errs ** 2, axis=0))
    return f"| {name} | {len(errs)} | {rx:.3f} / {ry:.3f} | {np.median(h):.3f} | {int((h > 0.3).sum())} |"


def run_noise(detector, ds, frames) -> None:
    import dockfactory.core.camera_chain.emva as emva
    print("| camera, temporal noise | refined centres | RMS x / y px | median px | over 0.3 px |")
    print("| --- | --- | --- | --- | --- |")
    keep = emva._add_temporal_noise
    for noise in ("on", "off"):
        emva._add_temporal_noise = keep if noise == "on" else (lambda mu, sensor, rng: None)
        try:
            for effect in ("three-chip", "bayer-bilinear"):
                print(centre_row(f"{effect}, noise {noise}", detections(detector, ds, frames, effect), ds))
        finally:
            emva._add_temporal_noise = keep


def pose_rmse(ds, dets: dict, noise_px) -> str:
    from dockfactory.eval.pose_metrics import pose_error
    from dockfactory.eval.solve_frames import detection_arrays, docking_options, solve_frame
    errs = []
    for fid, d in dets.items():
        rec = solve_frame(ds.markers(), (639.5, 479.5), detection_arrays(d, 0.25), None, "pinhole",
                          docking_options(noise_px))[0]
        if rec["ok"]:
            e = pose_error(rec["pose"], ds.labels[fid]["pose_b_in_d"])
            errs.append([e[c] for c in COMPONENTS])
    r = np.sqrt(np.mean(np.square(errs), axis=0))
    return f"{len(errs)} | {r[0]:.3f} / {r[1]:.3f} / {r[2]:.4f}"


def substituted(bayer: dict, three: dict, ds, replace_if) -> dict:
    """``bayer`` with each matched detection for which ``replace_if(detection, truth)`` holds given
    the three-chip camera's centre (and refined flag) of the same marker."""
    out = copy.deepcopy(bayer)
    for fid, dets in out.items():
        ref = matched(three[fid], ds.labels[fid])
        for mid, (i, truth) in matched(dets, ds.labels[fid]).items():
            if mid in ref and replace_if(dets[i], truth):
                j = ref[mid][0]
                dets[i]["center_px"], dets[i]["refined"] = list(three[fid][j]["center_px"]), three[fid][j]["refined"]
    return out


def halved(bayer: dict, ds) -> dict:
    out = copy.deepcopy(bayer)
    for fid, dets in out.items():
        for i, truth in matched(dets, ds.labels[fid]).values():
            if dets[i]["refined"]:
                dets[i]["center_px"] = list(truth + 0.5 * (np.array(dets[i]["center_px"]) - truth))
    return out


def run_tail(detector, ds, frames) -> None:
    three, bayer = (detections(detector, ds, frames, e) for e in ("three-chip", "bayer-bilinear"))
    off = lambda limit: (lambda d, t: d["refined"] and np.hypot(*(np.array(d["center_px"]) - t)) > limit)  # noqa: E731
    rows = [("three-chip", three), ("Bayer bilinear", bayer),
            ("Bayer, refined centres > 0.3 px -> three-chip", substituted(bayer, three, ds, off(0.3))),
            ("Bayer, refined centres > 0.2 px -> three-chip", substituted(bayer, three, ds, off(0.2))),
            ("Bayer, unrefined -> three-chip", substituted(bayer, three, ds, lambda d, t: not d["refined"])),
            ("Bayer, every centre -> three-chip", substituted(bayer, three, ds, lambda d, t: True)),
            ("Bayer, refined centre errors halved", halved(bayer, ds))]
    print("| centres | frames solved | X / Y / alpha RMSE (mm, mm, deg) |")
    print("| --- | --- | --- |")
    for name, dets in rows:
        print(f"| {name} | {pose_rmse(ds, dets, detector.centre_noise_px)} |")


def box_and_ring(image: np.ndarray, dets: list[dict], label: dict) -> list[tuple[float, float, float, float]]:
    """(detector box width / label box width, the same for heights, median colour score in the
    label box's annulus at 1.08-1.22 radii, 25th percentile of the score within 0.5 radii) per
    fully visible marker with a detection of its class within 3 px."""
    from dockfactory.detector.centre import score_and_purity
    out = []
    for m, (i, truth) in ((m, matched(dets, label).get(m["id"], (None, None))) for m in label["markers"]):
        if i is None:
            continue
        x0, y0, x1, y1 = m["bbox_px"]
        bx = dets[i]["bbox_px"]
        cx, cy, hw, hh = (x0 + x1) / 2, (y0 + y1) / 2, (x1 - x0) / 2, (y1 - y0) / 2
        wx0, wy0 = int(max(cx - 1.4 * hw, 0)), int(max(cy - 1.4 * hh, 0))
        win = image[wy0:int(cy + 1.4 * hh) + 1, wx0:int(cx + 1.4 * hw) + 1]
        score, _ = score_and_purity(win, m["class_id"])
        ys, xs = np.mgrid[wy0:wy0 + win.shape[0], wx0:wx0 + win.shape[1]]
        rho = np.hypot((xs - cx) / hw, (ys - cy) / hh)
        out.append(((bx[2] - bx[0]) / (x1 - x0), (bx[3] - bx[1]) / (y1 - y0),
                    float(np.median(score[(rho >= 1.08) & (rho <= 1.22)])), float(np.percentile(score[rho <= 0.5], 25))))
    return out


def run_boxes(detector, ds, frames) -> None:
    from dockfactory.generator.exr import read_passes
    rows = []
    for fid in frames:
        image = delivered(read_passes(ds.root / "exr" / f"{fid}.exr").rgb, ds.labels[fid], "three-chip")
        rows += box_and_ring(image, detector.detect(image), ds.labels[fid])
    r = np.array(rows)
    print("| markers | box / label box, width / height: median (10th percentile) | ring score: median (90th pct) | disc score (median) |")
    print("| --- | --- | --- | --- |")
    print(f"| {len(r)} | {np.median(r[:, 0]):.3f} / {np.median(r[:, 1]):.3f} ({np.percentile(r[:, 0], 10):.3f} / "
          f"{np.percentile(r[:, 1], 10):.3f}) | {np.median(r[:, 2]):.3f} ({np.percentile(r[:, 2], 90):.3f}) | "
          f"{np.median(r[:, 3]):.3f} |")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("experiment", choices=("synthetic", "noise", "tail", "boxes"))
    p.add_argument("dataset", nargs="?")
    p.add_argument("--frames", type=int, default=0, help="first N test frames (0: all)")
    p.add_argument("--blur", default="0.3,0.6,1.2", help="synthetic: optical blur sigmas, px")
    p.add_argument("--weights", help="detector weights (default: the shipped ones)")
    args = p.parse_args(argv)
    if args.experiment == "synthetic":
        run_synthetic([float(b) for b in args.blur.split(",")])
        return 0
    if not args.dataset:
        p.error(f"{args.experiment} needs a DATASET")
    import torch
    torch.set_num_threads(2)
    from dockfactory.core.resources import shipped_weights
    from dockfactory.detector.infer import MarkerDetector
    from dockfactory.generator.datasets.reader import Dataset
    weights = args.weights or shipped_weights()
    ds = Dataset.open(args.dataset, full=False)
    frames = ds.frames("test")[: args.frames or None]
    print(f"{ds.config.dataset.name}@{ds.version_id}, {len(frames)} test frames")
    if args.experiment == "boxes":
        run_boxes(MarkerDetector(weights, refine=False), ds, frames)
        return 0
    (run_noise if args.experiment == "noise" else run_tail)(MarkerDetector(weights), ds, frames)
    return 0


if __name__ == "__main__":
    sys.exit(main())
