"""Marker identification: which layout marker is each detection? (hypothesise and verify)

A detector reports, per marker it sees, a class (section A or B) and a 2D centre, but no id.
Ids follow from the known layout:

Why and how: docs/solver.md, "Identification".
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from dockfactory.core.layout_file import MAX_MARKERS_PER_SECTION
from dockfactory.solver.checks import (
    as_points,
    as_principal_point,
    check_correspondences,
    layout_arrays,
)
from dockfactory.solver.errors import (
    AmbiguousIdentification,
    IdentificationFailed,
    InvalidSolverInput,
    SolverError,
    TooFewPoints,
)
from dockfactory.solver.estimate import estimate_pnpf
from dockfactory.solver.joint import JointFit, JointStart, fit_joint
from dockfactory.solver.options import (
    DEFAULT_IDENTIFY,
    GATE_NOISE_FACTOR,
    FacingPrior,
    IdentifyOptions,
    RefineOptions,
)
from dockfactory.solver.refine import DEFAULT_REFINE
from dockfactory.solver.stats import chi2_logsf

RIVAL_P = 1e-6   # a rival the known noise explains at a lower p-value is none (eval.fit_gate.GATE_P's level)

__all__ = ["Identification", "identify_markers", "parse_detections"]


@dataclass(frozen=True)
class Identification:
    """Per detection (N rows, input order): ``marker_ids`` (id or None), ``points_2d`` (N, 2),
    ``class_ids`` (N,) int (0 = A, 1 = B, as given), ``swapped`` (N,) bool, ``inliers`` (N,)
    bool (identified), ``rmse_px`` of the final joint fit and ``start`` that fit (both poses
    and the shared focal: the verified start of a joint fit of the identified detections)."""

    marker_ids: tuple
    points_2d: np.ndarray
    class_ids: np.ndarray
    swapped: np.ndarray
    inliers: np.ndarray
    rmse_px: float
    start: JointStart | None = None


_CLASS_NAMES = {"A": 0, "B": 1, "REDA": 0, "BLUEB": 1, "0": 0, "1": 1}


def parse_detections(detections):
    """(class_ids (N,) int in {0, 1}, points_2d (N, 2)) from a pair (classes, points_2d)."""
    try:
        classes, uv = detections
    except (TypeError, ValueError):
        raise InvalidSolverInput("detections: expected a pair (class_ids (N,), points_2d "
                                 "(N, 2))") from None
    uv = as_points("detections points_2d", uv, 2)
    cls = []
    for c in np.asarray(classes, dtype=object).reshape(-1):
        key = str(c).strip().upper()
        if isinstance(c, (float, np.floating)) and float(c).is_integer():
            key = str(int(c))
        if key not in _CLASS_NAMES:
            raise InvalidSolverInput(f"detections: unknown class {c!r} (use 0/1, 'A'/'B' or "
                              "'RedA'/'BlueB')")
        cls.append(_CLASS_NAMES[key])
    cls = np.array(cls, dtype=int)
    if cls.size != uv.shape[0]:
        raise InvalidSolverInput(f"detections: {cls.size} class ids but {uv.shape[0]} points: "
                                 "shapes do not match")
    return cls, uv


@dataclass
class _Hyp:
    pairs: dict          # marker index (in section) -> detection index
    rmse: float
    model: tuple         # (cam_from_section (4, 4), focal)

    def identity_conflicts(self, other) -> bool:
        """True when some detection is given a different marker by ``other``.

        Two hypotheses that differ only in which detection serves a marker (a duplicate or a
        spurious detection next to it) agree on every identity: that is not an ambiguity, and the
        better-fitting one is kept.
        """
        inv_a = {d: m for m, d in self.pairs.items()}
        return any(d in inv_a and inv_a[d] != m for m, d in other.pairs.items())


DETECTIONS_SPARE = 16
HYPOTHESIS_BLOCK = 1 << 21   # (hypothesis, marker, detection) distances held at once: 32 MB


def _similarity_hypotheses(w, z, anchor_idx, prior: FacingPrior, spacing_mm, max_keep):
    """Score the similarities through every pair of anchor detections and ordered pair of
    markers (``w`` (M,) complex marker coordinates X - iY, ``z`` (N,) complex pixels); return
    up to ``max_keep`` distinct match keys (per marker: detection index or -1), best first.
    Computed in blocks of hypotheses, so memory stays bounded by ``HYPOTHESIS_BLOCK`` distances
    plus a few numbers per hypothesis, whatever the counts (the result does not depend on it)."""
    a, b = _plausible_similarities(w, z, anchor_idx, prior)
    if a.size == 0:
        return []
    s = np.abs(a)
    gate = prior.loose_gate * spacing_mm * s
    score, n_hit = np.empty(a.size), np.empty(a.size, dtype=np.int64)
    step = max(1, HYPOTHESIS_BLOCK // max(1, w.size * z.size))
    for k in range(0, a.size, step):
        nearest, dmin, hit = _matches(a[k:k + step], b[k:k + step], w, z, gate[k:k + step])
        n_hit[k:k + step] = hit.sum(axis=1)
        score[k:k + step] = n_hit[k:k + step] - 1e-3 * (dmin * hit).sum(axis=1) / np.maximum(gate[k:k + step], 1e-9)
    order = np.argsort(-score)[:max_keep * 8]
    few = np.flatnonzero(n_hit[order] < 3)
    if few.size:
        order = order[:few[0]]                                # the rest explain too little
    nearest, _, hit = _matches(a[order], b[order], w, z, gate[order])
    out = []
    seen = set()
    for key in np.where(hit, nearest, -1).tolist():
        key = tuple(key)
        if key in seen:
            continue
        seen.add(key)
        out.append(key)
        if len(out) >= max_keep:
            break
    return out


def _plausible_similarities(w, z, anchor_idx, prior: FacingPrior):
    """(a, b) (H,) complex: the similarities z = a w + b mapping an ordered pair of markers onto
    a pair of anchor detections, within the prior's scale range and roll; in the order of
    (anchor pair, marker pair), computed one block of anchor pairs at a time."""
    scale_range, max_roll_rad = prior.scale_range, np.radians(prior.max_roll_deg)
    ii, jj = np.triu_indices(anchor_idx.size, 1)
    mi, mj = np.nonzero(~np.eye(w.size, dtype=bool))
    wi, wj = w[mi][None, :], w[mj][None, :]
    step = max(1, HYPOTHESIS_BLOCK // max(1, mi.size))
    a_out, b_out = [], []
    for k in range(0, ii.size, step):
        zi, zj = z[anchor_idx[ii[k:k + step]]][:, None], z[anchor_idx[jj[k:k + step]]][:, None]
        a = ((zj - zi) / (wj - wi))                           # (P, Q)
        b = (zi - a * wi).ravel()
        a = a.ravel()
        s = np.abs(a)
        ok = (s >= scale_range[0]) & (s <= scale_range[1]) & (np.abs(np.angle(a)) <= max_roll_rad)
        a_out.append(a[ok])
        b_out.append(b[ok])
    if not a_out:
        return np.empty(0, complex), np.empty(0, complex)
    return np.concatenate(a_out), np.concatenate(b_out)


def _matches(a, b, w, z, gate):
    """For hypotheses (a, b) (H,): each marker's nearest detection (H, M), its distance and
    whether it lies within the hypothesis's ``gate`` (H,)."""
    proj = a[:, None] * w[None, :] + b[:, None]                # (H, M)
    dist = np.abs(proj[:, :, None] - z[None, None, :])         # (H, M, N)
    nearest = dist.argmin(axis=2)
    dmin = np.take_along_axis(dist, nearest[:, :, None], axis=2)[:, :, 0]
    return nearest, dmin, dmin <= gate[:, None]


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


