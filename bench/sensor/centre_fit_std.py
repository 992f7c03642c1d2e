"""Does the edge fit's own covariance tell a good centre from a bad one?

    python -m bench.sensor.centre_fit_std DATASET [DATASET ...] [--frames N] [--effects three-chip,bayer-bilinear]
                                   [--save-dir DIR]

For each delivered test frame (``sensor_effects.delivered``) the shipped detector's boxes are
refined as the shipped refinement does (told the Bayer pattern, no JPEG), and the final edge fit's
covariance is taken: (J J^T)^-1 r^T r / (n - p) of its (weighted) residuals, the centre block. Each
fully visible marker's centre error (against the label's outline centroid) is set beside that
std; the table gives, per bin of the fit's std, the RMS error per axis and the RMS of error / std.
A covariance that tells good from bad centres has an RMS error that grows with its std and an
RMS z that stays near a constant across the bins.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from bench.sensor import sensor_effects as se

from dockfactory.detector import centre, centre_joint
def _centre_cov(j: np.ndarray, r: np.ndarray) -> np.ndarray | None:
    """(2, 2) px^2 centre block of (J J^T)^-1 r^T r / (n - p), J (p, n)."""
    p, n = j.shape
    if n <= p:
        return None
    try:
        inv = np.linalg.inv(j @ j.T)
    except np.linalg.LinAlgError:
        return None
    return inv[:2, :2] * float(r @ r) / (n - p)


def three_chip_fit(win) -> tuple[np.ndarray, np.ndarray] | None:
    """(centre (2,), covariance (2, 2)) of ``centre.fit_disc_edge`` on ``win``."""
    m0 = centre._inverse_2x2(4 * win.cov)
    dx, dy = win.xs - win.centre[0], win.ys - win.centre[1]
    d0, _ = centre._sampson(dx, dy, m0[0, 0], m0[0, 1], m0[1, 1])
    band = ((d0 > -centre.FIT_BAND_IN_PX) & (d0 < centre.FIT_BAND_OUT_PX)
            & centre._usable(win.s, win.pur, win.rho, win.fg, win.bg))
    if band.sum() < 20:
        return None
    x, y, s = dx[band], dy[band], win.s[band].astype(np.float64)
    p0 = np.array([0.0, 0.0, m0[0, 0], m0[0, 1], m0[1, 1], np.log(0.2), win.fg, 0.0, 0.0, win.bg])
    p = centre._levenberg_marquardt(p0, x, y, s)
    if p is None or not centre._fit_accepted(p, m0):
        return None
    r, aux = centre._edge_residual(p, x, y, s)
    cov = _centre_cov(centre._edge_jacobian(p, x, y, aux), r)
    return None if cov is None else (win.centre + p[:2], cov, p[2:5])


def joint_fit(image, win, class_id: int, cfa: str) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(centre (2,), covariance (2, 2), ellipse M (3,)) of ``centre_joint.fit_disc_joint`` (reweighted)."""
    fitted = centre_joint.joint_fit(image, win, class_id, cfa)
    if fitted is None:
        return None
    p, data = fitted
    r, aux = centre_joint._residual(p, data)
    cov = _centre_cov(centre_joint._jacobian(p, data, aux), r)
    return None if cov is None else (win.centre + p[:2], cov, p[2:5])


def refine_with_cov(image, box, class_id: int, cfa: str | None):
    """(centre, covariance) of the shipped refinement's edge fit, or None when it is not refined."""
    first, win = centre._refine_once(image, box, class_id, 0.3, centre.EDGE_BIAS_PX)
    if not first.refined:
        return None
    second, win2 = centre._refine_once(image, first.box, class_id, 0.3, centre.EDGE_BIAS_PX)
    if second.refined:
        win = win2
    return three_chip_fit(win) if cfa is None else joint_fit(image, win, class_id, cfa)


def _disc_shape(m3) -> np.ndarray:
    """The disc-noise model's relative covariance T (2, 2) of the fitted ellipse e^T M e = 1."""
    from dockfactory.solver.disc_noise import noise_shapes
    m = np.array([[m3[0], m3[1]], [m3[1], m3[2]]])
    return noise_shapes(np.linalg.inv(m)[None])[0]


