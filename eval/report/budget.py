"""The report's uncertainty budget table (GUM): per gated localization component, the RMS over
the solved test frames of each input's standard uncertainty (eval.uncertainty_budget.budget_block),
the combined u and U = k u."""
from __future__ import annotations

import html

from dockfactory.core.names import POSE_KEYS, UNITS
from dockfactory.eval.uncertainty_budget import TERM_LABELS, TERMS


def _cell(v) -> str:
    return "<td>-</td>" if v is None else f"<td>{v:.4g}</td>"


def html_budget(metrics: dict) -> list[str]:
    """The section (empty when metrics.json has no budget): one row per gated localization
    component (every component when none is gated), units in every header."""
    block = metrics.get("uncertainty_budget")
    if not block or not block.get("n"):
        return []
    gated = [c["component"] for c in metrics["acceptance"]["criteria"] if c.get("block") == "localization"]
    comps = gated or list(POSE_KEYS)
    head = ("<tr><th>component</th>" + "".join(f"<th>{html.escape(TERM_LABELS[t])}</th>" for t in TERMS)
            + f"<th>combined u (1 sigma)</th><th>U (k = {block['k']:g})</th></tr>")
    rows = "".join(f"<tr><td>{c} ({UNITS[c]})</td>"
                   + "".join(_cell(block["components"][POSE_KEYS[c]][t]) for t in (*TERMS, "combined", "expanded"))
                   + "</tr>" for c in comps)
    bias = block.get("bias_px")
    bias_text = ("the mean offset of the detected centres measured on this split, "
                 f"({bias[0]:.3f}, {bias[1]:.3f}) px, as a common shift of unknown sign" if bias else "not measured")
    return [f"<h2>Uncertainty budget of a single pose (GUM, JCGM 100)</h2><table>{head}{rows}</table>",
            f"<p class='note'>RMS over the {block['n']} solved test frames of each input's standard uncertainty "
            "(mm / deg), propagated through the solver's Jacobian at each frame's solved pose: centre noise and "
            "intrinsics split the reported covariance (what estimating the focal length and the model's free "
            "intrinsics adds); camera model: what marginalising the intrinsics the camera model does not estimate "
            "(principal point, distortion) over their plausible range added (- when the lens is taken as known); "
            "section offset: what a common offset of each section's centres, measured on labelled frames of the "
            "camera class (the detector's noise card or the dataset's val split), added (- when none was given); "
            "the marker layout is exact in a rendered dataset (a real layout's sigma_mm enters "
            f"through measure); detector bias: {html.escape(bias_text)}. U = k u is what measure's guard band "
            "uses for one pose.</p>"]