@dataclass(frozen=True)
class _Search:
    """Settings of one identification search, derived from :class:`IdentifyOptions`."""

    gate: float                 # px, before the cap by the projected spacing
    max_rmse: float             # px, largest RMS of a verified hypothesis
    min_matches: int
    max_hypotheses: int
    prior: FacingPrior
    max_gate_spacing: float
    rescue_below: float         # px, see estimate_pnpf
    refine: RefineOptions
    leave_one_out: bool = False
    trusted: frozenset | None = None   # detections whose centre the detector refined (None: all)

    @classmethod
    def from_options(cls, options: IdentifyOptions, refine: RefineOptions) -> _Search:
        max_rmse = options.max_rmse
        return cls(options.gate, max_rmse, max(4, int(options.min_matches)),
                   int(options.max_hypotheses), options.prior, options.max_gate_spacing,
                   options.rescue_rmse_factor * max_rmse, refine)

    def rank(self, h) -> tuple:
        """Sort key of a verified hypothesis, best first: most trusted detections explained, then
        most detections, then the smallest RMS (see :func:`identify_markers`, ``trusted``)."""
        n_trusted = len(h.pairs) if self.trusted is None else sum(d in self.trusted for d in h.pairs.values())
        return -n_trusted, -len(h.pairs), h.rmse

    def match_gate(self, proj) -> float:
        """Gate (px) for matching detections to the projected markers ``proj`` (M,) complex."""
        return min(self.gate, self.max_gate_spacing * _min_spacing(proj))


