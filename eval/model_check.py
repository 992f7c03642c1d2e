"""Whether the solves' camera model explained their images: the report's count of the frames whose
residuals the model does not explain, and what the covariance carries for it.

Every solve tests the intrinsics its camera model does not estimate (solver.model_error: a score
test at 1e-3); the poses file keeps each frame's ``model_check`` record and the run's
``lens_prior`` (whether those intrinsics were marginalised into the covariance, and over what
range). This block counts them over the solved test frames; it is reported, not gated.
"""
from __future__ import annotations

import html

MAX_LISTED = 8   # frame ids of flagged frames the block keeps

# what the report reads of metrics["model_check"] (eval.report.check_schema)
BLOCK_SCHEMA = {"solved": "int", "checked": "int", "flagged": "int", "marginalised": "int",
                "flagged_frames": ("list", "str"), "lens_prior": ("map", "any")}


def model_check_block(poses: dict, test_rows: list[dict]) -> dict:
    """{solved, checked (frames with a model check), flagged (its model does not explain the
    residuals), marginalised (the unestimated intrinsics' error added), flagged_frames (the first
    MAX_LISTED ids), lens_prior (the poses file's, {} for an older file)} over the solved test
    rows of ``poses`` (a poses file's content)."""
    records = [(r["frame_id"], poses["frames"][r["frame_id"]]) for r in test_rows if r["ok"]]
    checks = [(fid, rec["model_check"]) for fid, rec in records if rec.get("model_check")]
    flagged = [fid for fid, c in checks if not c.get("explains", True)]
    return {"solved": len(records), "checked": len(checks), "flagged": len(flagged),
            "marginalised": sum(bool(c.get("marginalised")) for _, c in checks),
            "flagged_frames": flagged[:MAX_LISTED], "lens_prior": dict(poses.get("lens_prior") or {})}


def model_check_sentence(block: dict) -> str:
    """One sentence: how many solved test frames the camera model did not explain, and whether the
    covariance carries the error of the intrinsics it does not estimate."""
    if not block["checked"]:
        return "No solve recorded a camera-model check (a poses file from before the check)."
    prior = block["lens_prior"]
    carried = (f"the covariance of {block['marginalised']} of {block['checked']} carries the error of the "
               "intrinsics the model does not estimate, marginalised over the lens prior"
               if prior.get("marginalise") else
               "the lens is taken as known (an ideal or calibrated camera): nothing is marginalised")
    listed = (f" (first: {', '.join(block['flagged_frames'])})" if block["flagged"] else "")
    return (f"Camera model: {block['flagged']} of {block['checked']} solved test frames flagged as not explained "
            f"by their camera model (score test of the unestimated intrinsics, p < 1e-3){listed}; {carried}.")


def html_model_check(block: dict) -> list[str]:
    """The report paragraph of :func:`model_check_sentence`, with the prior's ranges."""
    prior = block["lens_prior"]
    ranges = ", ".join(f"{html.escape(str(k))} {html.escape(str(v))}" for k, v in prior.items() if k != "marginalise")
    return ["<h3>Does the camera model explain the images?</h3>",
            f"<p>{html.escape(model_check_sentence(block))}" + (f" Lens prior: {ranges}." if ranges else "") + "</p>"]
