"""``solve_docking``: relative pose of B in A (``d_from_b``) from one uncalibrated image.

Both sections are seen by one camera with one (unknown) focal length. Each section gets a
closed-form UPnP initialisation, then a joint Levenberg-Marquardt over 13 parameters
(cam_from_a, cam_from_b, f) gives the maximum-likelihood estimate under Gaussian pixel noise,
its covariance sigma^2 (J^T J)^-1, and ``d_from_b = inv(cam_from_a) @ cam_from_b`` with the
covariance of (X, Y, Z, alpha, beta, gamma) propagated to first order.
Input is either detections (class + pixel centre, no id: identified by :mod:`solver.identify`)
or correspondences (marker id + pixel centre, optionally with outliers: LO-RANSAC per section).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
from dockfactory.core.geometry import pose_components
from dockfactory.solver.checks import (
    MIN_POINTS,
    as_points,
    as_principal_point,
    check_correspondences,
)
from dockfactory.solver.crb import POSE_NAMES
from dockfactory.solver.errors import SolverError
from dockfactory.solver.identify import parse_detections
from dockfactory.solver.pnpf import solve_checked
from dockfactory.solver.refine import (
    covariance_from_jacobian,
    d_from_b_jacobian,
    refine_joint,
    relative_pose,
)
from dockfactory.solver.upnp import upnp

__all__ = ["DockingResult", "solve_docking", "layout_arrays", "solve_docking_arrays",
           "MAX_JOINT_FOCAL_REL_STD"]

# The joint estimate is refused only when the shared focal has clearly run off (relative std
# above this): a poorly known focal is otherwise reported through the covariances, since X, Y
# and alpha stay well determined (they are nearly independent of the focal / depth trade-off).
MAX_JOINT_FOCAL_REL_STD = 10.0


@dataclass(frozen=True)
class DockingResult:
    """Result of :func:`solve_docking`.

    - ``d_from_b`` (4, 4): pose of B in D (= A's frame); ``x_mm``, ``y_mm``, ``z_mm``,
      ``alpha_deg``, ``beta_deg``, ``gamma_deg`` its components (R = Rz(a) Ry(b) Rx(g));
    - ``focal_px``: the shared focal length (px);
    - ``covariance`` (6, 6) over (X, Y, Z mm, alpha, beta, gamma deg) = ``POSE_NAMES``;
      ``std`` the matching dict of standard deviations;
    - ``covariance_params`` (13, 13) over (w_A, t_A, w_B, t_B, f) (see :mod:`solver.refine`);
    - ``rmse_px``: {"A": ..., "B": ...} reprojection RMS per section (px, per point);
    - ``marker_ids``: per input row, the marker id ("A3") or None (not identified, or rejected
      by RANSAC);
    - ``inliers`` (N,) bool per input row: used in the final fit (an identified detection left
      out as suspect keeps its id and is not an inlier);
    - ``swapped`` (N,) bool: detections whose class label disagreed with the section of the
      marker they were identified as (all False for correspondences);
    - ``cam_from_a``, ``cam_from_b`` (4, 4); ``sigma_px``: noise std used for the covariances.
    """

    d_from_b: np.ndarray
    x_mm: float
    y_mm: float
    z_mm: float
    alpha_deg: float
    beta_deg: float
    gamma_deg: float
    focal_px: float
    covariance: np.ndarray
    std: dict
    covariance_params: np.ndarray
    rmse_px: dict
    marker_ids: tuple
    inliers: np.ndarray
    swapped: np.ndarray
    cam_from_a: np.ndarray
    cam_from_b: np.ndarray
    sigma_px: float
    iterations: int = field(default=0)

    def pose(self) -> dict:
        """{"x_mm": ..., ..., "gamma_deg": ...}."""
        return {k: getattr(self, k) for k in POSE_NAMES}


def layout_arrays(markers):
    """(ids tuple, sections tuple, points (M, 3) mm in each marker's section frame)."""
    try:
        ids = tuple(m.id for m in markers)
        sections = tuple(m.section for m in markers)
        pts = np.array([m.center_mm for m in markers], dtype=np.float64).reshape(-1, 3)
    except (AttributeError, TypeError) as exc:
        raise SolverError(f"markers: expected a sequence of generator.layout.Marker ({exc})") \
            from None
    if len(set(ids)) != len(ids):
        raise SolverError("markers: duplicate marker ids in the layout")
    bad = set(sections) - {"A", "B"}
    if bad:
        raise SolverError(f"markers: unknown sections {sorted(bad)} (expected 'A' and 'B')")
    if not np.all(np.isfinite(pts)):
        raise SolverError("markers: a marker centre is NaN or inf")
    return ids, sections, pts


def _parse_correspondences(correspondences):
    """(ids list (N,), points_2d (N, 2)) from a dict id -> (u, v) or a pair (ids, (N, 2))."""
    if isinstance(correspondences, dict):
        ids = [str(k) for k in correspondences]
        uv = as_points("correspondences", [correspondences[k] for k in correspondences], 2) \
            if ids else np.zeros((0, 2))
        return ids, uv
    try:
        ids, uv = correspondences
    except (TypeError, ValueError):
        raise SolverError("correspondences: expected a dict id -> (u, v) or a pair "
                          "(marker_ids (N,), points_2d (N, 2))") from None
    ids = [str(i) for i in np.asarray(ids).reshape(-1)]
    uv = as_points("correspondences points_2d", uv, 2)
    if len(ids) != uv.shape[0]:
        raise SolverError(f"correspondences: {len(ids)} marker ids but {uv.shape[0]} points: "
                          "shapes do not match")
    return ids, uv


def solve_docking(markers, principal_point, *, detections=None, correspondences=None,
                  sigma_px: float | None = None, robust: bool = False,
                  rng: np.random.Generator | None = None, threshold_px: float = 4.0,
                  identify_options: dict | None = None, boxes=None, refined=None,
                  min_extent: float = 0.85, eccentricity: bool = True) -> DockingResult:
    """Pose of B relative to A from one image of both sections (shared unknown focal length).

    ``markers``: the layout, a sequence of :class:`generator.layout.Marker` of both sections
    (``center_mm`` in each marker's own section frame), e.g. ``build_layout(...)``.
    ``principal_point``: (2,) float64, pixels.
    Exactly one of:
    - ``detections = (class_ids, points_2d)``: class_ids (N,) int (0 = A / RedA, 1 = B / BlueB)
      or "A"/"B"; points_2d (N, 2) float64 pixels. Ids are assigned by
      :func:`solver.identify.identify_markers` (hypothesise and verify); ``identify_options``
      are passed to it. Missing markers, spurious detections and swapped classes are tolerated;
      an ambiguous assignment raises SolverError.
    - ``correspondences``: dict marker id -> (u, v), or a pair (marker_ids (N,), points_2d
      (N, 2)). With ``robust=True`` (needs ``rng``), outliers are rejected per section by
      LO-RANSAC with inlier threshold ``threshold_px``.
    Detections only: identification uses every detection; the pose then leaves out, worst
    first, identified detections whose centre is suspect (see :mod:`solver.suspects`), as long
    as each section keeps ``MIN_POINTS`` (suspects left out keep their id; ``inliers`` False):
    - ``boxes`` (N, 4) [x0, y0, x1, y1] px: the detected outline; narrower or lower than
      ``min_extent`` x the outline the first fit predicts for its marker = partly hidden;
    - ``refined`` (N,) bool: False where the detector could not refine the centre (box
      centre only).
    ``eccentricity`` (detections only): detected centres are centroids of the disc's image;
    after the fit each is corrected by its predicted perspective offset and the pose refitted
    (see :mod:`solver.eccentricity`).
    ``sigma_px``: pixel noise std for the covariances; None estimates it from the residuals.

    Every section needs at least 4 usable points. Returns a :class:`DockingResult`; raises
    :class:`SolverError` on bad input (shapes, NaN/inf, unknown or repeated ids, too few or
    collinear points, points behind the camera) or an ambiguous identification.
    """
    if (detections is None) == (correspondences is None):
        raise SolverError("give exactly one of detections= or correspondences=")
    ids_layout, sections, pts_layout = layout_arrays(markers)
    pp = as_principal_point(principal_point)
    if sigma_px is not None and not (np.isfinite(sigma_px) and sigma_px > 0):
        raise SolverError(f"sigma_px must be positive and finite, got {sigma_px}")
    if correspondences is not None and (boxes is not None or refined is not None):
        raise SolverError("boxes= and refined= describe detections: give them with detections=")
    if detections is not None:
        from dockfactory.solver.identify import identify_markers
        n_det = len(parse_detections(detections)[0])
        boxes = _row_array(boxes, n_det, (4,), "boxes", float)
        refined = _row_array(refined, n_det, (), "refined", bool)
        ident = identify_markers(markers, pp, detections, **(identify_options or {}))
        ids = list(ident.marker_ids)
        uv = ident.points_2d
        used = np.array([i is not None for i in ids])
        swapped = ident.swapped
    else:
        ids, uv = _parse_correspondences(correspondences)
        used = np.ones(len(ids), dtype=bool)
        swapped = np.zeros(len(ids), dtype=bool)
        index = {mid: k for k, mid in enumerate(ids_layout)}
        unknown = sorted({i for i in ids if i not in index})
        if unknown:
            raise SolverError(f"correspondences: unknown marker ids {unknown[:10]}")
        if len(set(ids)) != len(ids):
            dup = sorted({i for i in ids if ids.count(i) > 1})
            raise SolverError(f"correspondences: marker ids given more than once: {dup[:10]}")
    index = {mid: k for k, mid in enumerate(ids_layout)}
    rows = {s: [k for k, mid in enumerate(ids) if mid is not None and used[k]
                and sections[index[mid]] == s] for s in ("A", "B")}
    p3 = {}
    p2 = {}
    for s in ("A", "B"):
        if len(rows[s]) < MIN_POINTS:
            raise SolverError(f"section {s}: {len(rows[s])} usable points, at least "
                              f"{MIN_POINTS} are needed")
        p3[s], p2[s] = check_correspondences(
            pts_layout[[index[ids[k]] for k in rows[s]]], uv[rows[s]], what=f"section {s}")
    inliers = used.copy()
    init = None
    if robust and correspondences is not None:
        from dockfactory.solver.ransac import ransac_docking
        if not isinstance(rng, np.random.Generator):
            raise SolverError("robust=True needs rng, a numpy.random.Generator (explicit seed)")
        keep_a, keep_b, init = ransac_docking(p3["A"], p2["A"], p3["B"], p2["B"], pp, rng,
                                              threshold_px=threshold_px)
        for s, keep in (("A", keep_a), ("B", keep_b)):
            for k, ok in zip(rows[s], keep):
                inliers[k] = bool(ok)
            rows[s] = [k for k, ok in zip(rows[s], keep) if ok]
            p3[s], p2[s] = p3[s][keep], p2[s][keep]
    out = solve_docking_arrays(p3["A"], p2["A"], p3["B"], p2["B"], pp, sigma_px, init=init)
    if robust and correspondences is not None:
        # final inlier check with the joint model over every correspondence
        out, inliers, rows = _recheck_inliers(out, ids, uv, index, sections, pts_layout, pp,
                                              threshold_px, sigma_px, inliers)
    identified = inliers.copy()
    if detections is not None:
        from dockfactory.solver.suspects import leave_out_suspects
        fit = functools.partial(solve_docking_arrays, pp=pp, sigma_px=sigma_px)
        by_id = {m.id: m for m in markers}
        row_markers = [by_id.get(i) for i in ids]
        out, inliers = leave_out_suspects(out, rows, p3, p2, fit, inliers, row_markers, pp,
                                          boxes, refined, min_extent)
        if eccentricity:
            from dockfactory.solver.eccentricity import correct_eccentricity
            out = correct_eccentricity(out, rows, p3, p2, fit, inliers, row_markers, pp)
    marker_ids = tuple(ids[k] if identified[k] else None for k in range(len(ids)))
    return _finish(out, marker_ids, inliers, swapped)


def _row_array(value, n, shape, name, dtype):
    """None, or ``value`` as an (n, *shape) array of ``dtype`` (one row per detection)."""
    if value is None:
        return None
    try:
        arr = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise SolverError(f"{name}: not an array of {dtype.__name__}: {exc}") from None
    if arr.shape != (n, *shape):
        raise SolverError(f"{name}: expected shape {(n, *shape)} (one row per detection), "
                          f"got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise SolverError(f"{name}: contains NaN or inf")
    return arr


def _recheck_inliers(out, ids, uv, index, sections, pts_layout, pp, thr, sigma_px, inliers):
    cams = {"A": out["cam_from_a"], "B": out["cam_from_b"]}
    new = np.zeros(len(ids), dtype=bool)
    for k, mid in enumerate(ids):
        if mid is None:
            continue
        cam = cams[sections[index[mid]]]
        pc = cam[:3, :3] @ pts_layout[index[mid]] + cam[:3, 3]
        if pc[2] <= 0:
            continue
        e = out["focal_px"] * pc[:2] / pc[2] + pp - uv[k]
        new[k] = float(e @ e) <= thr * thr
    rows = {s: [k for k in range(len(ids)) if new[k] and sections[index[ids[k]]] == s]
            for s in ("A", "B")}
    if all(len(rows[s]) >= MIN_POINTS for s in rows) and not np.array_equal(new, inliers):
        p3 = {s: pts_layout[[index[ids[k]] for k in rows[s]]] for s in rows}
        p2 = {s: uv[rows[s]] for s in rows}
        out = solve_docking_arrays(p3["A"], p2["A"], p3["B"], p2["B"], pp, sigma_px,
                                   init=(out["cam_from_a"], out["cam_from_b"], out["focal_px"]))
        return out, new, rows
    return out, inliers, rows


def solve_docking_arrays(points_a, uv_a, points_b, uv_b, pp, sigma_px=None, init=None,
                         accept_rmse=None) -> dict:
    """Joint solve on validated arrays: points_a (Na, 3) mm in A, uv_a (Na, 2) px, same for B.

    Returns a dict with cam_from_a, cam_from_b, focal_px, d_from_b, cov6, cov13, sigma,
    rmse_a, rmse_b, iterations. ``init`` = (cam_from_a, cam_from_b, f) replaces the closed-form
    start. If the joint LM does not converge, or ends with an RMS above ``accept_rmse`` px,
    each section is first solved on its own (with every closed-form candidate if needed) and
    the joint LM restarts from those; the lowest cost wins.
    """
    if init is not None:
        ca, cb, f0 = init
        starts = [(ca[:3, :3], ca[:3, 3], cb[:3, :3], cb[:3, 3], f0)]
    else:
        starts = _closed_form_starts(points_a, uv_a, points_b, uv_b, pp)
    best = None
    errors = []
    n_res = 2 * (points_a.shape[0] + points_b.shape[0])
    for attempt in range(2):
        for st in starts:
            try:
                jr = refine_joint(points_a, uv_a, points_b, uv_b, pp, *st)
            except SolverError as exc:
                errors.append(str(exc))
                continue
            cost = float(jr.residuals_a @ jr.residuals_a + jr.residuals_b @ jr.residuals_b)
            if best is None or cost < best[0]:
                best = (cost, jr)
            if jr.converged and attempt == 0:
                break
        good = best is not None and best[1].converged and (
            accept_rmse is None or np.sqrt(2.0 * best[0] / n_res) <= accept_rmse)
        if good or attempt == 1:
            break
        # fall back: solve each section on its own first, then join
        try:
            sol_a = solve_checked(points_a, uv_a, pp, check_focal=False, accept_rmse=accept_rmse)
            sol_b = solve_checked(points_b, uv_b, pp, check_focal=False, accept_rmse=accept_rmse)
        except SolverError as exc:
            errors.append(str(exc))
            break
        starts = _joint_starts(sol_a, sol_b)
    if best is None:
        raise SolverError("joint refinement failed: " + "; ".join(errors))
    jr = best[1]
    res = np.concatenate([jr.residuals_a, jr.residuals_b])
    cov13, sigma = covariance_from_jacobian(jr.jacobian, res, sigma_px)
    rel = _rel_focal_std(cov13, jr.focal_px)
    if not rel <= MAX_JOINT_FOCAL_REL_STD:
        raise SolverError(f"focal length is not observable from these points (relative std "
                          f"{rel:.3g}); the pose cannot be trusted")
    prop = d_from_b_jacobian(jr.rotation_a, jr.translation_a, jr.rotation_b, jr.translation_b)
    cov6 = prop @ cov13[:12, :12] @ prop.T
    cam_a = np.eye(4)
    cam_a[:3, :3], cam_a[:3, 3] = jr.rotation_a, jr.translation_a
    cam_b = np.eye(4)
    cam_b[:3, :3], cam_b[:3, 3] = jr.rotation_b, jr.translation_b
    rmse = {s: float(np.sqrt(2.0 * (r @ r) / r.size))
            for s, r in (("A", jr.residuals_a), ("B", jr.residuals_b))}
    return {"cam_from_a": cam_a, "cam_from_b": cam_b, "focal_px": float(jr.focal_px),
            "d_from_b": relative_pose(jr.rotation_a, jr.translation_a, jr.rotation_b,
                                      jr.translation_b),
            "cov6": cov6, "cov13": cov13, "sigma": sigma, "rmse_a": rmse["A"],
            "rmse_b": rmse["B"], "iterations": jr.iterations}


def _closed_form_starts(points_a, uv_a, points_b, uv_b, pp):
    """Joint LM start from the per-section closed forms (cheap path first)."""
    cands = []
    for p3, p2 in ((points_a, uv_a), (points_b, uv_b)):
        c = upnp(p3, p2, pp, checked=True, first_only=True)
        if not c:
            c = upnp(p3, p2, pp, checked=True, sweep_above_px=None)
        cands.append(c[0])
    ca, cb = cands
    f0 = float(np.sqrt(ca.focal_px * cb.focal_px))
    return [(ca.rotation, ca.translation * (f0 / ca.focal_px),
             cb.rotation, cb.translation * (f0 / cb.focal_px), f0)]


def _joint_starts(sol_a, sol_b):
    """Initial (R_A, t_A, R_B, t_B, f) for the joint LM, most plausible first.

    Focal candidates: the better-determined section's own focal (smaller relative std), the
    geometric mean, the other section's focal. Translations are rescaled with the focal
    (f / depth is what the image fixes).
    """
    (ref_a, cov_a), (ref_b, cov_b) = (sol_a[0], sol_a[1]), (sol_b[0], sol_b[1])
    rel_a = _rel_focal_std(cov_a, ref_a.focal_px)
    rel_b = _rel_focal_std(cov_b, ref_b.focal_px)
    first, other = (ref_a.focal_px, ref_b.focal_px) if rel_a <= rel_b else \
        (ref_b.focal_px, ref_a.focal_px)
    out = []
    for f0 in (first, np.sqrt(first * other), other):
        out.append((ref_a.rotation, ref_a.translation * (f0 / ref_a.focal_px),
                    ref_b.rotation, ref_b.translation * (f0 / ref_b.focal_px), f0))
    return out


def _rel_focal_std(cov, focal):
    v = cov[-1, -1]
    return float(np.sqrt(v)) / focal if np.isfinite(v) and v >= 0 else np.inf


def _finish(out, marker_ids, inliers, swapped) -> DockingResult:
    comp = pose_components(out["d_from_b"])
    std = dict(zip(POSE_NAMES, np.sqrt(np.diag(out["cov6"])).tolist()))
    return DockingResult(
        d_from_b=out["d_from_b"], focal_px=out["focal_px"], covariance=out["cov6"], std=std,
        covariance_params=out["cov13"], rmse_px={"A": out["rmse_a"], "B": out["rmse_b"]},
        marker_ids=marker_ids, inliers=np.asarray(inliers, dtype=bool),
        swapped=np.asarray(swapped, dtype=bool), cam_from_a=out["cam_from_a"],
        cam_from_b=out["cam_from_b"], sigma_px=out["sigma"], iterations=out["iterations"],
        **comp)
