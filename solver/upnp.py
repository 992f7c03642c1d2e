"""Closed-form pose and focal length: UPnP after Penate-Sanchez, Andrade-Cetto, Moreno-Noguer.

"Exhaustive Linearization for Robust Camera Pose and Focal Length Estimation", TPAMI 2013.

Model: square pixels, no skew, known principal point ``c``; the unknowns are the rotation R,
the translation t and the focal length f of ``u = f * (R X + t)_xy / (R X + t)_z + c``.

Why and how: docs/solver.md, "UPnP".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dockfactory.solver.checks import as_principal_point, check_correspondences
from dockfactory.solver.errors import NoValidCamera

__all__ = ["Candidate", "upnp", "focal_sweep", "PLANAR_TOL", "NEAR_PLANAR_TOL"]

# sqrt(lambda_3 / lambda_1) of the point scatter: below PLANAR_TOL the set counts as planar (only
# the planar branch runs); below NEAR_PLANAR_TOL both branches run.
PLANAR_TOL = 1e-5
NEAR_PLANAR_TOL = 0.05

_PAIRS4 = np.array([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)])
_PAIRS3 = np.array([(0, 1), (0, 2), (1, 2)])


class CameraPose:
    """Rotation (3, 3) and translation (3,) views of a result's ``cam_from_world`` (4, 4)."""

    @property
    def rotation(self) -> np.ndarray:
        return self.cam_from_world[:3, :3]

    @property
    def translation(self) -> np.ndarray:
        return self.cam_from_world[:3, 3]


@dataclass(frozen=True)
class Candidate(CameraPose):
    """One closed-form solution.

    ``cam_from_world``: (4, 4); ``focal_px``: focal length (px); ``rmse_px``: reprojection RMS
    over the points, sqrt(mean |uv_hat - uv|^2) (px, Euclidean per point); ``method``: which
    branch produced it ("general-k1", "general-k2", "general-k3", "planar-k1", "dlt4").
    """

    cam_from_world: np.ndarray
    focal_px: float
    rmse_px: float
    method: str


# ----------------------------------------------------------------------------------------------
# relinearisation structure for K = 3: entries z = (b_00, b_01, b_02, b_11, b_12, b_22,
# c_00, ..., c_22), b_kl = beta_k beta_l, c_kl = f^2 beta_k beta_l.

def _relin_structure_k3():
    mono = [(k, l) for k in range(3) for l in range(k, 3)]
    entries = [(k, l, e) for e in (0, 1) for (k, l) in mono]
    groups: dict = {}
    for p in range(12):
        for q in range(p, 12):
            kp, lp, ep = entries[p]
            kq, lq, eq = entries[q]
            key = (tuple(sorted((kp, lp, kq, lq))), ep + eq)
            groups.setdefault(key, []).append((p, q))
    lhs, rhs = [], []
    for members in groups.values():
        for other in members[1:]:
            lhs.append(members[0])
            rhs.append(other)
    return np.array(lhs), np.array(rhs)


_K3_LHS, _K3_RHS = _relin_structure_k3()          # 33 identities z_p z_q = z_r z_s
_IU7 = np.triu_indices(7)                          # products of (1, mu_1, ..., mu_6)
_W7 = np.where(_IU7[0] == _IU7[1], 1.0, 2.0)
_IU6 = np.triu_indices(6)
_W6 = np.where(_IU6[0] == _IU6[1], 1.0, 2.0)


def _relinearise_k3(z0: np.ndarray, nb: np.ndarray) -> np.ndarray:
    """mu (6,) from the 33 identities z_p z_q = z_r z_s with z = z0 + nb @ mu.

    Each identity is a quadratic form in (1, mu); its 28 distinct coefficients are linear in
    the relinearised unknowns (mu_m, mu_m mu_n): 33 equations, 27 unknowns, least squares.
    """
    zz = np.empty((z0.size, 7))
    zz[:, 0] = z0
    zz[:, 1:] = nb
    e, f = zz[_K3_LHS[:, 0]], zz[_K3_LHS[:, 1]]
    g, h = zz[_K3_RHS[:, 0]], zz[_K3_RHS[:, 1]]
    q = e[:, :, None] * f[:, None, :] - g[:, :, None] * h[:, None, :]
    q = q + q.transpose(0, 2, 1)
    rows = q[:, _IU7[0], _IU7[1]] * (0.5 * _W7)                # (33, 28); column 0 = constant
    a = rows[:, 1:]
    ata = a.T @ a
    ata.flat[::28] += 1e-14 * np.trace(ata) / 27.0
    y = np.linalg.solve(ata, -(a.T @ rows[:, 0]))
    return y[:6]


