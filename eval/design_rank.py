"""Every design of a space predicted and ranked against the acceptance spec.

Why and how: docs/design.md, "Ranking designs".
"""
from __future__ import annotations

import hashlib
import math

from dockfactory.eval.gate_statistic import gate_statistic
from dockfactory.core.config import ConfigError
from dockfactory.core.errors import DockfactoryError
from dockfactory.eval.design_card import DesignCard
from dockfactory.eval.design_predict import design_config, predict_design
from dockfactory.eval.design_refusals import simulated_no_pose
from dockfactory.eval.design_sensor import camera_variance
from dockfactory.eval.design_space import Design, DesignSpace
from dockfactory.generator.sampler import check_focal_fits

__all__ = ["pass_probability", "reject_probability", "design_row", "rank_rows", "design_id", "all_posed_probability"]


def pass_probability(rmse: float, threshold: float, dof: int, confidence: float, statistic: str = "rmse") -> float:
    """P(the guarded rule proves a criterion in ``statistic`` passes) with ``dof`` degrees of
    freedom, errors of true RMS ``rmse`` against a threshold of RMS ``threshold`` (mm, deg; the
    statistic's bounds under the Gaussian model: eval.gate_statistic); 1.0 for rmse 0."""
    return gate_statistic(statistic).pass_probability(rmse, threshold, dof, confidence)


def reject_probability(rmse: float, threshold: float, dof: int, confidence: float, statistic: str = "rmse") -> float:
    """P(the guarded rule proves a criterion in ``statistic`` fails) (as :func:`pass_probability`);
    0.0 for rmse 0."""
    return gate_statistic(statistic).reject_probability(rmse, threshold, dof, confidence)


def all_posed_probability(rate: float, frames: int) -> float:
    """P(each of ``frames`` frames gets a pose) when an honest frame goes without one (refused by
    the fit gate, or unsolved) with probability ``rate``, independently. A block with a frame
    without a pose has no value and fails (eval.acceptance), so this multiplies the block's P(pass)
    and its complement is a way to fail."""
    return (1.0 - rate) ** frames


def _no_pose(card: DesignCard, design: Design, test_frames: int, captures: int, simulate=None,
             settled: bool = False) -> dict:
    """The share of honest frames without a pose for ``design`` and what it does to the user's
    ``test_frames`` test frames and ``captures`` repeatability captures: with the card's
    ``no_pose_simulation``, ``simulate()`` (the design's frames through the gate:
    eval.design_refusals.simulated_no_pose), else the card's table per class and format.
    ``settled``: the design fails on its predicted pose errors alone, and frames without a pose can
    only add to that, so the simulation (seconds a design) is skipped: rate 0, ``skipped`` True, said
    in ``card_key``."""
    if card.no_pose_gate is not None and settled:
        rate, key, extra = 0.0, "not simulated: the design fails on its predicted pose errors", {"skipped": True}
    elif card.no_pose_gate is not None and simulate is not None:
        sim = simulate()
        rate, key = sim["rate"], "no_pose_simulation"
        extra = {"simulated": sim["simulated"], "refused": sim["refused"], "reasons": sim["reasons"]}
    else:
        (rate, key), extra = card.no_pose_rate_of(design), {}
    return {"rate_per_frame": rate, "card_key": key, **extra,
            "p_all_test_posed": all_posed_probability(rate, test_frames),
            "p_all_captures_posed": all_posed_probability(rate, captures)}


def _any_of(probabilities: list[float]) -> float:
    """P(at least one of independent events of ``probabilities``): the rule rejects a design when
    any gated criterion or block is proven failing."""
    return 1.0 - math.prod(1.0 - p for p in probabilities)


def design_id(design: Design) -> str:
    return hashlib.sha256(design.label().encode()).hexdigest()[:10]


def _base_row(design: Design, space: DesignSpace) -> dict:
    c = design.camera
    return {"id": design_id(design), "design": design.label(), "camera": c.name, "width": c.width,
            "height": c.height, "pixel_um": c.pixel_um, "cfa": c.cfa, "focal_mm": design.lens.focal_mm,
            "focal_px": round(design.focal_px, 1), "distance_mm": list(design.distance_mm),
            "marker_diameter_mm": design.marker_diameter_mm, "ring": design.ring,
            "markers_per_section": design.markers_per_section, "image_format": design.image_format,
            "cost": design.cost(space.marker_cost)}


def _block(spec, block: str, figures: dict, dof: int) -> dict:
    """Per gated component of ``block``: predicted, threshold, margin, probability, frames (RMS
    figures; the gate's statistic converts its thresholds and judges: eval.gate_statistic)."""
    gate = getattr(spec, block)
    stat = gate_statistic(gate.statistic)
    out = {}
    for comp, thr in gate.thresholds().items():
        t, r = stat.to_rms(thr), figures[comp]
        out[comp] = {"predicted": r, "threshold": t, "margin": r / t,
                     "probability": pass_probability(r, t, dof, spec.confidence, gate.statistic),
                     "reject_probability": reject_probability(r, t, dof, spec.confidence, gate.statistic),
                     "frames_to_prove": stat.frames_to_decide(r, t, 1, spec.confidence) if r < t else None}
    return out


