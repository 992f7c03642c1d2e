"""The best any refinement can do through each camera: Cramer-Rao bounds of the markers' centres
and of the pose, side by side with the three-chip camera.

    python -m bench.sensor.centre_bound DATASET [DATASET ...] [--frames N] [--psf-px 0.5] [--out FILE.json]

For each fully visible, legible marker of the first N test frames (0: all):
- its disc's image: the ellipse of ``solver.disc_noise.disc_ellipses`` (exact geometry of the
  label) around the label's outline centroid; the edge a Gaussian step of width
  sqrt(psf^2 + 1/12) px (``--psf-px``: the optics and the renderer's pixel filter; 1/12: the
  pixel's own width), plus the effect's optical blur;
- the levels of disc and ring in each channel as the camera delivers them, and the noise of each
  channel at both: the frame (its noise-free render) exposed ``REPEATS`` times through its camera
  of ``sensor_effects.delivered`` with only the noise seed changed, read back in linear light at
  the channel's own sites (every pixel of a three-chip camera) inside half the disc's radius and
  over its ring (1.08-1.2 radii): level the mean, noise the pixels' variance between exposures
  (EMVA 1288 shot and dark noise, ADC; the frame's own auto exposure, vignetting and glare),
  measured, not modelled, with the 8-bit step as its floor; the unit's fixed patterns are the same
  in every exposure and left out. Between the two levels the variance is taken affine in the
  level (EMVA 1288);
- the Fisher information of the centre: sum over the channels' samples of
  (contrast * pdf(d / s) / s)^2 n n^T / variance, d the signed distance to the edge, n its
  normal, s the edge width. The bound is its inverse (px^2); the other parameters of the disc
  (levels, axes, edge width) are left known, so it is a lower bound; by the disc's symmetry they
  barely couple to its centre.

Cameras ("bound" rows): ``three-chip`` every channel at every pixel, ``three-chip-score`` the
class channel minus the mean of the other two at every pixel (the one image the shipped
three-chip refinement fits: ``detector.centre``), ``rggb`` every channel at its own sites (what
``detector.centre_joint`` fits), ``blur1.2`` the three-chip camera behind a 1.2 px optical blur
(and its ``-score`` variant). The pose bound of each frame (``solver.crb.crb_d_from_b``, joint
problem, the frame's exact geometry) takes every marker's own 2 x 2 centre bound. Printed: per
camera the RMS over frames of the pose bound (X, Y mm, alpha deg), its ratio to the three-chip
camera's, the median centre bound per axis (px) and the share of the information the other two
channels bring. JPEG is not in the table: its error is not Gaussian pixel noise.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from bench.sensor.sensor_effects import delivered

from dockfactory.core.camera_chain.cfa import channel_map
from dockfactory.detector.centre import CLASS_CHANNEL, _SRGB_TO_LINEAR
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.exr import read_passes
from dockfactory.solver.crb import crb_d_from_b
from dockfactory.solver.disc_noise import disc_ellipses
from dockfactory.solver.errors import SolverError
REPEATS = 4         # exposures of each frame whose spread gives the camera's temporal noise
BLUR_PX = 1.2
# camera name -> (effect of sensor_effects.delivered, Bayer pattern or None, optical blur px, score only)
CAMERAS = {
    "three-chip": ("three-chip", None, 0.0, False),
    "three-chip-score": ("three-chip", None, 0.0, True),
    "rggb": ("bayer-bilinear", "RGGB", 0.0, False),
    "blur1.2": ("three-chip", None, BLUR_PX, False),
    "blur1.2-score": ("three-chip", None, BLUR_PX, True),
}
POSE_KEYS = {"x": "x_mm", "y": "y_mm", "alpha": "alpha_deg"}


def disc_geometry(label: dict, markers: list[dict]) -> np.ndarray:
    """(n, 2, 2) px^2: each marker's disc image S = A A^T (eigenvalues: squared semi-axes)."""
    cam = np.asarray(label["camera"]["cam_from_d"], dtype=np.float64)
    centres = np.array([m["center_d_mm"] for m in markers], dtype=np.float64) @ cam[:3, :3].T + cam[:3, 3]
    normals = np.array([m["normal_d"] for m in markers], dtype=np.float64) @ cam[:3, :3].T
    return disc_ellipses(centres, normals, [m["diameter_mm"] for m in markers], float(label["camera"]["focal_px"]))


