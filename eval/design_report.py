"""The design answer in the report's style: a table (terminal and markdown), a plot of margin
against cost (or pixels), and design.json + design.md + design.html (self-contained) in one folder,
each written atomically.

The plot: one point per predicted design, its worst margin (predicted RMSE over threshold, the
largest over the gated components) against its cost when the space gives costs, else its pixel
count; passing designs green, undecided orange, failing red, Pareto designs ringed, the threshold at margin 1.
"""
from __future__ import annotations

import base64
import html
import io
from pathlib import Path

from dockfactory.core.io import make_output_folder, write_json_atomic, write_text_atomic

__all__ = ["table_lines", "markdown", "write_design_outputs"]



def _fmt(v, digits: int = 3) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.{digits}g}"
    return str(v)


def _no_pose_note(no_pose: dict) -> str:
    """" (P every test frame posed q: r % of frames without a pose)" when the card gives the
    design's camera class a share of frames without a pose; that they were not simulated when the
    design fails on its pose errors alone (eval.design_rank); else ""."""
    rate = no_pose.get("rate_per_frame") or 0.0
    if no_pose.get("skipped"):
        return " (frames without a pose not simulated: it fails on its pose errors alone)"
    if rate <= 0:
        return ""
    return f" (P every test frame posed {no_pose['p_all_test_posed']:.2f}: {100 * rate:.1f} % of frames without a pose)"


def _cells(r: dict) -> list[str]:
    pred = r.get("predicted_rmse", {})
    flag = "*" if r.get("pareto") else ""
    prov = " (provisional: " + ", ".join(r["provisional"]) + ")" if r.get("provisional") else ""
    prov += f" ({r['extrapolated']})" if r.get("extrapolated") else ""
    prov += _no_pose_note(r.get("no_pose") or {})
    return [_fmt(r.get("rank")) + flag, r["status"], _fmt(r.get("p_accept")), _fmt(r.get("worst_margin")),
            _fmt(pred.get("x")), _fmt(pred.get("y")), _fmt(pred.get("alpha")), _fmt(r["cost"]),
            r["design"] + prov + (f" ({r['reason']})" if r.get("reason") else "")]


VERIFY_HEAD = ["id", "X mm: predicted / rendered", "Y mm", "alpha deg", "predicted", "rendered", "design"]


def _pair(rec: dict, c: str) -> str:
    p, r = rec["predicted"]["rmse"][c], rec["rendered"]["rmse"][c]
    return f"{p:.3g} / -" if r is None else f"{p:.3g} / {r:.3g} ({p / r:.2f})" if r else f"{p:.3g} / 0"


def _verify_cells(rec: dict) -> list[str]:
    """A verified design: predicted / rendered RMSE (their ratio), the predicted status and the
    rendered verdict with its localization decision."""
    got = rec["rendered"]
    return [rec["id"], *(_pair(rec, c) for c in ("x", "y", "alpha")), rec["predicted"]["status"],
            f"{got['verdict']} (localization {got.get('blocks', {}).get('localization', '-')}, {got['solved']} solved)",
            rec["design"]]


def table_lines(rows: list[dict], top: int) -> list[str]:
    """The first ``top`` ranked designs, then a count of the rest by status."""
    head = ["rank", "status", "P(accept)", "margin", "X mm", "Y mm", "alpha deg", "cost", "design"]
    shown = rows[:top]
    body = [head] + [_cells(r) for r in shown]
    widths = [max(len(c[i]) for c in body) for i in range(len(head) - 1)]
    lines = ["  ".join(c[i].ljust(widths[i]) for i in range(len(widths))) + "  " + c[-1] for c in body]
    counts = {}
    for r in rows:
        counts[r["status"]] = counts.get(r["status"], 0) + 1
    lines.append(f"{len(rows)} designs: " + ", ".join(f"{n} {s}" for s, n in counts.items())
                 + ("; * Pareto front" if any(r.get("pareto") for r in rows) else ""))
    return lines