def likelihoods(rows: np.ndarray) -> str:
    """Gaussian log-likelihood per marker of the errors under each variance model, its one scale
    fitted by maximum likelihood: constant, the disc model, the fit's covariance, their product."""
    e = rows[:, 1:3]
    models = {"constant": np.ones_like(e), "disc": rows[:, 5:7] ** 2, "fit": rows[:, 3:5] ** 2,
              "fit x disc^0.5": rows[:, 3:5] ** 2 * rows[:, 5:7]}
    out = []
    for name, v in models.items():
        k2 = np.mean(e ** 2 / v)
        ll = -0.5 * np.mean(np.log(2 * np.pi * k2 * v) + e ** 2 / (k2 * v))
        out.append(f"{name} {ll:.3f} (scale {np.sqrt(k2):.3g})")
    return "; ".join(out)


def marker_rows(detector, ds, fid: str, effect: str) -> list[tuple]:
    """(class, dx, dy, std x, std y, corr) per fully visible marker refined with a covariance."""
    from dockfactory.generator.exr import read_passes
    label = ds.labels[fid]
    cam = se.EFFECTS[effect][0](label["spec"]["index"])
    cfa = cam.cfa if cam is not None and cam.cfa != "none" else None
    image = se.delivered(read_passes(ds.root / "exr" / f"{fid}.exr").rgb, label, effect)
    rows = []
    fitted = []
    for d in detector.detect(image):
        out = refine_with_cov(image, np.array(d["bbox_detector_px"]), d["class_id"], cfa)
        if out is not None:
            fitted.append({"class_id": d["class_id"], "center_px": out[0].tolist(), "cov": out[1], "m": out[2]})
    for m in label["markers"]:
        if m.get("visibility") != 2 or not m.get("legible", True):
            continue
        truth = np.array(m["outline_centroid_px"])
        near = [f for f in fitted if f["class_id"] == m["class_id"]
                and np.hypot(*(np.array(f["center_px"]) - truth)) < 2.0]
        if near:
            f = min(near, key=lambda f: np.hypot(*(np.array(f["center_px"]) - truth)))
            e, cv = np.array(f["center_px"]) - truth, f["cov"]
            t = _disc_shape(f["m"])
            rows.append((m["class_id"], e[0], e[1], np.sqrt(cv[0, 0]), np.sqrt(cv[1, 1]),
                         np.sqrt(t[0, 0]), np.sqrt(t[1, 1])))
    return rows


def table(rows: np.ndarray, name: str) -> list[str]:
    """Markdown rows: per quartile of the fit's std (mean of both axes), RMS error and RMS z."""
    s = np.sqrt(0.5 * (rows[:, 3] ** 2 + rows[:, 4] ** 2))
    edges = np.quantile(s, [0, 0.25, 0.5, 0.75, 0.9, 1.0])
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        k = rows[(s >= lo) & (s <= hi)]
        ex, ey = np.sqrt(np.mean(k[:, 1] ** 2)), np.sqrt(np.mean(k[:, 2] ** 2))
        zx, zy = np.sqrt(np.mean((k[:, 1] / k[:, 3]) ** 2)), np.sqrt(np.mean((k[:, 2] / k[:, 4]) ** 2))
        out.append(f"| {name} | {lo:.4f}-{hi:.4f} | {len(k)} | {ex:.3f} / {ey:.3f} | {zx:.1f} / {zy:.1f} |")
    c = np.corrcoef(np.log(s), np.log(np.hypot(rows[:, 1], rows[:, 2]) + 1e-4))[0, 1]
    out.append(f"| {name} | all (log-log corr {c:.2f}) | {len(rows)} | "
               f"{np.sqrt(np.mean(rows[:, 1] ** 2)):.3f} / {np.sqrt(np.mean(rows[:, 2] ** 2)):.3f} | |")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("datasets", nargs="+")
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--effects", default="three-chip,bayer-bilinear")
    ap.add_argument("--save-dir", help="folder for the per-marker rows (.npy), none by default")
    args = ap.parse_args(argv)
    from dockfactory.core.resources import shipped_weights
    from dockfactory.detector.infer import MarkerDetector
    from dockfactory.generator.datasets.reader import Dataset
    detector = MarkerDetector(shipped_weights(), refine=False)
    print("| dataset, effect | fit std px (bin) | markers | RMS error x / y px | RMS z x / y |")
    print("| --- | --- | --- | --- | --- |")
    for root in args.datasets:
        ds = Dataset.open(root, full=False)
        for effect in args.effects.split(","):
            rows = [r for fid in ds.frames("test")[:args.frames] for r in marker_rows(detector, ds, fid, effect)]
            arr = np.array(rows, dtype=float)
            if args.save_dir:
                np.save(Path(args.save_dir) / f"fitstd_{ds.config.dataset.name}_{effect}.npy", arr)
            print("\n".join(table(arr, f"{ds.config.dataset.name}, {effect}")), flush=True)
            print(likelihoods(arr), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
