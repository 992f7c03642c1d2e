"""``dockfactory design --verify K``: the top K designs rendered and judged, predicted beside
rendered.

Each design becomes a dataset config (eval.design_predict.design_config: its camera, lens,
distance, markers, CFA, sensor preset and JPEG; ``frames`` test frames in normal light, the
space's repeatability captures or 1 x 2) written as OUT/verify/ID/config.toml, and goes through
``dockfactory run`` (render, detect with the shipped or given weights, solve, evaluate against the
space's spec, report) in OUT/verify/ID/run: resumable, a design already rendered is not rendered
again. The comparison per gated or fitted component: predicted RMSE, rendered RMSE and their
ratio, and the run's verdict beside the predicted status.
"""
from __future__ import annotations

import json
from pathlib import Path

from dockfactory.core.config_text import to_toml
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.io import write_text_atomic
from dockfactory.core.names import COMPONENTS
from dockfactory.eval.design_predict import design_config
from dockfactory.pipeline import run_pipeline

__all__ = ["verify_designs", "comparison_lines", "block_decision"]

SHOWN = ("x", "y", "alpha")


def block_decision(criteria: list[dict], block: str) -> str | None:
    """The verdict's decision on one block: "pass" (every criterion passes), "fail" (one is proven
    beyond its threshold), "undecided", or None when the spec gates nothing there."""
    mine = [c for c in criteria if c.get("block") == block]
    if not mine:
        return None
    if all(c["pass"] for c in mine):
        return "pass"
    return "fail" if any(c.get("decision") == "fail" for c in mine) else "undecided"


def _block_decisions(criteria: list[dict]) -> dict:
    """{block: :func:`block_decision`} of the gated pose blocks."""
    out = {b: block_decision(criteria, b) for b in ("localization", "estimation")}
    return {b: d for b, d in out.items() if d is not None}


def _rendered(run_dir: Path) -> dict:
    """{"rmse": {component: mm / deg}, "repeat": {...}, "verdict", "blocks", "solved"} of a
    finished run; DockfactoryError (one line) when the run left no metrics (its render or a later
    stage failed: the run's own messages say why; the same command resumes it)."""
    path = run_dir / "eval" / "metrics.json"
    if not path.is_file():
        raise DockfactoryError(f"design --verify: {run_dir} has no eval/metrics.json: the run of this design "
                               "did not finish (see its messages above); run the same command again to resume")
    metrics = json.loads(path.read_text(encoding="utf-8"))
    loc = metrics["localization"]
    pooled = metrics.get("estimation", {}).get("pooled", {})
    return {"rmse": {c: loc["overall"][c]["rmse"] for c in COMPONENTS},
            "repeat": {c: (pooled.get(c) or {}).get("rmse") for c in COMPONENTS},
            "verdict": metrics["acceptance"]["verdict"],
            "blocks": _block_decisions(metrics["acceptance"]["criteria"]),
            "solved": f"{loc['n_solved']}/{loc['n_frames']}"}


def verify_designs(rows, designs_by_id, space, scene_cfg, spec_path, out_dir, k: int, frames: int,
                   weights=None, workers: int = 1) -> list[dict]:
    """Render and judge the first ``k`` ranked designs of ``rows`` (module docstring); one record
    per design: id, design, predicted (rmse, status), rendered (rmse, repeat, verdict), ratio
    (predicted / rendered per component)."""
    ranked = [r for r in rows if r.get("rank") is not None][:k]
    out = []
    for r in ranked:
        design = designs_by_id[r["id"]]
        folder = Path(out_dir) / "verify" / r["id"]
        cfg = design_config(scene_cfg, design, space, frames, space.repeatability if space.repeatability[0] else (1, 2))
        write_text_atomic(folder / "config.toml", f"# {design.label()}\n" + to_toml(cfg.resolved_dict()))
        run_pipeline(folder / "config.toml", folder / "run", spec_path, weights=weights, workers=workers)
        got = _rendered(folder / "run")
        ratio = {c: (r["predicted_rmse"][c] / got["rmse"][c]) if got["rmse"][c] else None for c in COMPONENTS}
        out.append({"id": r["id"], "design": r["design"], "predicted": {"rmse": r["predicted_rmse"],
                    "repeat": r["predicted_repeatability"], "status": r["status"],
                    "p_localization": r["p_localization"]},
                    "rendered": got, "ratio": ratio, "frames": frames})
    return out


def _num(v) -> str:
    return "-" if v is None else f"{v:.2f}"


def comparison_lines(records: list[dict]) -> list[str]:
    """One line per verified design: predicted / rendered X, Y, alpha and the two verdicts."""
    lines = []
    for rec in records:
        parts = [f"{c} {rec['predicted']['rmse'][c]:.3g} / {rec['rendered']['rmse'][c]:.3g}"
                 if rec["rendered"]["rmse"][c] is not None else f"{c} -" for c in SHOWN]
        lines.append(f"{rec['id']}: predicted / rendered RMSE " + ", ".join(parts)
                     + f"; predicted {rec['predicted']['status']} (P localization "
                     f"{_num(rec['predicted']['p_localization'])}), rendered {rec['rendered']['verdict']}, "
                     f"localization {rec['rendered']['blocks'].get('localization', '-')} "
                     f"({rec['rendered']['solved']} solved): {rec['design']}")
    return lines