# ----------------------------------------------------------------------------------------------

_IU = {k: np.triu_indices(k) for k in (1, 2, 3)}
_WU = {k: np.where(_IU[k][0] == _IU[k][1], 1.0, 2.0) for k in (1, 2, 3)}


def _distance_tensors(basis: np.ndarray, pairs: np.ndarray, k: int):
    """G, H (P, k, k): |dx|^2 + |dy|^2 and |dw|^2 as quadratic forms in the null coefficients."""
    ncp = basis.shape[0] // 3
    v = basis[:, :k].reshape(ncp, 3, k)
    d = v[pairs[:, 0]] - v[pairs[:, 1]]                      # (P, 3, k)
    dxy = d[:, :2]
    g = np.einsum("pik,pil->pkl", dxy, dxy)
    h = d[:, 2, :, None] * d[:, 2, None, :]
    return g, h


def _linear_rows(g: np.ndarray, h: np.ndarray, k: int) -> np.ndarray:
    """Distance equations in the monomials (b, c) of the first ``k`` null vectors."""
    iu, w = _IU[k], _WU[k]
    out = np.empty((g.shape[0], 2 * w.size))
    out[:, :w.size] = g[:, iu[0], iu[1]] * w
    out[:, w.size:] = h[:, iu[0], iu[1]] * w
    return out


def _beta_f2_from_monomials(b: np.ndarray, c: np.ndarray, k: int):
    """(beta (k,), f^2) from monomials b_kl ~ beta beta^T and c_kl ~ f^2 beta beta^T."""
    iu = _IU[k]
    bm = np.zeros((k, k))
    bm[iu] = b
    bm.T[iu] = b
    cm = np.zeros((k, k))
    cm[iu] = c
    cm.T[iu] = c
    den = float(np.vdot(bm, bm))
    if not den > 0.0:
        return None
    f2 = float(np.vdot(bm, cm)) / den
    evals, evecs = np.linalg.eigh(bm)
    if not (evals[-1] > 0.0 and f2 > 0.0):
        return None
    return np.sqrt(evals[-1]) * evecs[:, -1], f2


def _procrustes(xw: np.ndarray, pc: np.ndarray):
    """R, t minimising |R xw + t - pc|; ``xw`` (n, 3) centred (mean 0), ``pc`` (n, 3)."""
    mc = pc.sum(axis=0) * (1.0 / pc.shape[0])
    u, _, vt = np.linalg.svd(xw.T @ pc)                      # xw centred: no need to centre pc
    r = vt.T @ u.T
    if _det3(r) < 0.0:
        vt[2] = -vt[2]
        r = vt.T @ u.T
    return r, mc


def _det3(m) -> float:
    (a, b, c), (d, e, f), (g, h, i) = m.tolist()
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)