def region_pixels(centre: np.ndarray, s: np.ndarray, lo: float, hi: float, h: int, w: int):
    """(ys, xs) int arrays of the pixels of an (h, w) image whose ellipse radius
    sqrt((x - c)^T S^-1 (x - c)) about ``centre`` (2,) px lies in [lo, hi]."""
    half = int(np.ceil(np.sqrt(np.linalg.eigvalsh(s)[1]) * hi)) + 2
    x0, y0 = int(round(centre[0])) - half, int(round(centre[1])) - half
    ys, xs = np.mgrid[max(y0, 0):min(y0 + 2 * half + 1, h), max(x0, 0):min(x0 + 2 * half + 1, w)]
    d = np.stack([xs - centre[0], ys - centre[1]], -1)
    rho = np.sqrt(np.einsum("...i,ij,...j->...", d, np.linalg.inv(s), d))
    sel = (rho >= lo) & (rho <= hi)
    return ys[sel], xs[sel]


def region_levels(rgb: np.ndarray, label: dict, effect: str, cfa: str | None, centres: np.ndarray,
                  shapes: np.ndarray, repeats: int = REPEATS) -> np.ndarray:
    """(n, 2, 3, 2): per marker, its disc (within half its radius) and its ring (1.08-1.2 radii),
    per channel the (mean, temporal variance) the camera of ``effect`` delivers there, in linear
    light at the channel's own sites: ``repeats`` exposures of the frame ``rgb`` (the noise-free
    render) that differ only in their noise seed. The frame's auto exposure, vignetting and glare
    are the camera's own; the variance is the mean over the region of each pixel's sample variance
    over the exposures. The unit's fixed patterns (DSNU, PRNU) are the same in every exposure and
    left out: the bound is then lower still."""
    sensor = label["sampled"]["sensor"]
    shots = np.stack([_SRGB_TO_LINEAR[delivered(rgb, {**label, "sampled": {**label["sampled"], "sensor": {
        **sensor, "noise_seed": int(sensor["noise_seed"]) + k}}}, effect)] for k in range(repeats)])
    mean, var = shots.mean(axis=0), shots.var(axis=0, ddof=1)
    h, w = rgb.shape[:2]
    cmap = channel_map(cfa, h, w) if cfa else None
    out = np.full((len(centres), 2, 3, 2), np.nan)
    for i, (c, sh) in enumerate(zip(centres, shapes)):
        for j, (lo, hi) in enumerate(((0.0, 0.5), (1.08, 1.2))):
            ys, xs = region_pixels(c, sh, lo, hi, h, w)
            for ch in range(3):
                keep = np.ones(ys.shape, bool) if cmap is None else cmap[ys, xs] == ch
                if keep.any():
                    level = float(mean[ys[keep], xs[keep], ch].mean())
                    out[i, j, ch] = level, max(float(var[ys[keep], xs[keep], ch].mean()), quantisation_variance(level))
    return out


def quantisation_variance(level: float) -> float:
    """Variance (linear light^2) of the 8-bit sRGB rounding at linear ``level``: one code step
    mapped to linear, squared, over 12; the floor of a channel's noise where it clips (a clipped
    pixel varies not at all between exposures and tells the edge no more than one step)."""
    code = int(np.clip(np.searchsorted(_SRGB_TO_LINEAR, level), 1, 255))
    step = float(_SRGB_TO_LINEAR[code] - _SRGB_TO_LINEAR[code - 1])
    return step * step / 12.0


