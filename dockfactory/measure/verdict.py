"""measure's uncertainty budget and conformity decision per image (eval.uncertainty_budget,
eval.conformity), added to the records after every image is solved.

Every image with a pose gets ``record["uncertainty"]``: per pose component the budget's terms
(centre noise, intrinsics, marker layout when the layout file states ``sigma_mm``, detector bias
when the weights' noise card measured it), the combined standard uncertainty u and U = k u (k = 2). With an acceptance spec,
``record["conformity"]``: per component of the spec's ``[localization]`` table IN / OUT /
UNDECIDED with the guard band U (u the combined one), and the image's worst; an image without a
pose is UNDECIDED (nothing is proven about it). The summary counts the decisions; the exit status
follows the worst image (0 IN, 1 OUT, 3 UNDECIDED, as evaluate's verdict).
"""
from __future__ import annotations

from dockfactory.core.names import POSE_NAMES
from dockfactory.eval.acceptance import AcceptanceSpec
from dockfactory.eval.conformity import (
    COVERAGE_K,
    IN,
    OUT,
    UNDECIDED,
    coverage_k,
    pose_conformity,
    pose_tolerances,
    worst,
)
from dockfactory.eval.uncertainty_budget import TERM_LABELS, TERMS, pose_budget


def add_uncertainty(records: list[dict], markers, sigma_mm: dict | None, bias_px=None) -> None:
    """``record["uncertainty"]`` of every record with a pose (in place); ``bias_px`` the detector's
    measured centre offset (detector.noise_card.centre_bias_px) or None. A budget that cannot be
    computed (a marker id the layout lacks, a degenerate Jacobian) is recorded as its reason."""
    for r in records:
        if not r.get("ok"):
            continue
        try:
            r["uncertainty"] = pose_budget(r, markers, sigma_mm, bias_px)
        except (KeyError, ValueError, IndexError) as exc:
            r["uncertainty"] = {"error": f"{type(exc).__name__}: {exc}"[:200]}


def combined_std(record: dict) -> dict:
    """{pose name: combined standard uncertainty} of a record (its reported std when the budget
    is missing)."""
    budget = record.get("uncertainty") or {}
    if "error" not in budget and budget:
        return {n: budget[n]["combined"] for n in POSE_NAMES}
    cov = record["covariance"]
    return {n: cov[i][i] ** 0.5 if cov[i][i] >= 0 else None for i, n in enumerate(POSE_NAMES)}


def add_conformity(records: list[dict], spec: AcceptanceSpec, source: str) -> dict:
    """``record["conformity"]`` of every record (in place) and the summary: tolerances, k, the
    decision rule, counts of IN / OUT / UNDECIDED images, and the worst."""
    tolerances, k = pose_tolerances(spec, source), coverage_k(spec)
    for r in records:
        if r.get("ok"):
            r["conformity"] = pose_conformity(r["pose"], combined_std(r), tolerances, k)
        else:
            r["conformity"] = {"components": {}, "decision": UNDECIDED, "k": k, "note": "no pose"}
    decisions = [r["conformity"]["decision"] for r in records]
    return {"spec": source, "decision_rule": spec.decision_rule, "k": k, "tolerances": tolerances,
            "nominal": "the docked pose: X = Y = Z = 0 mm, alpha = beta = gamma = 0 deg",
            "counts": {d: decisions.count(d) for d in (IN, OUT, UNDECIDED)}, "worst": worst(decisions)}


def summary_line(s: dict) -> str:
    """One line: the worst decision, the counts, the rule and the tolerances."""
    tol = ", ".join(f"|{n.split('_')[0]}| <= {t:g} {n.split('_')[1]}" for n, t in s["tolerances"].items())
    rule = (f"guarded, U = {s['k']:g} u" if s["decision_rule"] == "guarded" else "simple, no guard band")
    c = s["counts"]
    return (f"conformity {s['worst']}: {c[IN]} IN, {c[OUT]} OUT, {c[UNDECIDED]} UNDECIDED "
            f"({rule}; tolerance {tol} about the docked pose)")


def pose_lines(records: list[dict], names) -> list[str]:
    """Per image with a conformity decision: the decision and each component's value +- U
    (k = 2) against its tolerance."""
    out = []
    for name, r in zip(names, records):
        conf = r.get("conformity")
        if conf is None:
            continue
        parts = [f"{n.split('_')[0]} {c['value']:.3f} +- {c['U']:.3f} {n.split('_')[1]} ({c['decision']})"
                 for n, c in conf["components"].items() if c["value"] is not None and c["U"] is not None]
        k = conf.get("k", COVERAGE_K)
        out.append(f"{conf['decision']:9s} {name}: " + ("; ".join(parts) + f" [+- U, k = {k:g}]" if parts
                                                         else conf.get("note", "")))
    return out


def budget_lines(record: dict) -> list[str]:
    """The uncertainty budget of one pose as a terminal table: per component each term's
    standard uncertainty, the combined u and U (k = 2); "-" for a term not given."""
    budget = record.get("uncertainty") or {}
    if not budget or "error" in budget:
        return []
    head = ["component"] + [TERM_LABELS[t] for t in TERMS] + ["u (1 sigma)", f"U (k = {budget['x_mm']['k']:g})"]
    lines = ["uncertainty budget (GUM): " + " | ".join(head)]
    for n in POSE_NAMES:
        b = budget[n]
        cells = ["-" if b[t] is None else f"{b[t]:.4f}" for t in TERMS] + [f"{b['combined']:.4f}", f"{b['expanded']:.4f}"]
        lines.append(f"  {n.split('_')[0]} ({n.split('_')[1]}): " + " | ".join(cells))
    return lines
