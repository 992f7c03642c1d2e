"""Marker identification: which layout marker is each detection? (hypothesise and verify)

A detector reports, per marker it sees, a class (section A or B) and a 2D centre, but no id.
Ids follow from the known layout:

1. Hypothesise (per section, vectorised): the camera faces the markers, so to first order the
   image of a section's markers is a similarity of their (X, -Y) coordinates (weak perspective,
   small roll). Every pair of detections labelled with the section and every ordered pair of the
   section's markers fixes one similarity; those with a plausible scale and roll project all the
   section's markers, and a hypothesis scores the markers that land within a loose gate of some
   detection (of any class: labels may be swapped).
2. Verify (full perspective): the best-scoring hypotheses are fitted by the uncalibrated solver
   (UPnP + Levenberg-Marquardt) on their matches, all markers are re-projected, re-matched
   within a tight gate, and refitted. A verified hypothesis is the set of (marker, detection)
   pairs it explains and its reprojection RMS.
3. Decide: the hypothesis explaining the most detections wins (ties: smaller RMS). If another
   verified hypothesis that gives some detection a different marker explains as many
   detections, the identification is ambiguous and SolverError is raised: the solver reports
   ambiguity instead of guessing. Hypotheses that differ only in which of two nearby
   detections (a duplicate) serves a marker agree on every identity; the better fit is kept.
4. Both sections: one joint fit (shared focal) re-projects all markers and assigns every
   detection to the nearest projected marker within the tight gate, one to one; detections
   left over are spurious (inlier mask False); a detection whose class label disagrees with its
   marker's section is flagged as swapped.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dockfactory.solver.checks import as_points
from dockfactory.solver.errors import AmbiguousIdentification, SolverError

__all__ = ["Identification", "identify_markers", "parse_detections"]


@dataclass(frozen=True)
class Identification:
    """Per detection (N rows, input order): ``marker_ids`` (id or None), ``points_2d`` (N, 2),
    ``class_ids`` (N,) int (0 = A, 1 = B, as given), ``swapped`` (N,) bool, ``inliers`` (N,)
    bool (identified), ``rmse_px`` of the final joint fit."""

    marker_ids: tuple
    points_2d: np.ndarray
    class_ids: np.ndarray
    swapped: np.ndarray
    inliers: np.ndarray
    rmse_px: float


_CLASS_NAMES = {"A": 0, "B": 1, "REDA": 0, "BLUEB": 1, "0": 0, "1": 1}


def parse_detections(detections):
    """(class_ids (N,) int in {0, 1}, points_2d (N, 2)) from a pair (classes, points_2d)."""
    try:
        classes, uv = detections
    except (TypeError, ValueError):
        raise SolverError("detections: expected a pair (class_ids (N,), points_2d (N, 2))") \
            from None
    uv = as_points("detections points_2d", uv, 2)
    cls = []
    for c in np.asarray(classes, dtype=object).reshape(-1):
        key = str(c).strip().upper()
        if isinstance(c, (float, np.floating)) and float(c).is_integer():
            key = str(int(c))
        if key not in _CLASS_NAMES:
            raise SolverError(f"detections: unknown class {c!r} (use 0/1, 'A'/'B' or "
                              "'RedA'/'BlueB')")
        cls.append(_CLASS_NAMES[key])
    cls = np.array(cls, dtype=int)
    if cls.size != uv.shape[0]:
        raise SolverError(f"detections: {cls.size} class ids but {uv.shape[0]} points: shapes "
                          "do not match")
    return cls, uv


@dataclass
class _Hyp:
    pairs: dict          # marker index (in section) -> detection index
    rmse: float
    model: tuple         # (cam_from_section (4, 4), focal)

    def conflicts(self, other) -> bool:
        inv_a = {d: m for m, d in self.pairs.items()}
        for m, d in other.pairs.items():
            if m in self.pairs and self.pairs[m] != d:
                return True
            if d in inv_a and inv_a[d] != m:
                return True
        return False

    def identity_conflicts(self, other) -> bool:
        """True when some detection is given a different marker by ``other``.

        Two hypotheses that differ only in which detection serves a marker (a duplicate or a
        spurious detection next to it) agree on every identity: that is not an ambiguity, and the
        better-fitting one is kept.
        """
        inv_a = {d: m for m, d in self.pairs.items()}
        return any(d in inv_a and inv_a[d] != m for m, d in other.pairs.items())


def _similarity_hypotheses(w, z, anchor_idx, scale_range, max_roll_rad, gate_frac, spacing_mm,
                           max_keep):
    """Score all similarity hypotheses; return list of (score, a, b) best first."""
    m = w.size
    ii, jj = np.triu_indices(anchor_idx.size, 1)
    di, dj = anchor_idx[ii], anchor_idx[jj]
    mi, mj = np.nonzero(~np.eye(m, dtype=bool))
    zi = z[di][:, None]
    zj = z[dj][:, None]
    wi = w[mi][None, :]
    wj = w[mj][None, :]
    a = (zj - zi) / (wj - wi)                                  # (P, Q)
    b = zi - a * wi
    a = a.ravel()
    b = b.ravel()
    s = np.abs(a)
    ok = (s >= scale_range[0]) & (s <= scale_range[1]) & (np.abs(np.angle(a)) <= max_roll_rad)
    if not ok.any():
        return []
    a, b, s = a[ok], b[ok], s[ok]
    proj = a[:, None] * w[None, :] + b[:, None]                # (H, M)
    dist = np.abs(proj[:, :, None] - z[None, None, :])         # (H, M, N)
    dmin = dist.min(axis=2)
    gate = gate_frac * spacing_mm * s
    hit = dmin <= gate[:, None]
    score = hit.sum(axis=1) - 1e-3 * (dmin * hit).sum(axis=1) / np.maximum(gate, 1e-9)
    order = np.argsort(-score)[:max_keep * 8]
    out = []
    seen = set()
    for h in order:
        if hit[h].sum() < 3:
            break
        nearest = dist[h].argmin(axis=1)
        key = tuple(int(nearest[k]) if hit[h, k] else -1 for k in range(m))
        if key in seen:
            continue
        seen.add(key)
        out.append(key)
        if len(out) >= max_keep:
            break
    return out


def _one_to_one(proj, z, gate):
    """Greedy one-to-one matching marker -> detection by distance within ``gate``."""
    d = np.abs(proj[:, None] - z[None, :])
    pairs = {}
    used = set()
    flat = np.argsort(d, axis=None)
    for k in flat:
        mi, di = divmod(int(k), z.size)
        if d[mi, di] > gate:
            break
        if mi in pairs or di in used:
            continue
        pairs[mi] = di
        used.add(di)
    return pairs


class _Fit:
    """A fitted section pose that remembers the pairs it was fitted on."""

    def __init__(self, ref, pairs):
        self.rotation, self.translation = ref.rotation, ref.translation
        self.focal_px, self.rmse_px = ref.focal_px, ref.rmse_px
        self.pairs = dict(pairs)


def _fit(p3, uv, pairs, pp, accept_rmse=None):
    from dockfactory.solver.checks import check_correspondences
    from dockfactory.solver.pnpf import solve_checked
    ms = sorted(pairs)
    q3, q2 = check_correspondences(p3[ms], uv[[pairs[m] for m in ms]])
    rescue = None if accept_rmse is None else 4.0 * accept_rmse
    ref = solve_checked(q3, q2, pp, check_focal=False, accept_rmse=accept_rmse,
                        rescue_below=rescue)[0]
    return _Fit(ref, pairs)


def _fit_leaving_one_out(p3, uv, pairs, pp, max_rmse):
    """Best fit (lowest RMS, at most ``max_rmse``) over the hypothesis without one of its pairs,
    or None: the loose similarity gate can pair a marker missing from the image with a stray
    detection, and that one wrong pair spoils the fit of all the others."""
    best = None
    for m in pairs:
        sub = {k: d for k, d in pairs.items() if k != m}
        try:
            ref = _fit(p3, uv, sub, pp, accept_rmse=max_rmse)
        except (SolverError, np.linalg.LinAlgError):
            continue
        if ref.rmse_px <= max_rmse and (best is None or ref.rmse_px < best.rmse_px):
            best = ref
    return best


def _project(p3, ref, pp):
    pc = p3 @ ref.rotation.T + ref.translation
    z = pc[:, 2]
    if np.any(z <= 0):
        return None
    uv = ref.focal_px * pc[:, :2] / z[:, None] + pp
    return uv[:, 0] + 1j * uv[:, 1]


def _verify(p3, uv, z, pairs, pp, gate, max_rmse, min_matches, rounds=3, leave_one_out=False):
    """Fit, re-project, re-match within ``gate`` px, refit. Returns _Hyp or None.

    A hypothesis is kept only if its final fit explains ``min_matches`` or more detections
    with a reprojection RMS of at most ``max_rmse`` px (consistent with the pixel noise).
    """
    ref = None
    for rnd in range(rounds):
        if len(pairs) < min_matches:
            return None
        try:
            ref = _fit(p3, uv, pairs, pp, accept_rmse=max_rmse)
        except (SolverError, np.linalg.LinAlgError):
            ref = None
        if leave_one_out and rnd == 0 and (ref is None or not ref.rmse_px <= max_rmse) \
                and len(pairs) > min_matches:
            ref = _fit_leaving_one_out(p3, uv, pairs, pp, max_rmse)
            if ref is not None:
                pairs = ref.pairs
        if ref is None:
            return None
        proj = _project(p3, ref, pp)
        if proj is None:
            return None
        new = _one_to_one(proj, z, min(gate, 0.3 * _min_spacing(proj)))
        if new == pairs:
            break
        pairs = new
    if ref is None or len(pairs) < min_matches:
        return None
    if pairs != ref.pairs:
        try:
            ref = _fit(p3, uv, pairs, pp, accept_rmse=max_rmse)
        except (SolverError, np.linalg.LinAlgError):
            return None
    if not ref.rmse_px <= max_rmse:
        return None
    cam = np.eye(4)
    cam[:3, :3], cam[:3, 3] = ref.rotation, ref.translation
    return _Hyp(dict(pairs), ref.rmse_px, (cam, ref.focal_px))


def _min_spacing(p):
    d = np.abs(p[:, None] - p[None, :])
    d[np.eye(p.size, dtype=bool)] = np.inf
    return float(d.min())


def _identify_section(p3, uv, z, cls, section_class, pp, opts):
    """All verified hypotheses for one section, best first (most matches, then smallest RMS)."""
    w = p3[:, 0] - 1j * p3[:, 1]
    spacing_mm = _min_spacing(w)
    labelled = np.flatnonzero(cls == section_class)
    hyps = []
    tried = set()
    for anchors in (labelled, np.arange(z.size)):
        if anchors.size < 2:
            continue
        keys = _similarity_hypotheses(w, z, anchors, opts["scale_range"],
                                      np.radians(opts["max_roll_deg"]), opts["loose_gate"],
                                      spacing_mm, opts["max_hypotheses"])
        for key in keys:
            if key in tried:
                continue
            tried.add(key)
            pairs = {m: d for m, d in enumerate(key) if d >= 0}
            h = _verify(p3, uv, z, pairs, pp, opts["gate"], opts["max_rmse"],
                        opts["min_matches"], leave_one_out=opts["leave_one_out"])
            if h is not None and not any(h.pairs == g.pairs for g in hyps):
                hyps.append(h)
        if hyps and max(len(h.pairs) for h in hyps) >= min(p3.shape[0], 5):
            break          # the labelled anchors already explain the section well
    hyps.sort(key=lambda h: (-len(h.pairs), h.rmse))
    return hyps


def _rivals(hyps):
    """Verified hypotheses that give some detection another identity than the best one does and
    explain as many detections."""
    if not hyps:
        return []
    best = hyps[0]
    return [h for h in hyps[1:] if len(h.pairs) >= len(best.pairs) and best.identity_conflicts(h)]


def identify_markers(markers, principal_point, detections, *, sigma_px: float = 1.0,
                     gate_px: float | None = None, loose_gate: float = 0.4,
                     max_roll_deg: float = 30.0, scale_range=(0.05, 50.0),
                     max_hypotheses: int = 8, min_matches: int = 4) -> Identification:
    """Assign layout marker ids to detections (see the module docstring).

    ``markers``: sequence of :class:`generator.layout.Marker` (both sections).
    ``principal_point``: (2,) px. ``detections``: pair (class_ids (N,), points_2d (N, 2) px),
    classes 0/1 or "A"/"B" (or "RedA"/"BlueB").
    ``sigma_px``: expected std of the detected centres (px); a hypothesis counts as explaining
    the detections if its reprojection RMS is at most 2.5 sigma, and detections match markers
    within ``gate_px`` (default 4 sigma, at most 0.3 x the projected marker spacing).
    ``loose_gate``: hypothesis gate as a fraction of the smallest marker spacing.
    ``max_roll_deg``, ``scale_range`` (px per mm): plausible image roll and scale (f / depth).
    ``min_matches``: markers a section hypothesis must explain (>= 4).

    Raises SolverError when a section cannot be identified with ``min_matches`` markers or when
    the identification is ambiguous (two conflicting assignments explain the detections
    equally well, even with the focal length shared between the sections).

    When identification fails for another reason, it is tried once more with hypotheses that
    may shed one pair: the loose similarity gate can pair a marker missing from the image with
    a stray detection, and that one wrong pair spoils the fit of the others (identification
    benchmark, 1000 frames with 15 % missing markers, 0-3 spurious detections and 0-2 swapped
    classes: refusals 1.1 % -> 0.5 %, wrong ids unchanged; the retry costs time only on frames
    that would otherwise be refused).
    """
    from dockfactory.solver.checks import as_principal_point
    from dockfactory.solver.docking import layout_arrays

    ids, sections, pts = layout_arrays(markers)
    pp = as_principal_point(principal_point)
    cls, uv = parse_detections(detections)
    if not (np.isfinite(sigma_px) and sigma_px > 0):
        raise SolverError(f"sigma_px must be positive and finite, got {sigma_px}")
    if gate_px is not None and not (np.isfinite(gate_px) and gate_px > 0):
        raise SolverError(f"gate_px must be positive and finite, got {gate_px}")
    min_matches = max(4, int(min_matches))
    gate = float(gate_px) if gate_px is not None else 4.0 * float(sigma_px)
    opts = {"gate": gate, "max_rmse": 2.5 * float(sigma_px), "loose_gate": float(loose_gate),
            "max_roll_deg": max_roll_deg, "scale_range": scale_range,
            "max_hypotheses": int(max_hypotheses), "min_matches": min_matches,
            "leave_one_out": False}
    try:
        return _search(ids, sections, pts, pp, cls, uv, opts)
    except AmbiguousIdentification:
        raise
    except SolverError as first:
        try:
            return _search(ids, sections, pts, pp, cls, uv, {**opts, "leave_one_out": True})
        except SolverError:
            raise first from None


def _search(ids, sections, pts, pp, cls, uv, opts) -> Identification:
    """Hypothesise, verify and decide on validated inputs (see :func:`identify_markers`)."""
    min_matches, gate = opts["min_matches"], opts["gate"]
    z = uv[:, 0] + 1j * uv[:, 1]
    sel = {s: [k for k, sec in enumerate(sections) if sec == s] for s in ("A", "B")}
    hyps = {}
    for s, c in (("A", 0), ("B", 1)):
        hyps[s] = _identify_section(pts[sel[s]], uv, z, cls, c, pp, opts)
        if not hyps[s]:
            raise SolverError(f"section {s}: could not identify {min_matches} or more markers "
                              f"among {uv.shape[0]} detections (within {gate:.3g} px)")
    # a section with rivals is re-judged jointly with the other section (shared focal length)
    order = sorted(("A", "B"), key=lambda s: (len(_rivals(hyps[s])), -len(hyps[s][0].pairs)))
    strong, weak = order
    for s, other in ((weak, strong), (strong, weak)):
        rivals = _rivals(hyps[s])
        if not rivals:
            continue
        if _rivals(hyps[other]):
            _raise_ambiguous(s, hyps[s][0], rivals[0], ids, sel[s])
        anchor = hyps[other][0]
        judged = []
        for h in [hyps[s][0]] + rivals:
            rmse = _joint_rmse(s, h, other, anchor, pts, sel, uv, pp, opts["max_rmse"])
            if rmse <= opts["max_rmse"]:
                judged.append((rmse, h))
        if len(judged) != 1:
            if not judged:
                raise SolverError(f"section {s}: no assignment is consistent with section "
                                  f"{other} under a shared focal length")
            judged.sort(key=lambda x: x[0])
            _raise_ambiguous(s, judged[0][1], judged[1][1], ids, sel[s])
        hyps[s] = [judged[0][1]]
    best = {s: hyps[s][0] for s in ("A", "B")}
    # joint fit on the union (detections claimed by both sections are left out of this fit)
    claimed = {}
    for s, h in best.items():
        for m, d in h.pairs.items():
            claimed.setdefault(d, []).append(s)
    fit = {s: [(m, d) for m, d in h.pairs.items() if len(claimed[d]) == 1]
           for s, h in best.items()}
    for s in fit:
        if len(fit[s]) < 4:
            raise SolverError(f"section {s}: only {len(fit[s])} markers identified without "
                              "conflict, at least 4 needed")
    out = _joint_fit(best["A"], best["B"], pts, sel, uv, pp, opts["max_rmse"],
                     fit["A"], fit["B"])
    # final one-to-one assignment of all detections to all projected markers
    proj = np.empty(len(ids), dtype=complex)
    for s, cam in (("A", out["cam_from_a"]), ("B", out["cam_from_b"])):
        pc = pts[sel[s]] @ cam[:3, :3].T + cam[:3, 3]
        q = out["focal_px"] * pc[:, :2] / pc[:, 2:3] + pp
        proj[sel[s]] = q[:, 0] + 1j * q[:, 1]
    pairs = _one_to_one(proj, z, min(gate, 0.3 * _min_spacing(proj)))
    marker_ids = [None] * uv.shape[0]
    for g, d in pairs.items():
        marker_ids[d] = ids[g]
    for s in ("A", "B"):
        n_s = sum(1 for g in pairs if sections[g] == s)
        if n_s < 4:
            raise SolverError(f"section {s}: only {n_s} detections match the fitted markers, "
                              "at least 4 needed")
    inl = np.array([mid is not None for mid in marker_ids])
    swapped = np.array([mid is not None and sections[ids.index(mid)] != "AB"[cls[k]]
                        for k, mid in enumerate(marker_ids)])
    rmse = max(out["rmse_a"], out["rmse_b"])
    return Identification(tuple(marker_ids), uv, cls, swapped, inl, float(rmse))


def _hyp_init(ha, hb):
    """Joint LM start from two section hypotheses: shared focal = geometric mean, translations
    rescaled so that f / depth is kept."""
    (ca, fa), (cb, fb) = ha.model, hb.model
    f0 = float(np.sqrt(fa * fb))
    ca, cb = ca.copy(), cb.copy()
    ca[:3, 3] *= f0 / fa
    cb[:3, 3] *= f0 / fb
    return ca, cb, f0


def _joint_fit(ha, hb, pts, sel, uv, pp, max_rmse, pairs_a=None, pairs_b=None):
    from dockfactory.solver.docking import solve_docking_arrays
    pa = sorted((pairs_a if pairs_a is not None else ha.pairs.items()))
    pb = sorted((pairs_b if pairs_b is not None else hb.pairs.items()))
    return solve_docking_arrays(pts[[sel["A"][m] for m, _ in pa]], uv[[d for _, d in pa]],
                                pts[[sel["B"][m] for m, _ in pb]], uv[[d for _, d in pb]], pp,
                                init=_hyp_init(ha, hb), accept_rmse=max_rmse)


def _joint_rmse(s, h, other, anchor, pts, sel, uv, pp, max_rmse):
    """RMS of the joint fit (shared focal) of hypothesis ``h`` of section ``s`` with the other
    section's best hypothesis; inf when the pair is inconsistent (shared detections, failure)."""
    if set(h.pairs.values()) & set(anchor.pairs.values()):
        return np.inf
    parts = {s: h, other: anchor}
    try:
        out = _joint_fit(parts["A"], parts["B"], pts, sel, uv, pp, max_rmse)
    except (SolverError, np.linalg.LinAlgError):
        return np.inf
    na, nb = len(parts["A"].pairs), len(parts["B"].pairs)
    return float(np.sqrt((na * out["rmse_a"] ** 2 + nb * out["rmse_b"] ** 2) / (na + nb)))


def _raise_ambiguous(s, h1, h2, ids, sel):
    a = {ids[sel[m]]: d for m, d in sorted(h1.pairs.items())}
    b = {ids[sel[m]]: d for m, d in sorted(h2.pairs.items())}
    raise AmbiguousIdentification(
        f"ambiguous identification of section {s}: marker->detection assignments {a} "
        f"(rms {h1.rmse:.2f} px) and {b} (rms {h2.rmse:.2f} px) explain the detections "
        "equally well; refusing to guess")