def centre_information(centre: np.ndarray, s: np.ndarray, width: float, contrast: np.ndarray,
                       var_ring: np.ndarray, var_disc: np.ndarray, sites) -> np.ndarray:
    """(2, 2) px^-2 Fisher information of the centre of the disc image ``S`` (2, 2) px^2 at
    ``centre`` (2,) px, Gaussian edge of std ``width`` px. Per channel (``contrast`` (c,) disc
    minus ring level, noise variances at the ring and the disc level (c,)), over its samples:
    ``sites(channel, xs, ys)`` -> (h, w) bool (None: every pixel)."""
    m = np.linalg.inv(s)
    half = int(np.ceil(np.sqrt(np.linalg.eigvalsh(s)[1]) + 5 * width)) + 2
    ys, xs = np.mgrid[-half:half + 1, -half:half + 1] + np.round(centre[::-1]).astype(int)[:, None, None]
    dx, dy = xs - centre[0], ys - centre[1]
    gx, gy = m[0, 0] * dx + m[0, 1] * dy, m[0, 1] * dx + m[1, 1] * dy
    gn = np.hypot(gx, gy) + 1e-12
    d = (dx * gx + dy * gy - 1.0) / (2.0 * gn)                  # Sampson distance, > 0 outside
    inside = 1.0 / (1.0 + np.exp(np.clip(1.702 * d / width, -60, 60)))   # logistic ~ Gaussian CDF: the variance's mix
    pdf = np.exp(-0.5 * (d / width) ** 2) / (width * np.sqrt(2 * np.pi))
    nx, ny = gx / gn, gy / gn
    info = np.zeros((2, 2))
    for ch in range(len(contrast)):
        keep = np.ones_like(d, dtype=bool) if sites is None else sites(ch, xs, ys)
        var = var_ring[ch] + (var_disc[ch] - var_ring[ch]) * inside
        g2 = (contrast[ch] * pdf) ** 2 / np.maximum(var, 1e-12)
        info += np.array([[np.sum((g2 * nx * nx)[keep]), np.sum((g2 * nx * ny)[keep])],
                          [np.sum((g2 * nx * ny)[keep]), np.sum((g2 * ny * ny)[keep])]])
    return info


def marker_bounds(label: dict, rgb: np.ndarray, markers: list[dict], psf_px: float) -> dict:
    """{camera: ((n, 2, 2) px^2 centre bounds, (n,) share of the information from the channels
    other than the class's)} of ``markers`` (label markers) in the frame of noise-free render
    ``rgb`` (H, W, 3) linear."""
    shapes = disc_geometry(label, markers)
    centres = np.array([m["outline_centroid_px"] for m in markers], dtype=np.float64)
    h, w = rgb.shape[:2]
    levels, out = {}, {}
    for name, (effect, cfa, blur, score) in CAMERAS.items():
        if (effect, cfa) not in levels:
            levels[effect, cfa] = region_levels(rgb, label, effect, cfa, centres, shapes)
        st = levels[effect, cfa]
        cmap = channel_map(cfa, h, w) if cfa else None
        sites = None if cmap is None else (
            lambda ch, xs, ys, cm=cmap: (cm[np.clip(ys, 0, h - 1), np.clip(xs, 0, w - 1)] == ch))
        width = float(np.sqrt(psf_px ** 2 + 1.0 / 12.0 + blur ** 2))
        covs, share = [], []
        for i, m in enumerate(markers):
            d_st, r_st = st[i, 0], st[i, 1]
            contrast, v_ring, v_disc = d_st[:, 0] - r_st[:, 0], r_st[:, 1], d_st[:, 1]
            own = CLASS_CHANNEL[m["class_id"]]
            if score:
                wts = np.full(3, -0.5)
                wts[own] = 1.0
                contrast, v_ring, v_disc = (np.array([wts @ contrast]), np.array([wts ** 2 @ v_ring]),
                                            np.array([wts ** 2 @ v_disc]))
                own_sites = sites
            else:
                own_sites = (lambda ch, xs, ys, o=own, s0=sites: (ch == o) & (np.ones(xs.shape, bool) if s0 is None else s0(ch, xs, ys)))
            info = centre_information(centres[i], shapes[i], width, contrast, v_ring, v_disc, sites)
            info_own = centre_information(centres[i], shapes[i], width, contrast, v_ring, v_disc, own_sites)
            covs.append(np.linalg.inv(info))
            share.append(1.0 - np.trace(info_own) / np.trace(info) if not score else 0.0)
        out[name] = (np.array(covs), np.array(share))
    return out