def _fit(p3, uv, pairs, pp, search: _Search, rescue: bool = True):
    ms = sorted(pairs)
    q3, q2 = check_correspondences(p3[ms], uv[[pairs[m] for m in ms]])
    est = estimate_pnpf(q3, q2, pp, check_focal=False, accept_rmse=search.max_rmse,
                        rescue_below=search.rescue_below, rescue=rescue, options=search.refine)
    return _Fit(est, pairs)


class _Fits:
    """The fits of one section's search, memoised by pair set (marker index -> detection
    index) and rescue: a fit is a pure function of them, and the hypotheses of a search share
    many (verification rounds of different seeds often meet at the same pairs)."""

    def __init__(self, p3, uv, pp, search: _Search):
        self.p3, self.uv, self.pp, self.search = p3, uv, pp, search
        self._done = {}

    def __call__(self, pairs, rescue: bool = True):
        """:func:`_fit` of ``pairs``, or None when it fails."""
        key = (frozenset(pairs.items()), rescue)
        if key not in self._done:
            try:
                self._done[key] = _fit(self.p3, self.uv, pairs, self.pp, self.search, rescue)
            except (SolverError, np.linalg.LinAlgError):
                self._done[key] = None
        return self._done[key]


def _fit_leaving_one_out(pairs, fits: _Fits, search: _Search, rescue: bool):
    """Best fit (lowest RMS, at most ``max_rmse``) over the hypothesis without one of its pairs,
    or None: the loose similarity gate can pair a marker missing from the image with a stray
    detection, and that one wrong pair spoils the fit of all the others."""
    best = None
    for m in pairs:
        ref = fits({k: d for k, d in pairs.items() if k != m}, rescue)
        if ref is None:
            continue
        if ref.rmse_px <= search.max_rmse and (best is None or ref.rmse_px < best.rmse_px):
            best = ref
    return best


def _project(p3, ref, pp):
    pc = p3 @ ref.rotation.T + ref.translation
    z = pc[:, 2]
    if np.any(z <= 0):
        return None
    uv = ref.focal_px * pc[:, :2] / z[:, None] + pp
    return uv[:, 0] + 1j * uv[:, 1]


def _verify(z, pairs, fits: _Fits, search: _Search, rescue: bool = True, rounds=3):
    """Fit, re-project, re-match within the gate, refit. Returns _Hyp or None.

    A hypothesis is kept only if its final fit explains ``min_matches`` or more detections
    with a reprojection RMS of at most ``max_rmse`` px (consistent with the pixel noise).
    ``rescue=False``: every fit takes the estimator's fast path only (see
    :func:`_identify_section`).
    """
    ref = None
    for rnd in range(rounds):
        if len(pairs) < search.min_matches:
            return None
        ref = fits(pairs, rescue)
        poor = ref is None or not ref.rmse_px <= search.max_rmse
        if search.leave_one_out and rnd == 0 and poor and len(pairs) > search.min_matches:
            ref = _fit_leaving_one_out(pairs, fits, search, rescue)
            if ref is not None:
                pairs = ref.pairs
        if ref is None:
            return None
        proj = _project(fits.p3, ref, fits.pp)
        if proj is None:
            return None
        new = _one_to_one(proj, z, search.match_gate(proj))
        if new == pairs:
            break
        pairs = new
    if ref is None or len(pairs) < search.min_matches:
        return None
    if pairs != ref.pairs:
        ref = fits(pairs, rescue)
        if ref is None:
            return None
    if not ref.rmse_px <= search.max_rmse:
        return None
    cam = np.eye(4)
    cam[:3, :3], cam[:3, 3] = ref.rotation, ref.translation
    return _Hyp(dict(pairs), ref.rmse_px, (cam, ref.focal_px))


