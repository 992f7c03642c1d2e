"""Uncertainty budget of one solved pose (GUM, JCGM 100): what each input contributes to the
standard uncertainty of X, Y, Z (mm) and alpha, beta, gamma (deg), their combination and the
expanded uncertainty U = k u (k = 2).

Combined u_c = sqrt(sum of the squares) (the inputs are independent), U = k u_c.

Why and how: docs/acceptance.md, "The uncertainty budget".
"""
from __future__ import annotations

import math

import numpy as np

from dockfactory.core.layout import Marker
from dockfactory.core.names import POSE_NAMES
from dockfactory.eval.conformity import COVERAGE_K
from dockfactory.solver.camera_models import MODELS, Intrinsics
from dockfactory.solver.refine import Block, d_from_b_jacobian, inverse_spd, stack_blocks

TERMS = ("centre_noise", "intrinsics", "model_error", "section_shift", "layout", "detector_bias")
TERM_LABELS = {"centre_noise": "centre noise", "intrinsics": "intrinsics",
               "model_error": "camera model (unestimated intrinsics)",
               "section_shift": "section offset of the centres",
               "layout": "marker layout", "detector_bias": "detector bias"}


class Sensitivity:
    """The solved frame's Jacobian J (2N, 12 + 1 + e), its section of every row's point, the
    d_from_b propagation ``prop`` (6, 12) and the section rotations."""

    def __init__(self, points_a, points_b, cam_from_a, cam_from_b, intr: Intrinsics, model):
        poses = ((cam_from_a[:3, :3], cam_from_a[:3, 3]), (cam_from_b[:3, :3], cam_from_b[:3, 3]))
        blocks = (Block(points_a, np.zeros((len(points_a), 2)), 0), Block(points_b, np.zeros((len(points_b), 2)), 1))
        _, self.jac, _ = stack_blocks(blocks, poses, intr, model)
        self.n_a = len(points_a)
        self.prop = d_from_b_jacobian(*poses[0], *poses[1])
        info = self.jac.T @ self.jac
        self.cov = inverse_spd(info)               # (J^T J)^-1, unit pixel noise
        self.cov_cond = inverse_spd(info[:12, :12])
        self.info_pi = info[:12, 12:]

    def pose_cov(self, params_cov: np.ndarray) -> np.ndarray:
        """(6, 6) over POSE_NAMES of a (12 + ..., 12 + ...) parameter covariance."""
        return self.prop @ params_cov[:12, :12] @ self.prop.T

    def intrinsics_share(self) -> np.ndarray:
        """(6,) the share of each component's variance that the intrinsics' estimation adds."""
        marg = np.diag(self.pose_cov(self.cov))
        cond = np.diag(self.pose_cov(self.cov_cond))
        with np.errstate(invalid="ignore", divide="ignore"):
            share = 1.0 - cond / marg
        return np.clip(np.nan_to_num(share, nan=0.0), 0.0, 1.0)

    def intrinsics_var(self, intr_var: np.ndarray) -> np.ndarray:
        """(6,) pose variance from independent intrinsics variances (1 + e,) held fixed in the
        fit (the pose follows them: S = -(J_p^T J_p)^-1 J_p^T J_i)."""
        s = self.prop @ (-self.cov_cond @ self.info_pi)
        return (s ** 2) @ intr_var

    def _layout_meat(self, sigma_mm: np.ndarray):
        """(J rows as (n, 2, p), per-point pixel covariance of the layout (n, 2, 2), the meat
        sum_i J_i^T S_i J_i) for marker displacements of ``sigma_mm`` (N,) per coordinate."""
        n = self.jac.shape[0] // 2
        jr = self.jac.reshape(n, 2, -1)
        t_cols = np.where(np.arange(n)[:, None] < self.n_a, np.arange(3, 6), np.arange(9, 12))
        t = np.take_along_axis(jr, np.broadcast_to(t_cols[:, None, :], (n, 2, 3)), axis=2)   # (n, 2, 3)
        shape = np.einsum("nak,nbk->nab", t, t) * (np.asarray(sigma_mm, dtype=float) ** 2)[:, None, None]
        return jr, shape, np.einsum("nap,nab,nbq->pq", jr, shape, jr)

    def layout_var(self, sigma_mm: np.ndarray) -> np.ndarray:
        """(6,) pose variance from independent marker displacements of ``sigma_mm`` (N,) per
        coordinate (rows of J in point order: A's points, then B's)."""
        _, _, meat = self._layout_meat(sigma_mm)
        return np.diag(self.pose_cov(self.cov @ meat @ self.cov))

    def layout_residual_px2(self, sigma_mm: np.ndarray) -> float:
        """What the layout's displacements add to a noise variance estimated from the residuals,
        px^2 per coordinate: tr((I - P) S) / (m - p), P = J (J^T J)^-1 J^T, S the layout's pixel
        covariance (the part of the displacements the pose cannot absorb shows as misfit)."""
        jr, shape, meat = self._layout_meat(sigma_mm)
        dof = self.jac.shape[0] - self.jac.shape[1]
        if dof <= 0:
            return 0.0
        return max(0.0, float(np.trace(shape, axis1=1, axis2=2).sum() - np.sum(self.cov * meat)) / dof)

    def bias_var(self, bias_px) -> np.ndarray:
        """(6,) pose variance from a common shift of every centre by (bx, by) px, each axis an
        independent standard uncertainty."""
        n = self.jac.shape[0] // 2
        out = np.zeros(6)
        for axis, b in enumerate(bias_px):
            shift = np.zeros((n, 2))
            shift[:, axis] = b
            d = -self.cov @ (self.jac.T @ shift.reshape(-1))
            out += (self.prop @ d[:12]) ** 2
        return out


