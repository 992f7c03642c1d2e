"""The report's camera sections: "Which cameras pass" (the tolerance envelope, eval.envelope, as
contours of each gated localization statistic over (principal-point offset, k1) with its threshold
line) and "Camera model" (eval.camera_models_eval: pinhole beside self-calibration)."""
from __future__ import annotations

import html

import numpy as np

# what the report reads of metrics["camera_envelope"] (see eval.report.check_schema)
ENVELOPE_SCHEMA = {"pp_offsets_px": ("list", "num"), "k1": ("list", "num"), "directions": "int", "frames": "int",
                   "sigma_px": "num", "statistic": "str", "thresholds": ("map", "num"),
                   "values": ("map", ("list", ("list", "num?"))), "passes": ("list", ("list", "bool")),
                   "pixel_aspect?": ("list", "num"), "verdict": "str"}


def plot_envelope(plt, env: dict, fig_png) -> str:
    """One panel per gated component: filled contours of the statistic, the threshold as a line."""
    comps = list(env["values"])
    fig, axes = plt.subplots(1, len(comps), figsize=(4.2 * len(comps), 3.6), squeeze=False)
    k1, pp = np.array(env["k1"]), np.array(env["pp_offsets_px"])
    for ax, c in zip(axes[0], comps):
        v = np.array([[np.nan if x is None else x for x in row] for row in env["values"][c]], dtype=float)
        thr = env["thresholds"][c]
        top = np.nanmax(v) if np.isfinite(v).any() else thr
        cs = ax.contourf(k1, pp, np.minimum(v, 2 * max(top, thr)), levels=12, cmap="viridis")
        fig.colorbar(cs, ax=ax, shrink=0.85)
        if np.nanmin(v) < thr < np.nanmax(v):
            ax.contour(k1, pp, v, levels=[thr], colors="red", linewidths=2)
        ax.set_title(f"{c} {env['statistic']} (limit {thr:g}, red)", fontsize=9)
        ax.set_xlabel("k1")
        ax.set_ylabel("principal point offset (px)")
    fig.tight_layout()
    return fig_png(fig)


def html_envelope(env: dict, img_html: str) -> list[str]:
    passes = np.array(env["passes"], dtype=bool)
    head = "".join(f"<th>k1 {k:g}</th>" for k in env["k1"])
    body = "".join("<tr><th>" + f"{m:g} px" + "</th>" + "".join(
        f"<td class='{'pass' if ok else 'fail'}'>{'pass' if ok else 'fail'}</td>" for ok in row) + "</tr>"
        for m, row in zip(env["pp_offsets_px"], passes))
    return ["<h2>Which cameras pass without calibration</h2>",
            f"<p>{html.escape(env['verdict'])}.</p>",
            f"<p>The test geometry of this dataset ({env['frames']} frames), its marker centres projected through "
            f"cameras whose principal point is off centre (worst of {env['directions']} directions) and with radial "
            f"distortion k1, plus {env['sigma_px']:.3g} px of centre noise, solved as the paper does (pinhole, "
            f"principal point at the image centre). Outside the passing cells a camera needs self-calibration "
            f"(<code>dockfactory measure --self-calibrate</code>).</p>",
            f"<table><tr><th>principal point offset</th>{head}</tr>{body}</table>", img_html]


_STAT4 = {"n": "int", "mean": "num?", "rmse": "num?", "p95": "num?"}
CAMERA_MODELS_SCHEMA = ("map", {"camera_model": "str", "self_calibrate": "str?", "n_frames": "int", "n_solved": "int",
                                "models_chosen": ("map", "int"), "pose": ("map", _STAT4),
                                "intrinsics_error": ("map", _STAT4), "rmse_over_reference?": ("map", "num?")})
UNIT = {"x": "mm", "y": "mm", "alpha": "deg", "pp_px": "px", "k1": "", "k2": "", "focal_pct": "%"}


def _cell(s: dict, key: str) -> str:
    v = s.get(key)
    return "-" if v is None else f"{v:.4g}"


def html_camera_models(block: dict) -> list[str]:
    """The test split solved with each camera model: pose errors and intrinsics errors."""
    head = ("<tr><th>solve</th><th>solved</th><th>models</th>"
            + "".join(f"<th>{html.escape(c)} bias / RMSE / p95 ({UNIT[c]})</th>" for c in ("x", "y", "alpha"))
            + "".join(f"<th>{k} error mean / RMSE</th>" for k in ("pp_px", "k1", "k2", "focal_pct"))
            + "<th>RMSE / reference (x, y, alpha)</th></tr>")
    rows = []
    for name, b in block.items():
        models = ", ".join(f"{m} {n}" for m, n in b["models_chosen"].items())
        cells = [f"<td>{_cell(b['pose'][c], 'mean')} / {_cell(b['pose'][c], 'rmse')} / {_cell(b['pose'][c], 'p95')}</td>"
                 for c in ("x", "y", "alpha")]
        cells += [f"<td>{_cell(b['intrinsics_error'][k], 'mean')} / {_cell(b['intrinsics_error'][k], 'rmse')}</td>"
                  for k in ("pp_px", "k1", "k2", "focal_pct")]
        ratio = b.get("rmse_over_reference") or {}
        cells.append("<td>" + " / ".join(_cell(ratio, c) for c in ("x", "y", "alpha")) + "</td>")
        rows.append(f"<tr><th>{html.escape(name)}</th><td>{b['n_solved']} of {b['n_frames']}</td>"
                    f"<td>{html.escape(models)}</td>{''.join(cells)}</tr>")
    return ["<h2>Camera model: the paper's pinhole beside self-calibration</h2>",
            "<p>The same test frames and centres solved with the paper's camera (focal length only, principal "
            "point at the image centre, no distortion) and self-calibrated: the model each frame supports, and "
            "each docking run (one camera unit) with shared intrinsics. Intrinsics errors are the estimate "
            "(or, for the pinhole, what it assumes) minus the truth in the labels; pp_px is the distance of "
            "the principal point. The reference solves each frame through its true camera (centres undistorted "
            "with the labels' principal point and distortion; the focal length still estimated): what a calibrated "
            "camera would give; the last column is each solve's RMSE over the reference's.</p>", f"<table>{head}{''.join(rows)}</table>"]