class _Problem:
    """Normalised data shared by all branches of one closed-form solve."""

    def __init__(self, p3: np.ndarray, p2: np.ndarray, pp: np.ndarray):
        self.p3, self.p2, self.pp = p3, p2, pp
        self.n = n = p3.shape[0]
        self.c0 = p3.sum(axis=0) * (1.0 / n)
        xc = p3 - self.c0
        lam, vec = np.linalg.eigh(xc.T @ xc * (1.0 / n))
        lam = lam[::-1]
        self.axes = vec[:, ::-1]
        self.s3 = float(np.sqrt(lam[0]))
        self.xn = xc * (1.0 / self.s3)                          # normalised world points
        self.ln = np.maximum(lam / lam[0], 0.0)                 # normalised variances
        uv = p2 - pp
        k2 = float(np.vdot(uv, uv)) / n
        self.k = float(np.sqrt(k2)) if k2 > 0.0 else 1.0
        self.un = uv * (1.0 / self.k)
        self.planarity = float(np.sqrt(self.ln[2]))
        self.rejected_depth = 0

    def kernel(self, alphas: np.ndarray, fn: float = 1.0) -> np.ndarray:
        """Eigenvectors of M^T M, ascending; unknowns (x, y, z / fn) per control point."""
        ncp = alphas.shape[1]
        m = np.zeros((2 * self.n, 3 * ncp))
        m[0::2, 0::3] = alphas
        m[1::2, 1::3] = alphas
        if fn == 1.0:
            m[0::2, 2::3] = alphas * -self.un[:, 0:1]
            m[1::2, 2::3] = alphas * -self.un[:, 1:2]
        else:
            m[0::2, 2::3] = alphas * (-self.un[:, 0:1] / fn)
            m[1::2, 2::3] = alphas * (-self.un[:, 1:2] / fn)
        return np.linalg.eigh(m.T @ m)[1]                       # ascending eigenvalues

    def candidate(self, alphas, xw, basis, beta, f2, method):
        """Candidate from null-space coefficients; None when it is not a valid camera."""
        fn = float(np.sqrt(f2))
        cps = (basis[:, :beta.size] @ beta).reshape(-1, 3)
        cps[:, 2] *= fn
        pc = alphas @ cps
        if pc[:, 2].sum() < 0.0:
            pc = -pc
        r, tn = _procrustes(xw, pc)
        return self.finish(r, tn, fn, method)

    def finish(self, r, tn, fn, method):
        """Candidate in world units / pixels, with its reprojection RMS (None if invalid)."""
        # camera point of world point i: s3 * (R xn_i + tn); reprojection in normalised pixels
        pc = self.xn @ r.T + tn
        z = pc[:, 2]
        if not z.min() > 0.0 or not np.isfinite(fn) or not fn > 0.0:
            self.rejected_depth += 1
            return None
        res = pc[:, :2] * (fn / z)[:, None] - self.un
        rmse = self.k * float(np.sqrt(np.vdot(res, res) / self.n))
        if not np.isfinite(rmse):
            return None
        cam = np.eye(4)
        cam[:3, :3] = r
        cam[:3, 3] = self.s3 * tn - r @ self.c0
        return Candidate(cam, fn * self.k, rmse, method)


def _general_alphas(pr: _Problem):
    a = pr.xn @ (pr.axes / np.sqrt(pr.ln))                   # (n, 3)
    alphas = np.empty((pr.n, 4))
    alphas[:, 1:] = a
    alphas[:, 0] = 1.0 - a.sum(axis=1)
    ln = pr.ln
    dist2 = np.array([ln[0], ln[1], ln[2], ln[0] + ln[1], ln[0] + ln[2], ln[1] + ln[2]])
    return alphas, dist2


def _general_branch(pr: _Problem, dims) -> list:
    alphas, dist2 = _general_alphas(pr)
    basis = pr.kernel(alphas)
    g, h = _distance_tensors(basis, _PAIRS4, max(dims))
    out = []
    for k in dims:
        try:
            sol = _solve_k(g[:, :k, :k], h[:, :k, :k], dist2, k)
        except np.linalg.LinAlgError:
            sol = None
        if sol is None:
            continue
        cand = pr.candidate(alphas, pr.xn, basis, sol[0], sol[1], f"general-k{k}")
        if cand is not None:
            out.append(cand)
    return out