def pose_bound(label: dict, markers: list[dict], covs: np.ndarray) -> dict | None:
    """{x, y, alpha: std} of the pose (mm, deg) under each marker's own centre bound ``covs``
    (n, 2, 2) px^2 (joint problem, the frame's exact geometry); None under 4 markers a section or
    a degenerate geometry."""
    idx = {s: [i for i, m in enumerate(markers) if m["section"] == s] for s in "AB"}
    if min(len(v) for v in idx.values()) < 4:
        return None
    pa, pb = (np.array([markers[i]["center_section_mm"] for i in idx[s]]) for s in "AB")
    cam_from_d = np.asarray(label["camera"]["cam_from_d"], dtype=np.float64)
    cam_from_b = cam_from_d @ np.asarray(label["d_from_b"], dtype=np.float64)
    shapes = (covs[idx["A"]], covs[idx["B"]])
    sigma = float(np.sqrt(np.trace(covs, axis1=1, axis2=2).mean() / 2.0))
    try:
        b = crb_d_from_b(pa, cam_from_d, pb, cam_from_b, label["camera"]["focal_px"],
                         label["camera"]["principal_point"], sigma, noise_shapes=shapes)
    except SolverError:
        return None
    return {c: b.std[POSE_KEYS[c]] for c in POSE_KEYS}


def dataset_bounds(ds: Dataset, frames: list[str], psf_px: float) -> dict:
    """Per camera: RMS over frames of the pose bound, median centre bound per axis (px), median
    share of the other channels' information, frames bounded."""
    poses, centres, shares = {k: [] for k in CAMERAS}, {k: [] for k in CAMERAS}, {k: [] for k in CAMERAS}
    for fid in frames:
        label = ds.labels[fid]
        markers = [m for m in label["markers"] if m.get("visibility") == 2 and m.get("legible", True)]
        bounds = marker_bounds(label, read_passes(ds.root / "exr" / f"{fid}.exr").rgb, markers, psf_px)
        for name, (covs, share) in bounds.items():
            pb = pose_bound(label, markers, covs)
            if pb is not None:
                poses[name].append([pb[c] for c in POSE_KEYS])
            centres[name] += np.sqrt(np.stack([covs[:, 0, 0], covs[:, 1, 1]], 1)).tolist()
            shares[name] += share.tolist()
    return {name: {"frames": len(poses[name]),
                   **{f"bound_{c}": float(np.sqrt(np.mean(np.square(poses[name]), axis=0))[k])
                      for k, c in enumerate(POSE_KEYS)},
                   "centre_bound_px": np.median(centres[name], axis=0).tolist(),
                   "other_channels_share": float(np.median(shares[name]))} for name in CAMERAS}


def table(results: dict) -> str:
    """Markdown: per dataset and camera, pose bounds (ratio to three-chip and to its score)."""
    lines = ["| dataset | camera | frames | X mm (x 3-chip, x score) | Y mm | alpha deg | centre bound x / y px | "
             "other channels' share |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for dname, cams in results.items():
        ref, score = cams["three-chip"], cams["three-chip-score"]
        for name, r in cams.items():
            cells = [f"{r[f'bound_{c}']:.4f} ({r[f'bound_{c}'] / ref[f'bound_{c}']:.2f}, "
                     f"{r[f'bound_{c}'] / score[f'bound_{c}']:.2f})" for c in POSE_KEYS]
            lines.append(f"| {dname} | {name} | {r['frames']} | " + " | ".join(cells) +
                         f" | {r['centre_bound_px'][0]:.4f} / {r['centre_bound_px'][1]:.4f} | "
                         f"{r['other_channels_share']:.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("datasets", nargs="+")
    p.add_argument("--frames", type=int, default=0, help="first N test frames (0: all)")
    p.add_argument("--psf-px", type=float, default=0.5, help="edge blur std of the optics and pixel filter, px")
    p.add_argument("--out", help="write the figures as JSON here")
    args = p.parse_args(argv)
    if not args.psf_px >= 0:
        p.error(f"--psf-px must be >= 0, got {args.psf_px}")
    results = {}
    for path in args.datasets:
        ds = Dataset.open(path, full=False)
        frames = ds.frames("test")[: args.frames or None]
        results[f"{ds.config.dataset.name}@{ds.version_id}"] = dataset_bounds(ds, frames, args.psf_px)
    print(table(results))
    if args.out:
        Path(args.out).write_text(json.dumps({"psf_px": args.psf_px, "datasets": results}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