def record_geometry(record: dict, markers) -> tuple:
    """(points_a (Na, 3), points_b (Nb, 3), used ids in that order, cam_from_a, cam_from_b,
    Intrinsics, IntrinsicsModel) of a solved pose record (eval.solve_frames.pose_record with
    ``image_size``; a pinhole record's principal point is the one it was solved about: its
    ``calibration``'s (measure --calibration), else the image centre)."""
    by_id = {m.id: m for m in markers}
    ids = [i for s in ("A", "B") for i in record["marker_ids"] if by_id[i].section == s]
    pts = {s: np.array([by_id[i].center_mm for i in ids if by_id[i].section == s], dtype=float).reshape(-1, 3)
           for s in ("A", "B")}
    cam_from_a = np.array(record["cam_from_a"], dtype=float)
    cam_from_b = cam_from_a @ np.array(record["d_from_b"], dtype=float)
    solved_pp = _solved_principal_point(record)
    intr_rec = record.get("intrinsics") or solved_pp
    coeffs = [intr_rec.get(k, 0.0) for k in ("k1", "k2", "p1", "p2")] + [0.0]
    intr = Intrinsics(float(record["focal_px"]), np.array([intr_rec["cx"], intr_rec["cy"]]), np.array(coeffs))
    return pts["A"], pts["B"], ids, cam_from_a, cam_from_b, intr, MODELS[record.get("camera_model", "pinhole")]


def _solved_principal_point(record: dict) -> dict:
    """{"cx", "cy"} px: the principal point a pinhole record was solved about: its calibration's,
    else the centre of its ``image_size``."""
    w, h = record["image_size"]
    cal = record.get("calibration")
    if cal is not None:
        cx, cy = cal["principal_point"]
        return {"cx": float(cx), "cy": float(cy)}
    return {"cx": (w - 1) / 2.0, "cy": (h - 1) / 2.0}


def solved_bias_px(record: dict, bias_px):
    """(x, y) px: the detector's centre offset ``bias_px`` (x, y; delivered pixels) in the pixels
    the record was solved in. A calibrated record's centres (its ``calibration``: measure
    --calibration) were taken to the ideal square camera at f = sqrt(fx fy)
    (core.calibration_files.ideal_pixels), which scales each axis by f / fx and f / fy (the lens's
    distortion, which varies over the image, left out); ``bias_px`` itself otherwise (None: None)."""
    cal = record.get("calibration")
    if bias_px is None or cal is None:
        return bias_px
    f = math.sqrt(float(cal["fx"]) * float(cal["fy"]))
    return (float(bias_px[0]) * f / float(cal["fx"]), float(bias_px[1]) * f / float(cal["fy"]))


def section_shift_variance(record: dict) -> np.ndarray | None:
    """(6,) the pose variances a common offset of each section's centres added to a record's
    covariance (``section_shift_variance``, solver.section_shift), or None when none was."""
    var = record.get("section_shift_variance")
    return None if var is None else np.maximum(np.array(var, dtype=float), 0.0)


