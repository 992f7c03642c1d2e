"""The tolerance envelope: which uncalibrated cameras pass.

For the dataset's own test geometry (each test frame's true camera pose, focal lengths fx and fy
and visible markers), the marker centres are projected through hypothetical real cameras: a
principal point ``m`` px off the image centre (in each of ``directions`` directions; the worst
direction counts) and radial distortion ``k1``, plus Gaussian centre noise (the measured detector
noise, or a given one). Each frame is then solved the way the paper's method does (pinhole, principal point
at the image centre, identities known) and each gated component's RMSE is computed per (m, k1),
in the gate's statistic under the Gaussian model (eval.gate_statistic ``from_rms``). The envelope
is where every gated statistic passes: the cameras that need no calibration for these
tolerances; outside it a camera needs self-calibration.

Correspondences are the projected marker centres (not disc centroids), so the solver's
eccentricity correction plays no part: the sweep isolates the camera model.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dockfactory.eval.gate_statistic import gate_statistic
from dockfactory.core.distortion import distort_normalized
from dockfactory.core.geometry import transform_points
from dockfactory.eval.acceptance import AcceptanceSpec
from dockfactory.eval.pixel_aspect import label_pixel_aspect
from dockfactory.eval.pose_metrics import pose_error
from dockfactory.generator.random_draws import rng_for
from dockfactory.solver import SolverError, solve_docking

ENVELOPE_STREAM = 103   # rng stream of the sweep's centre noise (generator.sampler.rng_for)


@dataclass(frozen=True)
class EnvelopeGrid:
    pp_offsets_px: tuple = (0.0, 10.0, 20.0, 30.0, 40.0, 50.0)
    k1: tuple = (-0.2, -0.15, -0.1, -0.05, 0.0, 0.05, 0.1)
    directions: int = 4          # principal point offsets along 45, 135, 225, 315 deg (+ rotations)
    max_frames: int = 60         # test frames used (evenly spread over the split)


def _frame_geometry(label: dict) -> dict | None:
    """What the sweep needs of a test frame: ids and camera-frame centres of its fully visible,
    legible markers (None when a section has fewer than 4), focal lengths (fx, fy: K's; a camera
    with non-square pixels keeps them, which the single-focal solve then carries as a camera
    without calibration would), pixel aspect, image centre, truth."""
    vis = [m for m in label["markers"] if m.get("visibility") == 2 and m.get("legible", True)]
    if min(sum(m["section"] == s for m in vis) for s in ("A", "B")) < 4:
        return None
    pts = transform_points(np.array(label["camera"]["cam_from_d"]), np.array([m["center_d_mm"] for m in vis]))
    w, h = label["image"]["width"], label["image"]["height"]
    fx, aspect = label["camera"]["focal_px"], label_pixel_aspect(label)
    return {"ids": [m["id"] for m in vis], "xy": pts[:, :2] / pts[:, 2:3], "focal": np.array([fx, fx * aspect]),
            "aspect": aspect, "centre": np.array([(w - 1) / 2.0, (h - 1) / 2.0]), "truth": label["pose_b_in_d"],
            "index": label["spec"]["index"]}


def _errors_at(frames, markers, offset, k1: float, sigma_px: float, seed: int, cell: int) -> list[dict]:
    """Pose errors of every frame solved as the paper does, for one camera (offset, k1)."""
    out = []
    for f in frames:
        uv = distort_normalized(f["xy"], (k1,)) * f["focal"] + f["centre"] + offset
        rng = rng_for(seed, ENVELOPE_STREAM, f["index"] * 1000 + cell)
        uv = uv + rng.normal(0.0, sigma_px, uv.shape)
        try:
            res = solve_docking(markers, f["centre"], correspondences=(f["ids"], uv), sigma_px=sigma_px or None)
        except SolverError:
            out.append(None)
            continue
        out.append(pose_error(res.pose(), f["truth"]))
    return out


def _rmse(errors: list, comp: str) -> float:
    """RMSE of one component; a frame without a pose makes the statistic fail (inf)."""
    if any(e is None for e in errors):
        return float("inf")
    return float(np.sqrt(np.mean([e[comp] ** 2 for e in errors])))


def camera_envelope(ds, spec: AcceptanceSpec, sigma_px: float, grid: EnvelopeGrid = EnvelopeGrid()) -> dict:
    """The sweep over ``grid`` on the test frames of the opened dataset ``ds`` (module docstring):
    per gated localization component, the RMSE (worst direction) on the (pp offset, k1) grid, the
    thresholds, and the pass map."""
    labels = ds.labels_of("test")
    pick = np.unique(np.linspace(0, len(labels) - 1, min(grid.max_frames, len(labels))).round().astype(int))
    frames = [g for g in (_frame_geometry(labels[i]) for i in pick) if g is not None]
    gated = spec.localization.thresholds()
    markers = ds.markers()
    angles = np.deg2rad(45.0 + 360.0 * np.arange(grid.directions) / grid.directions)
    rmse = {c: np.zeros((len(grid.pp_offsets_px), len(grid.k1))) for c in gated}
    cell = 0
    for i, m in enumerate(grid.pp_offsets_px):
        for j, k1 in enumerate(grid.k1):
            dirs = angles if m > 0 else angles[:1]
            for a in dirs:
                cell += 1
                errs = _errors_at(frames, markers, m * np.array([np.cos(a), np.sin(a)]), k1, sigma_px,
                                  ds.config.dataset.seed, cell)
                for c in gated:
                    rmse[c][i, j] = max(rmse[c][i, j], _rmse(errs, c))
    return _envelope_record(grid, frames, sigma_px, spec, rmse)


def _envelope_record(grid: EnvelopeGrid, frames, sigma_px: float, spec: AcceptanceSpec, rmse: dict) -> dict:
    """The envelope's record: ``rmse`` {component: (offsets, k1) RMSE grid} in the gate's statistic
    (its ``from_rms``) against the thresholds, the pass map and the verdict sentence."""
    gated = spec.localization.thresholds()
    statistic = spec.localization.statistic
    value = {c: gate_statistic(statistic).from_rms(r) for c, r in rmse.items()}
    passes = np.ones((len(grid.pp_offsets_px), len(grid.k1)), dtype=bool)
    for c, thr in gated.items():
        passes &= value[c] <= thr
    aspect, note = _aspect_note(frames)
    return {"pp_offsets_px": list(grid.pp_offsets_px), "k1": list(grid.k1), "directions": grid.directions,
            "frames": len(frames), "sigma_px": sigma_px, "statistic": statistic,
            "thresholds": dict(gated), "values": {c: np.where(np.isfinite(v), v, None).tolist() for c, v in value.items()},
            "passes": passes.tolist(), **aspect, "verdict": envelope_verdict(grid, passes) + note}


def _aspect_note(frames) -> tuple[dict, str]:
    """({"pixel_aspect": [lowest, highest]}, a clause for the verdict) of frames whose cameras have
    non-square pixels; ({}, "") when every one is square."""
    lo, hi = min((f["aspect"] for f in frames), default=1.0), max((f["aspect"] for f in frames), default=1.0)
    if lo == hi == 1.0:
        return {}, ""
    told = f"{lo:.4g}" if lo == hi else f"{lo:.4g}-{hi:.4g}"
    return {"pixel_aspect": [lo, hi]}, f" (every camera with the dataset's pixel aspect fy / fx, {told})"


def envelope_verdict(grid: EnvelopeGrid, passes: np.ndarray) -> str:
    """One sentence: the largest principal-point offset and the k1 range that pass together."""
    ok_k1 = [k for j, k in enumerate(grid.k1) if passes[0, j]]
    if not ok_k1:
        return "no camera of the grid passes, not even an ideal one: the tolerances are out of reach"
    k0 = grid.k1.index(0.0) if 0.0 in grid.k1 else None
    pp_ok = [m for i, m in enumerate(grid.pp_offsets_px) if k0 is not None and passes[i, k0]]
    rows = [i for i in range(len(grid.pp_offsets_px)) if passes[i].any()]
    return (f"without calibration, cameras pass with a principal point up to {max(pp_ok) if pp_ok else 0:g} px "
            f"off centre (k1 = 0) and k1 in [{min(ok_k1):g}, {max(ok_k1):g}] (principal point centred); "
            f"{int(passes.sum())} of {passes.size} grid cells pass (worst of {grid.directions} directions), "
            f"up to {grid.pp_offsets_px[max(rows)]:g} px with some k1")