def _min_spacing(p):
    d = np.abs(p[:, None] - p[None, :])
    d[np.eye(p.size, dtype=bool)] = np.inf
    return float(d.min())


def _contradicting(pairs, hyps):
    """The verified hypotheses of ``hyps`` that give a detection of the seed ``pairs`` another
    marker than the seed does ({marker: detection} dicts)."""
    out = []
    for h in hyps:
        marker_of = {d: m for m, d in h.pairs.items()}
        if any(marker_of.get(d, m) != m for m, d in pairs.items()):
            out.append(h)
    return out


def _settled(pairs, hyps, n_markers: int) -> bool:
    """True when the verified hypotheses ``hyps`` leave nothing to learn from the seed ``pairs``:
    one of them holds every pair of the seed (the seed is part of it: its fit re-projects onto
    the same detections and verifies back to it), or one explains every marker of the section
    and the seed gives one of its detections another marker (no hypothesis can explain more,
    and one explaining as many with other identities would need the detections to repeat the
    layout's pattern). A seed that only lets other detections serve some markers (a duplicate
    or a stray detection next to a marker) is still verified: the better fit of the two is
    kept."""
    if any(all(h.pairs.get(m) == d for m, d in pairs.items()) for h in hyps):
        return True
    return any(len(h.pairs) == n_markers for h in _contradicting(pairs, hyps))


def _identify_section(p3, uv, z, cls, section_class, pp, search: _Search):
    """All verified hypotheses for one section, best first (most matches, then smallest RMS).

    Seeds are verified in the order of their similarity score, each fit once
    (:class:`_Fits`). A seed that the hypotheses verified so far settle (:func:`_settled`) is
    not verified; one that contradicts a hypothesis explaining the section well (``min(M, 5)``
    markers, the test that also ends the search before the all-detection anchors) is verified
    without the estimator's rescue of a failed cheap fit: the rescue is there for right
    assignments whose cheap fit missed, and such a seed is almost always a wrong one. Measured
    against verifying every seed with rescue (bench/solve_speed.py: 500 synthetic frames, 800
    of the identification benchmark's harder kind, 330 real detector frames): the same
    marker ids, swapped flags and inliers on every frame, identification about 18 times faster
    (tests/solver/test_solver_fast_paths.py keeps checking it)."""
    w = p3[:, 0] - 1j * p3[:, 1]
    spacing_mm = _min_spacing(w)
    labelled = np.flatnonzero(cls == section_class)
    hyps = []
    tried = set()
    fits = _Fits(p3, uv, pp, search)
    well = min(p3.shape[0], 5)
    for anchors in (labelled, np.arange(z.size)):
        if anchors.size < 2:
            continue
        keys = _similarity_hypotheses(w, z, anchors, search.prior, spacing_mm,
                                      search.max_hypotheses)
        for key in keys:
            if key in tried:
                continue
            tried.add(key)
            pairs = {m: d for m, d in enumerate(key) if d >= 0}
            if _settled(pairs, hyps, p3.shape[0]):
                continue
            rescue = not any(len(h.pairs) >= well for h in _contradicting(pairs, hyps))
            h = _verify(z, pairs, fits, search, rescue)
            if h is not None and not any(h.pairs == g.pairs for g in hyps):
                hyps.append(h)
        if hyps and max(len(h.pairs) for h in hyps) >= well:
            break          # the labelled anchors already explain the section well
    hyps.sort(key=search.rank)
    return hyps


def _rivals(hyps, search: _Search):
    """Verified hypotheses that give some detection another identity than the best one does and
    explain as many (trusted) detections."""
    if not hyps:
        return []
    best = hyps[0]
    return [h for h in hyps[1:] if search.rank(h)[:2] <= search.rank(best)[:2] and best.identity_conflicts(h)]


