"""How many test frames (repeatability degrees of freedom) prove conformance under the guarded rule.

Localization: n = test frames (nu = n). Estimation: nu = the repeatability captures minus the
static poses (each pose's mean costs one degree of freedom).

Why and how: docs/acceptance.md, "Planning frames".
"""
from __future__ import annotations


import numpy as np

from dockfactory.eval.gate_statistic import gate_statistic
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.layout import marker_points
from dockfactory.core.names import COMPONENTS, POSE_KEYS, UNITS
from dockfactory.eval.acceptance import AcceptanceSpec
from dockfactory.generator.random_draws import static_scene
from dockfactory.eval.frame_cameras import cameras_of_test_frames
from dockfactory.eval.pixel_aspect import crb_delivered

BLOCKS = {"localization": "test frames", "estimation": "repeatability degrees of freedom (captures - poses)"}


def plan_frames(spec: AcceptanceSpec, expected: dict[str, dict[str, float]]) -> list[dict]:
    """How many frames would decide each gated criterion, given the error expected of it.

    Parameters
    ----------
    spec : AcceptanceSpec
        The gates (thresholds, statistics, confidence).
    expected : dict
        {"localization" | "estimation": {component: expected rmse}} (mm, deg).

    Returns
    -------
    list of dict
        One row per gated component: threshold (the RMS of the gate's statistic's threshold under
        the Gaussian model), margin, what the frames would prove ("conformance" / "non-conformance"
        / None at the threshold) and how many by the statistic's bounds (eval.gate_statistic; None:
        no count up to 100,000 decides).

    Raises
    ------
    DockfactoryError
        A gated component without an expected figure (one line).
    """
    rows = []
    for block, figures in expected.items():
        gate = getattr(spec, block)
        stat = gate_statistic(gate.statistic)
        for c, thr in gate.thresholds().items():
            if c not in figures:
                raise DockfactoryError(f"plan-frames: [{block}] gates {c} but no expected figure for it was given")
            rmse, t = figures[c], stat.to_rms(thr)
            n = stat.frames_to_decide(rmse, t, 1, spec.confidence)
            proves = None if rmse == t else ("conformance" if rmse < t else "non-conformance")
            rows.append({"block": block, "component": c, "unit": UNITS[c], "expected_rmse": rmse, "threshold": t,
                         "margin": rmse / t, "proves": proves, "frames": n, "counts": BLOCKS[block],
                         "confidence": spec.confidence})
    return rows


def plan_lines(rows: list[dict]) -> list[str]:
    """One line per row, then per block the count that decides every component."""
    out = []
    for r in rows:
        head = (f"{r['block']}: {r['component']}: expected {r['expected_rmse']:.4g} {r['unit']} against "
                f"{r['threshold']:.4g} {r['unit']} (margin {r['margin']:.2f})")
        if r["frames"] is None:
            out.append(f"{head}: no number of {r['counts']} decides it")
        else:
            out.append(f"{head}: {r['frames']} {r['counts']} prove {r['proves']} at {r['confidence']:.0%}")
    for block, what in BLOCKS.items():
        mine = [r for r in rows if r["block"] == block]
        if mine and all(r["proves"] == "conformance" and r["frames"] is not None for r in mine):
            out.append(f"{block}: {max(r['frames'] for r in mine)} {what} prove every gated component conforms")
        elif mine:
            out.append(f"{block}: conformance cannot be proven at these figures")
    return out


def expected_from_config(cfg, sigma_px: float, bound_factor: float = 1.0, max_frames: int = 200) -> dict:
    """{component: bound_factor x RMS over the config's test frames (the first ``max_frames``)
    of the Cramer-Rao std} at ``sigma_px`` of isotropic centre noise in the delivered image (a
    frame with non-square pixels: eval.pixel_aspect.crb_delivered). DockfactoryError when the
    config plans no test frame."""
    st = static_scene(cfg)
    pa, pb = marker_points(st.markers, "A"), marker_points(st.markers, "B")
    stds = []
    for f in cameras_of_test_frames(cfg, max_frames, "plan-frames"):
        b = crb_delivered(pa, f.cam_from_a, pb, f.cam_from_b, f.focal_px, f.principal_point, sigma_px,
                          f.pixel_aspect)
        stds.append([b.std[POSE_KEYS[c]] for c in COMPONENTS])
    rms = np.sqrt(np.mean(np.square(stds), axis=0)) * bound_factor
    return {c: float(v) for c, v in zip(COMPONENTS, rms)}