def _solve_k(g, h, dist2, k):
    if k == 1:
        # least squares in (beta^2, f^2 beta^2): 2x2 normal equations
        a0, a1 = g[:, 0, 0], h[:, 0, 0]
        s00, s01, s11 = float(a0 @ a0), float(a0 @ a1), float(a1 @ a1)
        r0, r1 = float(a0 @ dist2), float(a1 @ dist2)
        det = s00 * s11 - s01 * s01
        if not abs(det) > 1e-300:
            return None
        x0 = (s11 * r0 - s01 * r1) / det
        x1 = (s00 * r1 - s01 * r0) / det
        if not (x0 > 0.0 and x1 > 0.0):
            return None
        return np.array([np.sqrt(x0)]), x1 / x0
    rows = _linear_rows(g, h, k)
    if k == 2:
        if rows.shape[0] == 6:
            x = np.linalg.solve(rows, dist2)
        else:
            x = np.linalg.lstsq(rows, dist2, rcond=None)[0]
        return _beta_f2_from_monomials(x[:3], x[3:], 2)
    # k == 3: 6 equations, 12 monomials -> affine family z0 + nb @ mu, relinearised.
    u, s, vt = np.linalg.svd(rows)
    if not s[-1] > 1e-12 * s[0]:
        return None
    z0 = vt[:6].T @ ((u.T @ dist2) / s)
    nb = vt[6:].T                                               # (12, 6)
    z = z0 + nb @ _relinearise_k3(z0, nb)
    return _beta_f2_from_monomials(z[:6], z[6:], 3)


def _planar_setup(pr: _Problem):
    a = pr.xn @ (pr.axes[:, :2] / np.sqrt(pr.ln[:2]))
    alphas = np.empty((pr.n, 3))
    alphas[:, 1:] = a
    alphas[:, 0] = 1.0 - a.sum(axis=1)
    normal = pr.axes[:, 2]
    xw = pr.xn - np.outer(pr.xn @ normal, normal)               # points projected on the plane
    dist2 = np.array([pr.ln[0], pr.ln[1], pr.ln[0] + pr.ln[1]])
    return alphas, xw, dist2


def _planar_branch(pr: _Problem) -> list:
    alphas, xw, dist2 = _planar_setup(pr)
    basis = pr.kernel(alphas)
    g, h = _distance_tensors(basis, _PAIRS3, 1)
    sol = _solve_k(g, h, dist2, 1)
    if sol is None:
        return []
    cand = pr.candidate(alphas, xw, basis, sol[0], sol[1], "planar-k1")
    return [] if cand is None else [cand]


# the four quadrics on a DLT camera P = [M | m]: rows of diag(1/f, 1/f, 1) M orthogonal and of
# equal norm  <=>  m1.m2 = m1.m3 = m2.m3 = 0, |m1|^2 = |m2|^2 (f cancels).
_IU4 = np.triu_indices(4)
_W4 = np.where(_IU4[0] == _IU4[1], 1.0, 2.0)
_MINORS4 = np.array([(i, j, k, l) for i in range(4) for j in range(i + 1, 4)
                     for k in range(4) for l in range(k + 1, 4)])
_IU6_ALL = _IU6


def _dlt4_branch(pr: _Problem) -> list:
    """Exactly four non-coplanar points: DLT null space (4-dim) + relinearisation."""
    p = _dlt4_camera_matrix(pr)
    mm = p[:, :3]
    if np.linalg.det(mm) < 0.0:
        p = -p
        mm = -mm
    n12 = 0.5 * (mm[0] @ mm[0] + mm[1] @ mm[1])
    n3 = mm[2] @ mm[2]
    if n3 <= 0.0 or n12 <= 0.0:
        return []
    fn = float(np.sqrt(n12 / n3))
    kinv = np.diag([1.0 / fn, 1.0 / fn, 1.0])
    scale = np.sqrt(n3)
    r0 = kinv @ mm / scale
    u, _, vt4 = np.linalg.svd(r0)
    r = u @ vt4
    tn = kinv @ p[:, 3] / scale
    cand = pr.finish(r, tn, fn, "dlt4")
    return [] if cand is None else [cand]