def identify_markers(markers, principal_point, detections,
                     options: IdentifyOptions = DEFAULT_IDENTIFY,
                     refine_options: RefineOptions = DEFAULT_REFINE, trusted=None) -> Identification:
    """Assign layout marker ids to detections (the search: docs/solver.md, "Identification").

    When identification fails for another reason than ambiguity, it is tried once more with hypotheses that may shed
    one pair: the loose similarity gate can pair a marker missing from the image with a stray detection, and that one
    wrong pair spoils the fit of the others (the retry costs time only on frames that would otherwise be refused; its
    effect: results/README.md).

    Parameters
    ----------
    markers, principal_point : sequence of :class:`core.layout.Marker` (both sections), (2,) px
    detections : (class_ids (N,), points_2d (N, 2) px)
        Classes 0/1 or "A"/"B" (or "RedA"/"BlueB").
    options, refine_options : IdentifyOptions, RefineOptions
        Gates, prior and budgets; the refinement of every fit.
    trusted : (N,) bool or None
        Detections whose centre the detector could refine (None: every detection). Between hypotheses, the one
        explaining more trusted detections wins before the one explaining more detections: a partly hidden marker's
        unrefined centre sits pixels off, and a hypothesis bent to take in two of them can beat the one that explains
        a fully visible marker instead, leaving that marker out of the fit (the case that showed it: results/README.md).

    Returns
    -------
    Identification

    Raises
    ------
    IdentificationFailed, TooFewPoints
        When a section cannot be identified with ``min_matches`` markers.
    AmbiguousIdentification
        When two conflicting assignments explain the detections equally well, even with the focal shared.
    InvalidSolverInput
        Bad input (shapes, classes, sizes).
    """
    ids, sections, pts = layout_arrays(markers)
    pp = as_principal_point(principal_point)
    cls, uv = parse_detections(detections)
    check_identification_size(sections, len(cls))
    search = replace(_Search.from_options(options, refine_options), trusted=_trusted_rows(trusted, len(cls)))
    try:
        return _search(ids, sections, pts, pp, cls, uv, search)
    except AmbiguousIdentification:
        raise
    except SolverError as first:
        try:
            return _search(ids, sections, pts, pp, cls, uv, replace(search, leave_one_out=True))
        except SolverError:
            raise first from None


def max_detections(n_markers: int) -> int:
    """Most detections one frame may bring for a layout of ``n_markers``: two per marker (a
    duplicate each) and DETECTIONS_SPARE strays; beyond, the detector's output is not a picture
    of the layout (non-maximum suppression off, a wrong class map) and the search's time, which
    grows about as detections^2, would be unbounded."""
    return 2 * n_markers + DETECTIONS_SPARE


def check_identification_size(sections, n_detections: int) -> None:
    """InvalidSolverInput when the layout has more than MAX_MARKERS_PER_SECTION markers in a
    section or the frame more than :func:`max_detections`: the limits that bound the time and
    memory of identification (bench/solve_memory.py)."""
    for s in ("A", "B"):
        n = sum(sec == s for sec in sections)
        if n > MAX_MARKERS_PER_SECTION:
            raise InvalidSolverInput(f"markers: section {s} has {n} markers, at most {MAX_MARKERS_PER_SECTION} "
                                     "per section can be identified")
    limit = max_detections(len(sections))
    if n_detections > limit:
        raise InvalidSolverInput(f"detections: {n_detections} for a layout of {len(sections)} markers, at most "
                                 f"{limit} (2 per marker + {DETECTIONS_SPARE}): is the detector's non-maximum "
                                 "suppression off?")


def _trusted_rows(trusted, n: int) -> frozenset | None:
    if trusted is None:
        return None
    arr = np.asarray(trusted)
    if arr.shape != (n,) or arr.dtype != bool:
        raise InvalidSolverInput(f"trusted: expected ({n},) bool (one per detection), got {arr.shape} {arr.dtype}")
    return frozenset(np.flatnonzero(arr).tolist())