def markdown(result: dict) -> str:
    """design.md: what was asked, the ranked table, the predictor's card and its limits."""
    rows = result["designs"]
    out = [f"# Design answer: {result['space']}", "",
           f"Scene `{result['scene']}`, spec `{result['spec']}` (rule {result['decision_rule']}, "
           f"confidence {result['confidence']:.0%}), {result['test_frames']} test frames, "
           f"passing at P(accept) >= {result['min_probability']}.", "",
           "| rank | status | P(accept) | margin | X mm | Y mm | alpha deg | cost | design |",
           "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    out += ["| " + " | ".join(c.replace("|", "\\|") for c in _cells(r)) + " |" for r in rows]
    if result.get("verify"):
        out += ["", "## Predicted against rendered (--verify)", "",
                "| " + " | ".join(VERIFY_HEAD) + " |", "|" + " --- |" * len(VERIFY_HEAD)]
        out += ["| " + " | ".join(c.replace("|", "\\|") for c in _verify_cells(v)) + " |" for v in result["verify"]]
    out += ["", f"Predictor card `{result['card']['path']}`: " + result["card"]["summary"], "",
            *[f"- {n}" for n in result["notes"]], ""]
    return "\n".join(out)


def _plot_png(rows: list[dict]) -> str | None:
    pts = [r for r in rows if r.get("worst_margin") is not None]
    if not pts:
        return None
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    costed = any(r["cost"] > 0 for r in pts)
    xs = [r["cost"] if costed else r["width"] * r["height"] / 1e6 for r in pts]
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for status, style in (("passes", dict(c="tab:green")), ("undecided", dict(c="tab:orange", alpha=0.7)),
                          ("fails", dict(c="tab:red", alpha=0.5))):
        sel = [i for i, r in enumerate(pts) if r["status"] == status]
        ax.scatter([xs[i] for i in sel], [pts[i]["worst_margin"] for i in sel], s=18, label=status, **style)
    par = [i for i, r in enumerate(pts) if r.get("pareto")]
    ax.scatter([xs[i] for i in par], [pts[i]["worst_margin"] for i in par], s=70, facecolors="none",
               edgecolors="k", label="Pareto front")
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    ax.set_xlabel("cost" if costed else "megapixels")
    ax.set_ylabel("worst margin (predicted RMSE / threshold)")
    ax.legend(fontsize=8)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode()


def _html(result: dict, png: str | None) -> str:
    esc = html.escape
    head = ["rank", "status", "P(accept)", "margin", "X mm", "Y mm", "alpha deg", "cost", "design"]
    rows = "".join("<tr>" + "".join(f"<td>{esc(c)}</td>" for c in _cells(r)) + "</tr>" for r in result["designs"])
    img = f'<img alt="margin against cost" src="data:image/png;base64,{png}">' if png else ""
    notes = "".join(f"<li>{esc(n)}</li>" for n in result["notes"])
    verify = "" if not result.get("verify") else (
        "<h2>Predicted against rendered (--verify)</h2><table><tr>" + "".join(f"<th>{esc(h)}</th>" for h in VERIFY_HEAD)
        + "</tr>" + "".join("<tr>" + "".join(f"<td>{esc(c)}</td>" for c in _verify_cells(v)) + "</tr>"
                            for v in result["verify"]) + "</table>")
    return ("<!doctype html><html><head><meta charset='utf-8'><title>dockfactory design</title>"
            "<style>body{font-family:sans-serif;margin:2em}td,th{border:1px solid #ccc;padding:2px 6px;"
            "font-size:13px}table{border-collapse:collapse}</style></head><body>"
            f"<h1>Design answer: {esc(result['space'])}</h1><p>Scene <code>{esc(result['scene'])}</code>, "
            f"spec <code>{esc(result['spec'])}</code>, {result['test_frames']} test frames, passing at "
            f"P(accept) &ge; {result['min_probability']}.</p>{img}<table><tr>"
            + "".join(f"<th>{esc(h)}</th>" for h in head) + f"</tr>{rows}</table>{verify}"
            f"<p>Predictor card <code>{esc(result['card']['path'])}</code>: {esc(result['card']['summary'])}</p>"
            f"<ul>{notes}</ul></body></html>\n")


def write_design_outputs(out_dir, result: dict) -> list[Path]:
    """design.json, design.md, design.html (+ design.png) in ``out_dir``; the paths written.
    DockfactoryError (one line naming ``--out``) when ``out_dir`` is a file or cannot be made."""
    out = make_output_folder(out_dir)
    png = _plot_png(result["designs"])
    write_json_atomic(out / "design.json", result)
    write_text_atomic(out / "design.md", markdown(result))
    write_text_atomic(out / "design.html", _html(result, png))
    paths = [out / "design.json", out / "design.md", out / "design.html"]
    if png:
        (out / "design.png.tmp").write_bytes(base64.b64decode(png))
        (out / "design.png.tmp").replace(out / "design.png")
        paths.append(out / "design.png")
    return paths