def design_row(design: Design, space: DesignSpace, scene_cfg, spec, card: DesignCard,
               fails_at: float | None = None) -> dict:
    """One design predicted: the base fields, ``status`` ("predicted", made passes / undecided /
    fails by :func:`rank_rows`; "infeasible" / "not predicted" with ``reason``), the predicted
    RMSE and repeatability per component, the median disc minor semi-axis and ``extrapolated`` (the
    card's line when it lies outside the card's scenes: DesignCard.outside_range, else ""), the
    localization and estimation blocks (estimation
    only when the space gives repeatability captures), ``no_pose`` (:func:`_no_pose`: frames the
    camera class leaves without a pose, each failing its block), P(accept) and P(reject).
    ``fails_at``: the P(reject) at which the answer calls a design failing (its min probability);
    a design its predicted pose errors already fail at it is not simulated (:func:`_no_pose`)."""
    row = _base_row(design, space)
    variance = camera_variance(design.camera.preset, scene_cfg.sensor)
    noise, provisional, why = card.noise_of(design, variance)
    if noise is None:
        return {**row, "status": "not predicted", "reason": why}
    row["sensor_factor"] = round(card.sensor_factor_of(design, variance), 4)
    prefix = f"{space.source}: design {design.label()}"
    try:
        cfg = design_config(scene_cfg, design, space, max(space.test_frames, space.geometry_frames))
        pred = predict_design(cfg, noise, card.bound_factor, space.geometry_frames)
        # every test frame the user will take must fit its markers, not only the predicted ones
        check_focal_fits(cfg, prefix)
    except (ConfigError, DockfactoryError) as exc:
        return {**row, "status": "infeasible", "reason": str(exc).replace(f"{prefix}: ", "")}
    loc = _block(spec, "localization", pred.rmse, space.test_frames)
    poses, captures = space.repeatability
    est = _block(spec, "estimation", pred.repeat, poses * (captures - 1)) if poses else {}
    rejects = [v["reject_probability"] for v in (*loc.values(), *est.values())]
    settled = fails_at is not None and bool(rejects) and _any_of(rejects) >= fails_at
    nopose = _no_pose(card, design, space.test_frames if loc else 0, poses * captures if est else 0,
                      lambda: simulated_no_pose(cfg, design, noise, card.no_pose_gate, space.geometry_frames, space.seed,
                                                card.tail_of(design)), settled)
    posed = [nopose["p_all_test_posed"]] * bool(loc) + [nopose["p_all_captures_posed"]] * bool(est)
    p_loc = math.prod(v["probability"] for v in loc.values()) * nopose["p_all_test_posed"]
    probs = [v["probability"] for v in (*loc.values(), *est.values())] + posed
    rejects += [1.0 - p for p in posed]
    margins = [v["margin"] for v in (*loc.values(), *est.values())]
    return {**row, "status": "predicted", "reason": "", "provisional": provisional,
            "disc_minor_median_px": round(pred.minor_median_px, 2), "extrapolated": card.outside_range(pred.minor_median_px),
            "predicted_rmse": pred.rmse, "predicted_repeatability": pred.repeat,
            "localization": loc, "estimation": est, "estimation_predicted": bool(poses), "no_pose": nopose,
            "p_accept": math.prod(probs) if probs else None, "p_localization": p_loc if loc else None,
            "p_reject": _any_of(rejects) if rejects else None,
            "worst_margin": max(margins) if margins else None, "geometry_frames": pred.frames}


def _pareto_key(r: dict) -> tuple:
    """What a design spends, each the less the better: margin, pixels, focal length, markers."""
    return r["worst_margin"], r["width"] * r["height"], r["focal_mm"], r["markers_per_section"]


def _dominates(a: dict, b: dict) -> bool:
    va, vb = _pareto_key(a), _pareto_key(b)
    return all(x <= y for x, y in zip(va, vb)) and any(x < y for x, y in zip(va, vb))


def _status(row: dict, min_probability: float) -> str:
    if row["p_accept"] is not None and row["p_accept"] >= min_probability:
        return "passes"
    if row["p_reject"] is not None and row["p_reject"] >= min_probability:
        return "fails"
    return "undecided"


def rank_rows(rows: list[dict], min_probability: float) -> list[dict]:
    """``rows`` with status passes / undecided / fails, ``rank`` and ``pareto`` set, in rank
    order (module docstring); infeasible and unpredicted designs last, unranked."""
    if not 0 < min_probability <= 1:
        raise DockfactoryError(f"min probability must be in (0, 1], got {min_probability}")
    done = [r for r in rows if r["status"] == "predicted"]
    for r in done:
        r["status"] = _status(r, min_probability)
    passing = [r for r in done if r["status"] == "passes"]
    costed = any(r["cost"] > 0 for r in rows)
    passing.sort(key=lambda r: (r["cost"], r["worst_margin"]) if costed else (r["worst_margin"], r["cost"]))
    rest = sorted((r for r in done if r["status"] != "passes"),
                  key=lambda r: (r["status"] == "fails", -(r["p_accept"] or 0.0), r["worst_margin"]))
    for r in passing:
        r["pareto"] = not any(_dominates(o, r) for o in passing if o is not r)
    for i, r in enumerate(passing + rest):
        r["rank"] = i + 1
        r.setdefault("pareto", False)
    return passing + rest + [r for r in rows if r["status"] not in ("passes", "undecided", "fails")]
