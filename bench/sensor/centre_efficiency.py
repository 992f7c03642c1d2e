"""How close the shipped refinements come to the Cramer-Rao bound when the camera's noise is the
only error: synthetic discs, three-chip against RGGB, measured beside ``centre_bound``'s bound.

    python -m bench.sensor.centre_efficiency [--trials 200] [--noise 0.004] [--seed 5]

A red disc (linear (0.30, 0.02, 0.02)) on a dark ring (grey 0.02, to 1.25 radii) on grey paint
(0.25), drawn with exact pixel coverage (8 x 8 supersampling) and an optical blur of 0.5 px: the
edge model of ``centre_bound`` at ``--psf-px 0.5``. Two shapes: a circle of radius 8 px and an
ellipse of 10 x 5 px (a foreshortened disc). Each trial puts the disc at a random sub-pixel
position and adds Gaussian noise of std ``--noise`` (linear light) to every value the camera
samples: all three channels of a three-chip camera, one per pixel behind an RGGB filter (then the
bilinear demosaic); both then 8-bit sRGB. Refinements: ``detector.centre.refine_centre`` (the
three-chip camera's colour-score fit) and ``detector.centre_camera.refine_centre_camera`` told
RGGB (the joint fit at the sensor's own samples), from the outline box scaled by 0.97 (the
shipped detector's boxes run 3-5 % inside the outline). Printed per shape and camera: the RMS
error per axis over the trials, the bound (the mean information over the trials' positions,
inverted), their ratio (the refinement's efficiency: >= 1 for any unbiased refinement), and the
RGGB / three-chip ratios measured and bounded.
"""
from __future__ import annotations

import argparse
import sys

import cv2
import numpy as np

from bench.sensor.centre_bound import centre_information

from dockfactory.core.camera_chain.cfa import channel_map, mosaic
from dockfactory.core.camera_chain.demosaic import demosaic
from dockfactory.core.camera_chain.isp import tone_map
from dockfactory.detector.centre import refine_centre
from dockfactory.detector.centre_camera import refine_centre_camera
DISC, RING, PAINT = (0.30, 0.02, 0.02), 0.02, 0.25
PSF_PX, SIZE, SS = 0.5, 64, 8
SHAPES = {"circle r 8 px": (8.0, 8.0), "ellipse 10 x 5 px": (10.0, 5.0)}
BOX_SCALE = 0.97


def disc_image(cx: float, cy: float, a: float, b: float) -> np.ndarray:
    """(SIZE, SIZE, 3) float32 linear: the disc (semi-axes a along x, b along y px) in its ring on
    paint, integrated over each pixel, blurred by PSF_PX."""
    ys, xs = np.mgrid[0:SIZE * SS, 0:SIZE * SS]
    rho = np.hypot(((xs + 0.5) / SS - 0.5 - cx) / a, ((ys + 0.5) / SS - 0.5 - cy) / b)
    img = np.full((SIZE * SS, SIZE * SS, 3), PAINT, np.float32)
    img[rho < 1.25] = RING
    img[rho < 1.0] = DISC
    return cv2.GaussianBlur(img.reshape(SIZE, SS, SIZE, SS, 3).mean(axis=(1, 3)), (0, 0), PSF_PX)


def srgb8(x: np.ndarray) -> np.ndarray:
    """Linear (H, W, 3) -> the camera ISP's 8-bit sRGB (``core.isp.tone_map``)."""
    return tone_map(np.asarray(x, dtype=np.float32), "srgb")


def trial_errors(a: float, b: float, trials: int, noise: float, rng: np.random.Generator):
    """({camera: (trials, 2) centre errors px}, [(cx, cy)] positions) over ``trials`` noisy discs."""
    errs, where = {"three-chip": [], "rggb": []}, []
    for _ in range(trials):
        cx, cy = SIZE / 2 + rng.uniform(-1, 1), SIZE / 2 + rng.uniform(-1, 1)
        lin = disc_image(cx, cy, a, b)
        box = np.array([cx - BOX_SCALE * a, cy - BOX_SCALE * b, cx + BOX_SCALE * a, cy + BOX_SCALE * b])
        three = srgb8(lin + rng.normal(0, noise, lin.shape).astype(np.float32))
        raw = mosaic(lin, "RGGB") + rng.normal(0, noise, lin.shape[:2]).astype(np.float32)
        bayer = srgb8(demosaic(np.clip(raw, 0, 1), "RGGB", "bilinear"))
        errs["three-chip"].append(refine_centre(three, box, 0).center - (cx, cy))
        errs["rggb"].append(refine_centre_camera(bayer, box, 0, "RGGB").center - (cx, cy))
        where.append((cx, cy))
    return {k: np.array(v) for k, v in errs.items()}, where


def bound_std(a: float, b: float, where, noise: float) -> dict:
    """{camera: (2,) px} the bound's std per axis, from the information averaged over ``where``."""
    width = float(np.sqrt(PSF_PX ** 2 + 1.0 / 12.0))
    contrast, var = np.array(DISC) - RING, np.full(3, noise ** 2)
    score = np.array([1.0, -0.5, -0.5])
    cmap = channel_map("RGGB", SIZE, SIZE)
    sites = {"three-chip": None, "rggb": lambda ch, xs, ys: cmap[np.clip(ys, 0, SIZE - 1), np.clip(xs, 0, SIZE - 1)] == ch}
    s = np.diag([a * a, b * b])
    out = {}
    for name, st in sites.items():
        info = np.mean([centre_information(np.array(c), s, width, contrast, var, var, st) for c in where], axis=0)
        out[name] = np.sqrt(np.diag(np.linalg.inv(info)))
    sc = np.array([score @ contrast])
    sv = np.array([score ** 2 @ var])
    info = np.mean([centre_information(np.array(c), s, width, sc, sv, sv, None) for c in where], axis=0)
    out["three-chip-score"] = np.sqrt(np.diag(np.linalg.inv(info)))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--trials", type=int, default=200)
    p.add_argument("--noise", type=float, default=0.004, help="std of the camera's noise per sample, linear light")
    p.add_argument("--seed", type=int, default=5)
    args = p.parse_args(argv)
    if args.trials < 10 or not args.noise > 0:
        p.error("--trials must be >= 10 and --noise > 0")
    rng = np.random.default_rng(args.seed)
    print("| shape | camera | RMS x / y px | bound x / y px | efficiency x / y |")
    print("| --- | --- | --- | --- | --- |")
    for shape, (a, b) in SHAPES.items():
        errs, where = trial_errors(a, b, args.trials, args.noise, rng)
        bound = bound_std(a, b, where, args.noise)
        rms = {k: np.sqrt((v ** 2).mean(axis=0)) for k, v in errs.items()}
        for cam, ref in (("three-chip", "three-chip-score"), ("rggb", "rggb")):
            eff = rms[cam] / bound[ref]
            print(f"| {shape} | {cam} (bound: {ref}) | {rms[cam][0]:.4f} / {rms[cam][1]:.4f} | "
                  f"{bound[ref][0]:.4f} / {bound[ref][1]:.4f} | {eff[0]:.2f} / {eff[1]:.2f} |")
        m, o, sc = rms["rggb"] / rms["three-chip"], bound["rggb"] / bound["three-chip"], bound["rggb"] / bound["three-chip-score"]
        print(f"| {shape} | rggb / three-chip | measured {m[0]:.2f} / {m[1]:.2f} | bound (efficient) {o[0]:.2f} / "
              f"{o[1]:.2f} | bound (score fit) {sc[0]:.2f} / {sc[1]:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
