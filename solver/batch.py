"""Batch entry points: many frames at once, vectorised over frames with numpy.

The common path is fully vectorised: the UPnP closed form with a one-dimensional null space
(K = 1, the general branch), then Levenberg-Marquardt with per-frame damping, then covariances
and ``d_from_b``. Frames on which that path does not give a converged, valid solution (a
negative squared focal, points behind the camera, no convergence) are re-solved one by one with
the full single-frame solver (every closed-form candidate, focal sweep). Frames that still fail
get ``ok = False``, NaN values and a message; no exception is raised for one bad frame.

Missing markers: ``visible`` (F, M) marks the points that exist; the others are ignored (their
coordinates may be NaN). Every frame needs at least 4 visible points per section.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dockfactory.solver.checks import as_principal_point
from dockfactory.solver.crb import POSE_NAMES
from dockfactory.solver.errors import SolverError

__all__ = ["DockingBatch", "PnPfBatch", "solve_docking_batch", "solve_pnpf_batch"]

_PAIRS4 = np.array([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)])


@dataclass(frozen=True)
class PnPfBatch:
    """``cam_from_world`` (F, 4, 4), ``focal_px`` (F,), ``rmse_px`` (F,), ``covariance``
    (F, 7, 7), ``ok`` (F,) bool, ``messages`` (F,) str ('' when ok). Failed frames hold NaN."""
    cam_from_world: np.ndarray
    focal_px: np.ndarray
    rmse_px: np.ndarray
    covariance: np.ndarray
    ok: np.ndarray
    messages: tuple


@dataclass(frozen=True)
class DockingBatch:
    """Per frame: ``d_from_b`` (F, 4, 4); ``pose`` (F, 6) = (X, Y, Z mm, alpha, beta, gamma
    deg) in ``POSE_NAMES`` order; ``focal_px`` (F,); ``covariance`` (F, 6, 6) of the pose;
    ``rmse_px`` (F, 2) per section (A, B); ``cam_from_a``, ``cam_from_b`` (F, 4, 4);
    ``ok`` (F,) bool; ``messages`` (F,) str. Failed frames hold NaN."""
    d_from_b: np.ndarray
    pose: np.ndarray
    focal_px: np.ndarray
    covariance: np.ndarray
    rmse_px: np.ndarray
    cam_from_a: np.ndarray
    cam_from_b: np.ndarray
    ok: np.ndarray
    messages: tuple

    def component(self, name: str) -> np.ndarray:
        """One pose component over frames, e.g. ``component("x_mm")``."""
        return self.pose[:, POSE_NAMES.index(name)]


# ---------------------------------------------------------------------------- input handling

def _batch_points(name, points_2d, n_markers, visible):
    try:
        uv = np.asarray(points_2d, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise SolverError(f"{name}: not a numeric array ({exc})") from None
    if uv.ndim != 3 or uv.shape[1:] != (n_markers, 2):
        raise SolverError(f"{name}: expected shape (F, {n_markers}, 2), got {uv.shape}")
    if visible is None:
        vis = np.ones(uv.shape[:2], dtype=bool)
    else:
        vis = np.asarray(visible)
        if vis.shape != uv.shape[:2]:
            raise SolverError(f"visible: expected shape {uv.shape[:2]}, got {vis.shape}")
        vis = vis.astype(bool)
    bad = vis & ~np.all(np.isfinite(uv), axis=2)
    if bad.any():
        frames = np.flatnonzero(bad.any(axis=1))
        raise SolverError(f"{name}: NaN or inf at visible points (frames {frames[:10].tolist()});"
                          " mark missing points with visible=False")
    uv = np.where(vis[..., None], uv, 0.0)
    return uv, vis


# ---------------------------------------------------------------------------- closed form

def _closed_form_k1(p3, uv, w, pp, planar: bool = False):
    """Vectorised UPnP, K = 1, weighted (w (F, N) in {0, 1}): general branch (4 control points),
    or with ``planar`` the planar branch (3 control points in the best-fit plane, points
    projected on it; its null space is 1-dim already for 5 points).

    Returns R (F, 3, 3), t (F, 3), f (F,), valid (F,) bool.
    """
    ncp = 3 if planar else 4
    nf, n = w.shape
    sw = w.sum(axis=1)
    c0 = (w @ p3) / sw[:, None]                                  # (F, 3)
    xc = p3[None] - c0[:, None]                                  # (F, N, 3)
    xw = xc * w[..., None]
    cov = xw.transpose(0, 2, 1) @ xc / sw[:, None, None]
    lam, axes = np.linalg.eigh(cov)
    lam, axes = lam[:, ::-1], axes[:, :, ::-1]
    s3 = np.sqrt(lam[:, 0])
    ln = np.maximum(lam / lam[:, :1], 1e-300)
    xn = xc / s3[:, None, None]
    uvc = (uv - pp) * w[..., None]
    k = np.sqrt((uvc * uvc).sum(axis=(1, 2)) / sw)
    k = np.where(k > 0, k, 1.0)
    un = uvc / k[:, None, None]
    if planar:
        a = xn @ (axes[:, :, :2] / np.sqrt(ln[:, :2])[:, None, :])
        normal = axes[:, :, 2]
        xn_fit = xn - (xn @ normal[..., None]) * normal[:, None, :]
        pairs = _PAIRS4[[0, 1, 3]]
        dist2 = np.stack([ln[:, 0], ln[:, 1], ln[:, 0] + ln[:, 1]], axis=1)
    else:
        a = xn @ (axes / np.sqrt(ln)[:, None, :])
        xn_fit = xn
        pairs = _PAIRS4
        dist2 = np.stack([ln[:, 0], ln[:, 1], ln[:, 2], ln[:, 0] + ln[:, 1],
                          ln[:, 0] + ln[:, 2], ln[:, 1] + ln[:, 2]], axis=1)
    alphas = np.concatenate([1.0 - a.sum(axis=2, keepdims=True), a], axis=2)   # (F, N, ncp)
    aw = alphas * w[..., None]
    m = np.zeros((nf, n, 2, 3 * ncp))
    m[:, :, 0, 0::3] = aw
    m[:, :, 1, 1::3] = aw
    m[:, :, 0, 2::3] = -aw * un[:, :, 0:1]
    m[:, :, 1, 2::3] = -aw * un[:, :, 1:2]
    m = m.reshape(nf, 2 * n, 3 * ncp)
    mtm = m.transpose(0, 2, 1) @ m
    v = np.linalg.eigh(mtm)[1][:, :, 0].reshape(nf, ncp, 3)
    d = v[:, pairs[:, 0]] - v[:, pairs[:, 1]]                    # (F, P, 3)
    a0 = d[:, :, 0] ** 2 + d[:, :, 1] ** 2
    a1 = d[:, :, 2] ** 2
    s00, s01, s11 = (a0 * a0).sum(1), (a0 * a1).sum(1), (a1 * a1).sum(1)
    r0, r1 = (a0 * dist2).sum(1), (a1 * dist2).sum(1)
    det = s00 * s11 - s01 * s01
    with np.errstate(divide="ignore", invalid="ignore"):
        x0 = (s11 * r0 - s01 * r1) / det
        x1 = (s00 * r1 - s01 * r0) / det
        valid = (x0 > 0) & (x1 > 0) & np.isfinite(x0) & np.isfinite(x1)
        beta = np.sqrt(np.where(valid, x0, 1.0))
        fn = np.sqrt(np.where(valid, x1 / x0, 1.0))
    cps = v * beta[:, None, None]
    cps[:, :, 2] *= fn[:, None]
    pc = alphas @ cps
    sign = np.where((pc[..., 2] * w).sum(axis=1) < 0, -1.0, 1.0)
    pc *= sign[:, None, None]
    mc = (pc * w[..., None]).sum(axis=1) / sw[:, None]
    h = (xn_fit * w[..., None]).transpose(0, 2, 1) @ pc
    u_, _, vt = np.linalg.svd(h)
    r = vt.transpose(0, 2, 1) @ u_.transpose(0, 2, 1)            # V U^T
    neg = np.linalg.det(r) < 0
    if neg.any():
        vt[neg, 2] *= -1.0
        r = vt.transpose(0, 2, 1) @ u_.transpose(0, 2, 1)
    t = s3[:, None] * mc - (r @ c0[..., None])[..., 0]
    f = fn * k
    z = (p3 @ r.transpose(0, 2, 1))[..., 2] + t[:, None, 2]
    valid &= np.all((z > 0) | (w == 0), axis=1) & np.isfinite(f)
    return r, t, f, valid


# ---------------------------------------------------------------------------- batched LM

def _so3_exp(wv):
    from dockfactory.solver.lie import so3_exp_batch
    return so3_exp_batch(wv)


def _section_rj(p3, uv, w, pp, r, t, f):
    """Residuals (F, N, 2) (weighted) and Jacobian (F, N, 2, 7); min depth over visible."""
    a = p3 @ r.transpose(0, 2, 1)                                # (F, N, 3) = R p
    pc = a + t[:, None, :]
    z = pc[..., 2]
    zs = np.where(w > 0, z, 1.0)
    iz = 1.0 / zs
    xn = pc[..., 0] * iz
    yn = pc[..., 1] * iz
    fz = f[:, None] * iz * w
    res = np.empty(uv.shape)
    res[..., 0] = (f[:, None] * xn + pp[0] - uv[..., 0]) * w
    res[..., 1] = (f[:, None] * yn + pp[1] - uv[..., 1]) * w
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    j = np.zeros(uv.shape[:2] + (2, 7))
    j[..., 0, 0] = -fz * ay * xn
    j[..., 0, 1] = fz * (az + ax * xn)
    j[..., 0, 2] = -fz * ay
    j[..., 1, 0] = -fz * (ay * yn + az)
    j[..., 1, 1] = fz * ax * yn
    j[..., 1, 2] = fz * ax
    j[..., 0, 3] = fz
    j[..., 0, 5] = -fz * xn
    j[..., 1, 4] = fz
    j[..., 1, 5] = -fz * yn
    j[..., 0, 6] = xn * w
    j[..., 1, 6] = yn * w
    zmin = np.where(w > 0, z, np.inf).min(axis=1)
    return res, j, zmin


def _eval(sections, pp, params):
    """Stack residuals/Jacobians of all sections: res (F, m), jac (F, m, 6S + 1), valid."""
    nsec = len(sections)
    f = params[-1]
    res_l, jac_l = [], []
    valid = np.isfinite(f) & (f > 0)
    for s, (p3, uv, w) in enumerate(sections):
        r, t = params[2 * s], params[2 * s + 1]
        res, j, zmin = _section_rj(p3, uv, w, pp, r, t, f)
        nf, n = w.shape
        full = np.zeros((nf, n, 2, 6 * nsec + 1))
        full[..., 6 * s:6 * s + 6] = j[..., :6]
        full[..., -1] = j[..., 6]
        res_l.append(res.reshape(nf, -1))
        jac_l.append(full.reshape(nf, 2 * n, -1))
        valid &= zmin > 0
    res = np.concatenate(res_l, axis=1)
    jac = np.concatenate(jac_l, axis=1)
    return res, jac, valid & np.all(np.isfinite(res), axis=1)


def _lm_batch(sections, pp, params, max_iter=40):
    """Vectorised LM (per-frame damping). ``params`` = [R_0, t_0, ..., f] with leading F."""
    res, jac, valid = _eval(sections, pp, params)
    cost = np.where(valid, (res * res).sum(axis=1), np.inf)
    nf = cost.size
    lam = np.full(nf, 1e-6)
    done = ~valid
    conv = np.zeros(nf, dtype=bool)
    npar = jac.shape[2]
    eye = np.eye(npar)
    for _ in range(max_iter):
        act = np.flatnonzero(~done)
        if act.size == 0:
            break
        ja, ra = jac[act], res[act]
        jat = ja.transpose(0, 2, 1)
        jtj = jat @ ja
        g = (jat @ ra[..., None])[..., 0]
        dg = np.einsum("fii->fi", jtj).copy()
        dg[dg <= 0] = 1.0
        a = jtj + (lam[act, None] * dg)[:, :, None] * eye
        try:
            step = np.linalg.solve(a, -g[..., None])[..., 0]
        except np.linalg.LinAlgError:
            step = np.stack([np.linalg.lstsq(ai, -gi, rcond=None)[0] for ai, gi in zip(a, g)])
        pred = -(g * step).sum(axis=1) - 0.5 * (step * (jtj @ step[..., None])[..., 0]).sum(axis=1)
        new = []
        for s in range(len(sections)):
            new.append(_so3_exp(step[:, 6 * s:6 * s + 3]) @ params[2 * s][act])
            new.append(params[2 * s + 1][act] + step[:, 6 * s + 3:6 * s + 6])
        new.append(params[-1][act] + step[:, -1])
        sub = [(p3, uv[act], w[act]) for p3, uv, w in sections]
        res_n, jac_n, valid_n = _eval(sub, pp, new)
        cost_n = np.where(valid_n, (res_n * res_n).sum(axis=1), np.inf)
        acc = cost_n <= cost[act]
        idx = act[acc]
        for q in range(len(params)):
            params[q][idx] = new[q][acc]
        dec = cost[idx] - cost_n[acc]
        tiny = np.max(np.abs(step[acc]) * np.sqrt(dg[acc]), axis=1) < 1e-9
        res[idx], jac[idx], cost[idx] = res_n[acc], jac_n[acc], cost_n[acc]
        lam[idx] = np.maximum(lam[idx] * 0.1, 1e-12)
        stop = tiny | (dec <= 1e-9 * cost[idx]) | (cost[idx] < 1e-28 * res.shape[1])
        conv[idx[stop]] = True
        done[idx[stop]] = True
        rej = act[~acc]
        lam[rej] *= 10.0
        nothing = act[pred <= 1e-12 * cost[act]]
        conv[nothing] = True
        done[nothing] = True
        done[rej[lam[rej] > 1e10]] = True
    return params, res, jac, cost, conv


# ---------------------------------------------------------------------------- pose algebra

def _euler_batch(r):
    beta = np.arcsin(np.clip(-r[:, 2, 0], -1.0, 1.0))
    alpha = np.arctan2(r[:, 1, 0], r[:, 0, 0])
    gamma = np.arctan2(r[:, 2, 1], r[:, 2, 2])
    return alpha, beta, gamma


def _skew_batch(v):
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def _docking_outputs(ra, ta, rb, tb, cov13):
    """d_from_b (F, 4, 4), pose (F, 6), cov6 (F, 6, 6): vectorised version of
    solver.refine.relative_pose / d_from_b_jacobian."""
    nf = ra.shape[0]
    rat = ra.transpose(0, 2, 1)
    rrel = rat @ rb
    trel = (rat @ (tb - ta)[..., None])[..., 0]
    d = np.tile(np.eye(4), (nf, 1, 1))
    d[:, :3, :3], d[:, :3, 3] = rrel, trel
    alpha, beta, gamma = _euler_batch(rrel)
    pose = np.column_stack([trel, np.degrees(alpha), np.degrees(beta), np.degrees(gamma)])
    jac = np.zeros((nf, 6, 12))
    jac[:, :3, 0:3] = rat @ _skew_batch(tb - ta)
    jac[:, :3, 3:6] = -rat
    jac[:, :3, 9:12] = rat
    ca, sa, cb, sb = np.cos(alpha), np.sin(alpha), np.cos(beta), np.sin(beta)
    e = np.zeros((nf, 3, 3))
    e[:, 0, 1], e[:, 0, 2] = -sa, ca * cb
    e[:, 1, 1], e[:, 1, 2] = ca, sa * cb
    e[:, 2, 0], e[:, 2, 2] = 1.0, -sb
    de = np.degrees(np.linalg.solve(e, rat))
    jac[:, 3:, 6:9] = de
    jac[:, 3:, 0:3] = -de
    cov6 = jac @ cov13[:, :12, :12] @ jac.transpose(0, 2, 1)
    return d, pose, cov6


def _covariances(jac, res, cost, dof, sigma_px):
    jtj = jac.transpose(0, 2, 1) @ jac
    dg = np.einsum("fii->fi", jtj)
    sc = 1.0 / np.sqrt(np.where(dg > 0, dg, np.nan))           # Jacobi scaling
    lam, vec = np.linalg.eigh(np.nan_to_num(jtj * sc[:, :, None] * sc[:, None, :]))
    inv = ((vec / lam[:, None, :]) @ vec.transpose(0, 2, 1)) * sc[:, :, None] * sc[:, None, :]
    singular = ~(lam[:, 0] > 1e-15 * lam[:, -1]) | ~np.all(dg > 0, axis=1)
    inv[singular] = np.inf
    if sigma_px is None:
        s2 = np.where(dof > 0, cost / np.maximum(dof, 1), np.inf)
    else:
        s2 = np.full(cost.shape, float(sigma_px) ** 2)
    return inv * s2[:, None, None]


def _transform(r, t):
    out = np.tile(np.eye(4), (r.shape[0], 1, 1))
    out[:, :3, :3], out[:, :3, 3] = r, t
    return out


# ---------------------------------------------------------------------------- public API

def solve_docking_batch(markers, principal_point, points_2d, visible=None, *,
                        sigma_px: float | None = None, chunk: int = 512) -> DockingBatch:
    """Docking solve for many frames with known marker ids (no identification, no outliers).

    ``markers``: the layout (sequence of :class:`generator.layout.Marker`, M markers, A and B).
    ``principal_point``: (2,) px, shared by all frames. ``points_2d``: (F, M, 2) float64 px,
    the centre of marker ``markers[m]`` in frame f. ``visible``: (F, M) bool or None (all).
    ``sigma_px``: pixel noise std for the covariances (None: from the residuals).
    Returns a :class:`DockingBatch`. Raises SolverError only for malformed input (shapes,
    NaN at visible points); per-frame failures are reported in ``ok``/``messages``.
    """
    from dockfactory.solver.docking import layout_arrays, solve_docking_arrays

    ids, sections, pts = layout_arrays(markers)
    pp = as_principal_point(principal_point)
    uv, vis = _batch_points("points_2d", points_2d, len(ids), visible)
    sel = {s: np.array([k for k, sec in enumerate(sections) if sec == s]) for s in ("A", "B")}
    nf = uv.shape[0]
    out = {
        "d": np.full((nf, 4, 4), np.nan), "pose": np.full((nf, 6), np.nan),
        "f": np.full(nf, np.nan), "cov": np.full((nf, 6, 6), np.nan),
        "rmse": np.full((nf, 2), np.nan), "ca": np.full((nf, 4, 4), np.nan),
        "cb": np.full((nf, 4, 4), np.nan)}
    ok = np.zeros(nf, dtype=bool)
    msgs = [""] * nf
    for lo in range(0, nf, chunk):
        hi = min(nf, lo + chunk)
        _docking_chunk(pts, sel, uv[lo:hi], vis[lo:hi], pp, sigma_px, out, ok, msgs, lo)
    # one-by-one fallback for frames the vectorised path did not settle
    for fi in np.flatnonzero(~ok):
        if msgs[fi].startswith("section"):
            continue                       # too few points: no solver can help
        try:
            pa, pb = sel["A"][vis[fi, sel["A"]]], sel["B"][vis[fi, sel["B"]]]
            from dockfactory.solver.checks import check_correspondences
            p3a, p2a = check_correspondences(pts[pa], uv[fi, pa], what="section A")
            p3b, p2b = check_correspondences(pts[pb], uv[fi, pb], what="section B")
            res = solve_docking_arrays(p3a, p2a, p3b, p2b, pp, sigma_px)
        except SolverError as exc:
            msgs[fi] = str(exc)
            continue
        from dockfactory.core.geometry import pose_components
        out["d"][fi] = res["d_from_b"]
        out["pose"][fi] = [pose_components(res["d_from_b"])[k] for k in POSE_NAMES]
        out["f"][fi] = res["focal_px"]
        out["cov"][fi] = res["cov6"]
        out["rmse"][fi] = (res["rmse_a"], res["rmse_b"])
        out["ca"][fi], out["cb"][fi] = res["cam_from_a"], res["cam_from_b"]
        ok[fi] = True
        msgs[fi] = ""
    return DockingBatch(out["d"], out["pose"], out["f"], out["cov"], out["rmse"], out["ca"],
                        out["cb"], ok, tuple(msgs))


def _docking_chunk(pts, sel, uv, vis, pp, sigma_px, out, ok, msgs, offset):
    nf = uv.shape[0]
    counts = {s: vis[:, sel[s]].sum(axis=1) for s in ("A", "B")}
    good = np.ones(nf, dtype=bool)
    for s in ("A", "B"):
        few = counts[s] < 4
        for fi in np.flatnonzero(few):
            msgs[offset + fi] = (f"section {s}: {counts[s][fi]} usable points, at least 4 "
                                 "are needed")
        good &= ~few
    idx = np.flatnonzero(good)
    if idx.size == 0:
        return
    secs = []
    inits = []
    for s in ("A", "B"):
        p3 = pts[sel[s]]
        u = uv[idx][:, sel[s]]
        w = vis[idx][:, sel[s]].astype(np.float64)
        with np.errstate(all="ignore"):
            r, t, f, v = _closed_form_k1(p3, u, w, pp)
            if not v.all():
                bad = np.flatnonzero(~v)
                r2, t2, f2, v2 = _closed_form_k1(p3, u[bad], w[bad], pp, planar=True)
                r[bad], t[bad], f[bad], v[bad] = r2, t2, f2, v2
        secs.append((p3, u, w))
        inits.append([r, t, f, v])
    # docking prior: B sits within a few degrees and 150 mm of A, so a section whose closed
    # form failed starts from the other section's camera (the joint LM moves it).
    (ra, ta, fa, va), (rb, tb, fb, vb) = inits
    only_a, only_b = va & ~vb, vb & ~va
    rb[only_a], tb[only_a], fb[only_a] = ra[only_a], ta[only_a], fa[only_a]
    ra[only_b], ta[only_b], fa[only_b] = rb[only_b], tb[only_b], fb[only_b]
    valid = va | vb
    inits = [(ra, ta, fa), (rb, tb, fb)]
    keep = np.flatnonzero(valid)
    if keep.size == 0:
        return
    (ra, ta, fa), (rb, tb, fb) = [(r[keep], t[keep], f[keep]) for r, t, f in inits]
    f0 = np.sqrt(fa * fb)
    params = [ra.copy(), ta * (f0 / fa)[:, None], rb.copy(), tb * (f0 / fb)[:, None], f0]
    secs = [(p3, u[keep], w[keep]) for p3, u, w in secs]
    with np.errstate(all="ignore"):
        params, res, jac, cost, conv = _lm_batch(secs, pp, params)
    nvis = sum(w.sum(axis=1) for _, _, w in secs)
    dof = 2 * nvis - 13
    with np.errstate(all="ignore"):
        cov13 = _covariances(jac, res, cost, dof, sigma_px)
        d, pose, cov6 = _docking_outputs(params[0], params[1], params[2], params[3], cov13)
    fvar = cov13[:, 12, 12]
    fine = conv & np.isfinite(cost) & np.all(np.isfinite(pose), axis=1) & np.isfinite(fvar) \
        & (fvar >= 0) & (np.sqrt(np.abs(fvar)) <= 10.0 * params[4])
    fr = offset + idx[keep[fine]]
    na = secs[0][2][fine].sum(axis=1)
    nb = secs[1][2][fine].sum(axis=1)
    ra_res = res[fine, :2 * secs[0][2].shape[1]]
    rb_res = res[fine, 2 * secs[0][2].shape[1]:]
    out["d"][fr] = d[fine]
    out["pose"][fr] = pose[fine]
    out["f"][fr] = params[4][fine]
    out["cov"][fr] = cov6[fine]
    out["rmse"][fr, 0] = np.sqrt((ra_res * ra_res).sum(axis=1) / na)
    out["rmse"][fr, 1] = np.sqrt((rb_res * rb_res).sum(axis=1) / nb)
    out["ca"][fr] = _transform(params[0][fine], params[1][fine])
    out["cb"][fr] = _transform(params[2][fine], params[3][fine])
    ok[fr] = True


def solve_pnpf_batch(points_3d, points_2d, principal_point, visible=None, *,
                     sigma_px: float | None = None, chunk: int = 512) -> PnPfBatch:
    """:func:`solver.solve_pnpf` for many frames of one rigid point set.

    ``points_3d``: (N, 3) float64 mm (shared by all frames); ``points_2d``: (F, N, 2) px;
    ``visible``: (F, N) bool or None; ``principal_point``: (2,) px.
    Returns a :class:`PnPfBatch` (covariance over (w, t, f) as in :mod:`solver.refine`).
    """
    from dockfactory.solver.checks import as_points, check_correspondences
    from dockfactory.solver.pnpf import solve_checked

    p3 = as_points("points_3d", points_3d, 3)
    pp = as_principal_point(principal_point)
    uv, vis = _batch_points("points_2d", points_2d, p3.shape[0], visible)
    nf = uv.shape[0]
    cam = np.full((nf, 4, 4), np.nan)
    foc = np.full(nf, np.nan)
    rmse = np.full(nf, np.nan)
    cov = np.full((nf, 7, 7), np.nan)
    ok = np.zeros(nf, dtype=bool)
    msgs = [""] * nf
    for lo in range(0, nf, chunk):
        hi = min(nf, lo + chunk)
        fr = np.arange(lo, hi)
        cnt = vis[fr].sum(axis=1)
        for fi in fr[cnt < 4]:
            msgs[fi] = f"{int(vis[fi].sum())} usable points, at least 4 are needed"
        fr = fr[cnt >= 4]
        if fr.size == 0:
            continue
        w = vis[fr].astype(np.float64)
        with np.errstate(all="ignore"):
            r, t, f, v = _closed_form_k1(p3, uv[fr], w, pp)
            if not v.all():
                bad = np.flatnonzero(~v)
                r2, t2, f2, v2 = _closed_form_k1(p3, uv[fr][bad], w[bad], pp, planar=True)
                r[bad], t[bad], f[bad], v[bad] = r2, t2, f2, v2
            fr, r, t, f, w = fr[v], r[v], t[v], f[v], w[v]
            params, res, jac, cost, conv = _lm_batch([(p3, uv[fr], w)], pp, [r, t, f])
            dof = 2 * w.sum(axis=1) - 7
            c7 = _covariances(jac, res, cost, dof, sigma_px)
        fvar = c7[:, 6, 6]
        fine = conv & np.isfinite(cost) & np.isfinite(fvar) & (fvar >= 0) & \
            (np.sqrt(np.abs(fvar)) <= params[2])
        g = fr[fine]
        cam[g] = _transform(params[0][fine], params[1][fine])
        foc[g] = params[2][fine]
        rmse[g] = np.sqrt(cost[fine] / w[fine].sum(axis=1))
        cov[g] = c7[fine]
        ok[g] = True
    for fi in np.flatnonzero(~ok):
        if msgs[fi]:
            continue
        try:
            q3, q2 = check_correspondences(p3[vis[fi]], uv[fi, vis[fi]])
            ref, c, _, _ = solve_checked(q3, q2, pp, sigma_px)
        except SolverError as exc:
            msgs[fi] = str(exc)
            continue
        cam[fi] = _transform(ref.rotation[None], ref.translation[None])[0]
        foc[fi], rmse[fi], cov[fi], ok[fi] = ref.focal_px, ref.rmse_px, c, True
    return PnPfBatch(cam, foc, rmse, cov, ok, tuple(msgs))