def _search(ids, sections, pts, pp, cls, uv, search: _Search) -> Identification:
    """Hypothesise, verify and decide on validated inputs (see :func:`identify_markers`)."""
    z = uv[:, 0] + 1j * uv[:, 1]
    sel = {s: [k for k, sec in enumerate(sections) if sec == s] for s in ("A", "B")}
    hyps = {}
    for s, c in (("A", 0), ("B", 1)):
        hyps[s] = _identify_section(pts[sel[s]], uv, z, cls, c, pp, search)
        if not hyps[s]:
            raise IdentificationFailed(
                f"section {s}: could not identify {search.min_matches} or more markers among "
                f"{uv.shape[0]} detections (within {search.gate:.3g} px)")
    _settle_rivals(hyps, ids, pts, sel, uv, pp, search)
    best = {s: hyps[s][0] for s in ("A", "B")}
    out = _unclaimed_joint_fit(best, pts, sel, uv, pp, search)
    return _final_assignment(out, ids, sections, pts, sel, cls, uv, z, pp, search)


def _settle_rivals(hyps, ids, pts, sel, uv, pp, search: _Search) -> None:
    """A section with rivals is re-judged jointly with the other section's best hypothesis
    (shared focal length); ``hyps[s]`` becomes the one survivor, or the search refuses."""
    order = sorted(("A", "B"), key=lambda s: (len(_rivals(hyps[s], search)), -len(hyps[s][0].pairs)))
    strong, weak = order
    for s, other in ((weak, strong), (strong, weak)):
        rivals = _rivals(hyps[s], search)
        if not rivals:
            continue
        if _rivals(hyps[other], search):
            _raise_ambiguous(s, hyps[s][0], rivals[0], ids, sel[s])
        anchor = hyps[other][0]
        judged = []
        for h in [hyps[s][0]] + rivals:
            rmse = _joint_rmse(s, h, other, anchor, pts, sel, uv, pp, search)
            if rmse <= search.max_rmse:
                judged.append((rmse, h))
        judged = _explained(judged, len(anchor.pairs), search.refine.sigma_floor_px)
        if len(judged) != 1:
            if not judged:
                raise IdentificationFailed(f"section {s}: no assignment is consistent with "
                                           f"section {other} under a shared focal length")
            judged.sort(key=lambda x: x[0])
            _raise_ambiguous(s, judged[0][1], judged[1][1], ids, sel[s])
        hyps[s] = [judged[0][1]]


def _explained(judged: list, n_other: int, sigma_px: float | None) -> list:
    """The (joint rmse, hypothesis) pairs of ``judged`` whose joint fit the centre noise explains
    (chi-square of the residuals against ``GATE_NOISE_FACTOR`` times it over 2 n - 13 dof, p >=
    RIVAL_P: the gate's test, eval.fit_gate); all of them without a known noise ``sigma_px``. The
    noise is the known one, or, where the best fit exceeds it, at least what the best fit shows
    (its RMSE over ``GATE_NOISE_FACTOR``): a camera noisier than its card makes every fit exceed
    the card, and a rival many times the best fit is still no explanation (the goodness-of-fit
    gate then judges the chosen pose against the card). Why: a rival whose fit is many times the
    camera's noise cannot make the identification ambiguous."""
    if sigma_px is None or not sigma_px > 0 or not judged:
        return judged
    sigma_px = max(sigma_px, min(r for r, _ in judged) / GATE_NOISE_FACTOR)
    keep = []
    for rmse, h in judged:
        n = len(h.pairs) + n_other
        dof = 2 * n - 13
        if dof >= 1 and chi2_logsf(n * rmse ** 2 / (GATE_NOISE_FACTOR * sigma_px) ** 2, dof) >= np.log(RIVAL_P):
            keep.append((rmse, h))
    return keep or judged


def _unclaimed_joint_fit(best, pts, sel, uv, pp, search: _Search) -> JointFit:
    """Joint fit of the two best hypotheses on their union (detections claimed by both
    sections are left out of this fit)."""
    claimed = {}
    for s, h in best.items():
        for m, d in h.pairs.items():
            claimed.setdefault(d, []).append(s)
    fit = {s: [(m, d) for m, d in h.pairs.items() if len(claimed[d]) == 1]
           for s, h in best.items()}
    for s in fit:
        if len(fit[s]) < 4:
            raise TooFewPoints(f"section {s}: only {len(fit[s])} markers identified without "
                               "conflict, at least 4 needed")
    return _joint_fit(best["A"], best["B"], pts, sel, uv, pp, search, fit["A"], fit["B"])