def _dlt4_camera_matrix(pr: _Problem) -> np.ndarray:
    """(3, 4) DLT camera P = [M | m] (normalised units, up to scale) in the 4-dim null space of
    the four points' projection equations, pinned down by the four quadrics (relinearised)."""
    xh = np.hstack([pr.xn, np.ones((4, 1))])
    m = np.zeros((8, 12))
    m[0::2, 0:4] = xh
    m[0::2, 8:12] = -xh * pr.un[:, 0:1]
    m[1::2, 4:8] = xh
    m[1::2, 8:12] = -xh * pr.un[:, 1:2]
    _, _, vt = np.linalg.svd(m)
    ps = vt[8:].reshape(4, 3, 4)[:, :, :3]                      # (basis k, row r, col)
    g = np.einsum("kri,lsi->rskl", ps, ps)                       # m_r . m_s as forms in a
    forms = [g[0, 1], g[0, 2], g[1, 2], g[0, 0] - g[1, 1]]
    a_rows = np.array([(0.5 * (q + q.T))[_IU4] * _W4 for q in forms])   # (4, 10)
    _, _, vt2 = np.linalg.svd(a_rows)
    kb = vt2[4:]                                                 # (6, 10): Veronese = kb^T lam
    ks = np.zeros((6, 4, 4))
    ks[:, _IU4[0], _IU4[1]] = kb
    ks = ks + np.triu(ks, 1).transpose(0, 2, 1)
    coef = _dlt4_null_coefficients(ks)
    return np.einsum("k,kij->ij", coef, vt[8:].reshape(4, 3, 4))


def _dlt4_null_coefficients(ks: np.ndarray) -> np.ndarray:
    """(4,) coefficients of the camera in the DLT null space: the Veronese matrix S = sum_m
    lam_m ks_m (4, 4) must have rank one (its 2 x 2 minors vanish, quadratic in lam)."""
    i, j, k, l = _MINORS4.T
    # S_ik S_jl - S_il S_jk = 0, quadratic in lam
    t1 = ks[:, i, k][:, None, :] * ks[:, j, l][None, :, :]
    t2 = ks[:, i, l][:, None, :] * ks[:, j, k][None, :, :]
    quad = t1 - t2                                               # (6, 6, 36)
    quad = 0.5 * (quad + quad.transpose(1, 0, 2))
    rows = quad[_IU6_ALL[0], _IU6_ALL[1]].T * _W6                # (36, 21)
    _, _, vt3 = np.linalg.svd(rows)
    lam2 = np.zeros((6, 6))
    lam2[_IU6_ALL] = vt3[-1]
    lam2 = lam2 + np.triu(lam2, 1).T
    ev, evec = np.linalg.eigh(lam2)
    lam = evec[:, -1] if abs(ev[-1]) >= abs(ev[0]) else evec[:, 0]
    s_mat = np.einsum("m,mij->ij", lam, ks)
    ev, evec = np.linalg.eigh(s_mat)
    return evec[:, -1] if abs(ev[-1]) >= abs(ev[0]) else evec[:, 0]


def _focal_sweep(pr: _Problem, num: int = 13, every: bool = False) -> list:
    """Fallback when noise swamps the focal information: calibrated EPnP on a grid of focals.

    For each f on a geometric grid (normalised focal 0.25 .. 64, i.e. fields of view from very
    wide to very narrow), the general (or planar) kernel with f fixed gives a pose; the grid
    point with the smallest reprojection error is returned as candidate "sweep". Refinement
    then slides along the (flat) focal valley.
    """
    setups = []
    if pr.planarity < 0.3 or pr.n <= 5:
        # with few points only the planar parametrisation (9 unknowns) has a 1-dim kernel
        alphas, xw, dist2 = _planar_setup(pr)
        setups.append((alphas, xw, dist2, _PAIRS3))
    if pr.planarity >= PLANAR_TOL and pr.n >= 6:
        alphas, dist2 = _general_alphas(pr)
        setups.append((alphas, pr.xn, dist2, _PAIRS4))
    best = None
    per_focal = {}
    for alphas, xw, dist2, pairs in setups:
        ncp = alphas.shape[1]
        for fn in np.geomspace(0.25, 64.0, num):
            # calibrated EPnP at this focal: unknowns (x, y, z) per control point
            basis = pr.kernel(alphas, fn)
            v = basis[:, 0].reshape(ncp, 3)
            d = v[pairs[:, 0]] - v[pairs[:, 1]]
            lhs = np.sum(d * d, axis=1)
            b2 = float(lhs @ dist2) / float(lhs @ lhs)
            scaled = basis[:, :1] / np.tile([1.0, 1.0, fn], ncp)[:, None]
            cand = pr.candidate(alphas, xw, scaled, np.array([np.sqrt(b2)]), fn * fn, "sweep")
            if cand is not None and (best is None or cand.rmse_px < best.rmse_px):
                best = cand
            if cand is not None and (fn not in per_focal or
                                     cand.rmse_px < per_focal[fn].rmse_px):
                per_focal[fn] = cand
    if every:
        return [per_focal[k] for k in sorted(per_focal)]
    return [] if best is None else [best]