def model_error_variance(record: dict) -> np.ndarray | None:
    """(6,) the pose variances the marginalised camera-model error added to a record's covariance,
    or None when nothing was marginalised (or the record predates ``pose_variance``)."""
    check = record.get("model_check") or {}
    var = check.get("pose_variance")
    if not check.get("marginalised") or var is None:
        return None
    return np.maximum(np.array(var, dtype=float), 0.0)


def _split_off(part, reported: np.ndarray):
    """(``part`` capped at ``reported``, what is left of ``reported``); (None, ``reported``)
    without a part."""
    if part is None:
        return None, reported
    part = np.minimum(part, reported)
    return part, reported - part


def pose_budget(record: dict, markers: tuple[Marker, ...], sigma_mm: dict | None = None, bias_px=None,
                k: float = COVERAGE_K, noise_from_residuals: bool = True) -> dict:
    """{component: {term: u or None, "combined": u_c, "expanded": U, "k": k}} of a solved record
    (module docstring); a term not given (no ``sigma_mm``, no ``bias_px``) is None and adds
    nothing; ``bias_px`` is in delivered pixels (:func:`solved_bias_px` takes it to the record's).
    Units: mm for x_mm, y_mm, z_mm, deg for the angles. ``noise_from_residuals``: the
    record's covariance scales with a noise estimated from its residuals (measure, solve without
    a known sigma), which then already holds the share of the layout term that shows as misfit:
    that share (the layout's residual variance over the noise used, ``sigma_px``) is moved from
    the centre-noise term to the layout term, so it is not counted twice."""
    pa, pb, ids, ca, cb, intr, model = record_geometry(record, markers)
    sens = Sensitivity(pa, pb, ca, cb, intr, model)
    reported = np.diag(np.array(record["covariance"], dtype=float))
    model2, reported = _split_off(model_error_variance(record), reported)
    shift2, reported = _split_off(section_shift_variance(record), reported)
    if record.get("self_calibrated") == "sequence":
        std = record.get("intrinsics_std") or {}
        intr_var = np.array([std.get("focal_px", 0.0)] + [std.get(n, 0.0) for n in model.free]) ** 2
        u_intr2 = np.minimum(sens.intrinsics_var(intr_var), reported)
    else:
        u_intr2 = reported * sens.intrinsics_share()
    centre2, layout2 = np.maximum(reported - u_intr2, 0.0), None
    if sigma_mm is not None:
        s = np.array([sigma_mm[i] for i in ids])
        layout2 = sens.layout_var(s)
        if noise_from_residuals and record.get("sigma_px"):
            centre2 = centre2 * (1.0 - min(1.0, sens.layout_residual_px2(s) / float(record["sigma_px"]) ** 2))
    terms = {"centre_noise": centre2, "intrinsics": u_intr2, "model_error": model2, "section_shift": shift2,
             "layout": layout2,
             "detector_bias": None if bias_px is None else sens.bias_var(solved_bias_px(record, bias_px))}
    out = {}
    for c, name in enumerate(POSE_NAMES):
        row = {t: (None if v is None else math.sqrt(float(v[c]))) for t, v in terms.items()}
        u_c = math.sqrt(sum(v * v for v in row.values() if v is not None))
        out[name] = {**row, "combined": u_c, "expanded": k * u_c, "k": k}
    return out


def budget_block(records: list[dict], markers, image_size, bias_px=None, sigma_mm: dict | None = None) -> dict:
    """The budget over many solved frames (an evaluation's test split): per component the RMS
    over the frames of each term, of the combined u and U = k u_rms, and ``n`` the frames whose
    budget could be computed; ``records``: solved pose records (eval.solve_frames.pose_record),
    ``image_size`` (W, H) of their images. The layout of a rendered dataset is exact: its term is
    None unless ``sigma_mm`` is given."""
    budgets = []
    for r in records:
        try:
            budgets.append(pose_budget({"image_size": list(image_size), **r}, markers, sigma_mm, bias_px))
        except (KeyError, ValueError, IndexError):
            continue   # a record the budget cannot read is left out (counted by n)
    out = {"n": len(budgets), "k": COVERAGE_K, "bias_px": None if bias_px is None else list(bias_px),
           "components": {}}
    for name in POSE_NAMES:
        row = {}
        for t in (*TERMS, "combined"):
            vals = [b[name][t] for b in budgets if b[name][t] is not None]
            row[t] = math.sqrt(sum(v * v for v in vals) / len(vals)) if vals else None
        row["expanded"] = None if row["combined"] is None else COVERAGE_K * row["combined"]
        out["components"][name] = row
    return out