def _final_assignment(out: JointFit, ids, sections, pts, sel, cls, uv, z, pp,
                      search: _Search) -> Identification:
    """One-to-one assignment of all detections to all markers projected by the joint fit."""
    proj = np.empty(len(ids), dtype=complex)
    for s, cam in out.cams.items():
        pc = pts[sel[s]] @ cam[:3, :3].T + cam[:3, 3]
        q = out.focal_px * pc[:, :2] / pc[:, 2:3] + pp
        proj[sel[s]] = q[:, 0] + 1j * q[:, 1]
    pairs = _one_to_one(proj, z, search.match_gate(proj))
    marker_ids = [None] * uv.shape[0]
    for g, d in pairs.items():
        marker_ids[d] = ids[g]
    for s in ("A", "B"):
        n_s = sum(1 for g in pairs if sections[g] == s)
        if n_s < 4:
            raise TooFewPoints(f"section {s}: only {n_s} detections match the fitted markers, "
                               "at least 4 needed")
    inl = np.array([mid is not None for mid in marker_ids])
    swapped = np.array([mid is not None and sections[ids.index(mid)] != "AB"[cls[k]]
                        for k, mid in enumerate(marker_ids)])
    rmse = max(out.rmse_a, out.rmse_b)
    return Identification(tuple(marker_ids), uv, cls, swapped, inl, float(rmse),
                          JointStart(out.cam_from_a, out.cam_from_b, out.focal_px))


def _hyp_init(ha, hb) -> JointStart:
    """Joint LM start from two section hypotheses: shared focal = geometric mean, translations
    rescaled so that f / depth is kept."""
    (ca, fa), (cb, fb) = ha.model, hb.model
    f0 = float(np.sqrt(fa * fb))
    ca, cb = ca.copy(), cb.copy()
    ca[:3, 3] *= f0 / fa
    cb[:3, 3] *= f0 / fb
    return JointStart(ca, cb, f0)


def _joint_fit(ha, hb, pts, sel, uv, pp, search: _Search, pairs_a=None,
               pairs_b=None) -> JointFit:
    pa = sorted(pairs_a if pairs_a is not None else ha.pairs.items())
    pb = sorted(pairs_b if pairs_b is not None else hb.pairs.items())
    return fit_joint(pts[[sel["A"][m] for m, _ in pa]], uv[[d for _, d in pa]],
                     pts[[sel["B"][m] for m, _ in pb]], uv[[d for _, d in pb]], pp,
                     start=_hyp_init(ha, hb), accept_rmse=search.max_rmse,
                     options=search.refine)


def _joint_rmse(s, h, other, anchor, pts, sel, uv, pp, search: _Search):
    """RMS of the joint fit (shared focal) of hypothesis ``h`` of section ``s`` with the other
    section's best hypothesis; inf when the pair is inconsistent (shared detections, failure)."""
    if set(h.pairs.values()) & set(anchor.pairs.values()):
        return np.inf
    parts = {s: h, other: anchor}
    try:
        out = _joint_fit(parts["A"], parts["B"], pts, sel, uv, pp, search)
    except (SolverError, np.linalg.LinAlgError):
        return np.inf
    na, nb = len(parts["A"].pairs), len(parts["B"].pairs)
    return float(np.sqrt((na * out.rmse_a ** 2 + nb * out.rmse_b ** 2) / (na + nb)))


def _raise_ambiguous(s, h1, h2, ids, sel):
    a = {ids[sel[m]]: d for m, d in sorted(h1.pairs.items())}
    b = {ids[sel[m]]: d for m, d in sorted(h2.pairs.items())}
    raise AmbiguousIdentification(
        f"ambiguous identification of section {s}: marker->detection assignments {a} "
        f"(rms {h1.rmse:.2f} px) and {b} (rms {h2.rmse:.2f} px) explain the detections "
        "equally well; refusing to guess")