def upnp(points_3d, points_2d, principal_point, *, checked: bool = False,
         sweep_above_px: float | None = None, first_only: bool = False) -> list:
    """Every closed-form candidate (R, t, f) for a 3D-2D correspondence set, best first.

    Parameters
    ----------
    points_3d, points_2d, principal_point, checked : (N, 3) float64 mm, N >= 4; (N, 2) float64 px; (2,) px; bool
        ``checked=True`` skips input validation (internal callers that already did it).
    sweep_above_px : float or None
        Branches: N >= 6 general K = 1, 2, 3; N = 5 general K = 2, 3; N = 4 DLT relinearisation; planar sets the
        planar branch only, near-planar ones (spread ratio < NEAR_PLANAR_TOL) both. If no branch gives a valid camera,
        or the best reprojection RMS exceeds ``sweep_above_px`` (when given), a focal sweep adds a fallback candidate
        (method "sweep").
    first_only : bool
        The cheap path used before refinement: only the smallest null-space dimension that determines the problem
        (K = 1 for N >= 6, K = 2 for N = 5, the DLT for N = 4, planar K = 1 for planar sets); it returns an empty list
        instead of raising when that gives no valid camera, so that the caller can fall back to the full set.

    Returns
    -------
    list of Candidate
        Sorted by reprojection RMS; candidates that are not valid cameras (f^2 <= 0, points behind the camera,
        non-finite numbers) are dropped.

    Raises
    ------
    SolverError : InvalidSolverInput / TooFewPoints / DegenerateGeometry (bad input), NoValidCamera (none valid).
    """
    if checked:
        p3 = points_3d
        p2 = points_2d
        pp = principal_point
    else:
        p3, p2 = check_correspondences(points_3d, points_2d)
        pp = as_principal_point(principal_point)
    pr = _Problem(p3, p2, pp)
    planar = pr.planarity < PLANAR_TOL
    if first_only:
        return _cheapest_candidates(pr, planar)
    cands = _every_candidate(pr, planar)
    if not cands or (sweep_above_px is not None and min(c.rmse_px for c in cands) > sweep_above_px):
        cands += _focal_sweep(pr)
    if not cands:
        if pr.rejected_depth:
            raise NoValidCamera("points behind the camera: every closed-form camera that fits "
                                "the image points puts some of the 3D points behind it")
        raise NoValidCamera("closed form found no valid camera (every candidate had a negative "
                            "squared focal length)")
    cands.sort(key=lambda c: c.rmse_px)
    return cands


def _cheapest_candidates(pr: _Problem, planar: bool) -> list:
    """The smallest null-space dimension that determines the problem only (may be empty)."""
    if planar:
        return _planar_branch(pr)
    if pr.n == 4:
        return _dlt4_branch(pr)
    return _general_branch(pr, (2,) if pr.n == 5 else (1,))


def _every_candidate(pr: _Problem, planar: bool) -> list:
    """Every branch that applies to the point set (see :func:`upnp`), unsorted."""
    cands: list = []
    if pr.n == 4:
        cands += _planar_branch(pr)
        if not planar:
            cands += _dlt4_branch(pr)
    else:
        if not planar:
            dims = (2, 3) if pr.n == 5 else (1, 2, 3)
            cands += _general_branch(pr, dims)
        if pr.planarity < NEAR_PLANAR_TOL:
            cands += _planar_branch(pr)
    return cands


def focal_sweep(points_3d, points_2d, principal_point, num: int = 13) -> list:
    """Calibrated EPnP poses on a geometric grid of focal lengths (validated inputs).

    One :class:`Candidate` per grid focal that gives a valid camera, in increasing focal order;
    used by the refiner's profile search when the closed form lands in a wrong basin.
    """
    return _focal_sweep(_Problem(points_3d, points_2d, principal_point), num, every=True)
