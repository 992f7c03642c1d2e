"""``dockfactory report``: one self-contained HTML file (images embedded) a quality engineer can
read and print, plus report.json and a short Markdown summary for CI logs."""
from __future__ import annotations

import base64
import csv
import datetime as _dt
import hashlib
import html
import io
import json
import os
import subprocess
from pathlib import Path

from dockfactory.eval.gate_statistic import STATISTICS, gate_statistic, statistics_of, summary_fields
from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.geometry import intrinsics, project_points
from dockfactory.core.io import write_json_atomic, write_text_atomic
from dockfactory.eval.acceptance import COMPONENTS, UNITS
from dockfactory.eval.dataset_access import json_kind, read_json_file, validate_detections, validate_poses
from dockfactory.eval.acceptance import DECISION_RULES, Gate, criterion_passes, decide_criterion, overall_verdict
from dockfactory.eval.report.calibration import (
    CALIBRATION_SCHEMA,
    CENTRE_NOISE_SCHEMA,
    html_bound,
    html_calibration,
    html_centre_noise,
    markdown_honesty,
    plot_qq,
)
from dockfactory.eval.report.budget import html_budget
from dockfactory.eval.report.cameras import (
    CAMERA_MODELS_SCHEMA,
    ENVELOPE_SCHEMA,
    html_camera_models,
    html_envelope,
    plot_envelope,
)
from dockfactory.eval.model_check import BLOCK_SCHEMA as MODEL_CHECK_SCHEMA
from dockfactory.eval.model_check import html_model_check, model_check_sentence
from dockfactory.eval.simulated_cameras import BLOCK_SCHEMA as SIMULATED_CAMERAS_SCHEMA
from dockfactory.eval.simulated_cameras import html_simulated_cameras, sensor_schema
from dockfactory.generator.datasets.folder import DatasetError
from dockfactory.generator.labels import image_px
from dockfactory.generator.version import generator_version, package_version

GATED = ("x", "y", "alpha")


def _fig_png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    import matplotlib.pyplot as plt
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode()


def _img(b64: str, alt: str) -> str:
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{b64}">'


def _num(v, digits=4) -> str:
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "-"
    return f"{v:.{digits}g}" if isinstance(v, float) else str(v)


ROW_TEXT = ("frame_id", "split", "condition", "reason", "category")
ROW_NEEDED = ("frame_id", "split", "condition", "ok")


def read_rows(eval_dir: Path) -> list[dict]:
    """The rows of EVAL/frames.csv, typed: ``ok`` a bool, the text columns text, the others float or None.

    Parameters
    ----------
    eval_dir : Path
        The evaluation folder holding frames.csv.

    Returns
    -------
    list of dict

    Raises
    ------
    DatasetError
        Naming the file, row and column: a missing or unreadable file, a missing or bad value.
    """
    path = eval_dir / "frames.csv"
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    except FileNotFoundError:
        raise DatasetError(f"{path}: per-frame table not found (run dockfactory evaluate first)") from None
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise DatasetError(f"{path}: unreadable per-frame table ({exc})") from None
    for i, r in enumerate(rows, start=2):
        for k in ROW_NEEDED:
            if r.get(k) in (None, ""):
                raise DatasetError(f"{path}: line {i}: column {k!r} missing or empty")
        if r["ok"] not in ("True", "False"):
            raise DatasetError(f"{path}: line {i}: ok: expected True or False, got {r['ok']!r}")
        for k, v in list(r.items()):
            if k is None or k in ROW_TEXT:
                if k is None:
                    raise DatasetError(f"{path}: line {i}: more values than columns")
                continue
            if k == "ok":
                r[k] = v == "True"
                continue
            try:
                r[k] = float(v) if v not in ("", None) else None
            except ValueError:
                raise DatasetError(f"{path}: line {i}: {k}: expected a number, got {v!r}") from None
            if r[k] is not None and not np.isfinite(r[k]):
                raise DatasetError(f"{path}: line {i}: {k}: must be finite, got {v!r}")
        if r["ok"] and r["split"] == "test":
            for k in [f"err_{c}" for c in GATED] + ["distance_mm", "focal_true"]:
                if r.get(k) is None:
                    raise DatasetError(f"{path}: line {i}: {k}: missing for a solved test frame")
    return rows


def check_rows_match(rows: list[dict], metrics: dict, path) -> None:
    """DatasetError unless the per-frame table has one row per frame the metrics count (test
    frames and repeatability captures) and as many solved test frames: a table cut down (to its
    header, say) must not pass for the evaluation it came with."""
    loc, est = metrics["localization"], metrics["estimation"]
    test = [r for r in rows if r["split"] == "test"]
    counts = {"test frames": (len(test), loc["n_frames"]),
              "repeatability captures": (len(rows) - len(test), est["n_frames"]),
              "solved test frames": (sum(r["ok"] for r in test), loc["n_solved"])}
    for what, (have, want) in counts.items():
        if have != want:
            raise DatasetError(f"{path}: {have} {what}, the metrics beside it count {want}: "
                               "the table does not belong to this evaluation (re-run dockfactory evaluate)")


TOLERANCE_STYLE = {"color": "#b00020", "ls": "--", "lw": 1.0}


def localization_tolerances(metrics: dict) -> dict:
    """Component -> the localization threshold in its unit (mm, deg; the root of an mse one)."""
    out = {}
    for c in (metrics.get("acceptance") or {}).get("criteria", []):
        if c.get("block") == "localization" and c["threshold"] is not None:
            out[c["component"]] = gate_statistic(c["statistic"]).to_rms(c["threshold"])
    return out


def _plot_error_histograms(plt, test: list[dict], tol: dict) -> str:
    fig, axes = plt.subplots(1, 3, figsize=(11, 3))
    for ax, c in zip(axes, GATED):
        e = [r[f"err_{c}"] for r in test]
        ax.hist(e, bins=max(5, min(40, len(e) // 2 or 5)), color="#4477aa")
        ax.set_title(f"{c} error ({UNITS[c]})")
        ax.axvline(0, color="k", lw=0.8)
        if c in tol:   # the tolerance: the errors seen against what is allowed
            ax.axvline(-tol[c], **TOLERANCE_STYLE, label=f"tolerance +-{tol[c]:g} {UNITS[c]}")
            ax.axvline(tol[c], **TOLERANCE_STYLE)
            ax.legend(fontsize=7)
    return _fig_png(fig)


def _plot_xy_scatter(plt, test: list[dict], tol: dict) -> str:
    fig, ax = plt.subplots(figsize=(4.5, 4.5))
    ax.scatter([r["err_x"] for r in test], [r["err_y"] for r in test], s=10, c="#aa3377")
    ax.set_xlabel("X error (mm)")
    ax.set_ylabel("Y error (mm)")
    ax.axhline(0, color="k", lw=0.5)
    ax.axvline(0, color="k", lw=0.5)
    if "x" in tol and "y" in tol:
        tx, ty = tol["x"], tol["y"]
        ax.plot([-tx, tx, tx, -tx, -tx], [-ty, -ty, ty, ty, -ty], **TOLERANCE_STYLE, label="tolerance")
        ax.legend(fontsize=7)
    ax.set_aspect("equal", "datalim")
    return _fig_png(fig)


def _plot_per_condition(plt, test: list[dict], tol: dict) -> str:
    conds = sorted({r["condition"] for r in test})
    fig, axes = plt.subplots(1, 3, figsize=(11, 3))
    for ax, c in zip(axes, GATED):
        ax.boxplot([[abs(r[f"err_{c}"]) for r in test if r["condition"] == k] or [0.0] for k in conds])
        ax.set_xticks(range(1, len(conds) + 1), conds, rotation=20)
        ax.set_title(f"|{c} error| ({UNITS[c]}) per condition")
        if c in tol:
            ax.axhline(tol[c], **TOLERANCE_STYLE, label="tolerance")
            ax.legend(fontsize=7)
    return _fig_png(fig)


def _plot_distance_focal(plt, test: list[dict], tol: dict) -> str:
    """|error| against camera distance and focal length, the tolerance drawn on every panel (the
    axis then runs to it, as the per-condition panels do)."""
    fig, axes = plt.subplots(2, 3, figsize=(11, 5.5))
    for j, c in enumerate(GATED):
        for i, (key, label, colour) in enumerate((("distance_mm", "camera distance (mm)", "#0077bb"),
                                                   ("focal_true", "focal length (px)", "#228833"))):
            ax = axes[i, j]
            ax.scatter([r[key] for r in test], [abs(r[f"err_{c}"]) for r in test], s=8, c=colour)
            ax.set_xlabel(label)
            ax.set_ylabel(f"|{c} error| ({UNITS[c]})")
            if c in tol:
                ax.axhline(tol[c], **TOLERANCE_STYLE, label="tolerance")
                ax.legend(fontsize=7)
    fig.tight_layout()
    return _fig_png(fig)


def _plot_against_crb(plt, test: list[dict], tol: dict) -> str:
    """|error| against the frame's Cramer-Rao std; the tolerance is drawn when it falls on the
    axis, else named in the panel's corner (the panel is about the bound, at the bound's scale)."""
    fig, axes = plt.subplots(1, 3, figsize=(11, 3.2))
    for ax, c in zip(axes, GATED):
        pts = [(r[f"crb_{c}"], abs(r[f"err_{c}"])) for r in test if r.get(f"crb_{c}")]
        if pts:
            b, e = np.array(pts).T
            ax.scatter(b, e, s=8, c="#ee7733")
            lim = max(b.max(), e.max()) * 1.05
            ax.plot([0, lim], [0, lim], "k--", lw=0.8, label="|error| = bound")
            ax.plot([0, lim], [0, 2 * lim], "k:", lw=0.8, label="2 x bound")
            if c in tol and tol[c] <= 2 * lim:
                ax.axhline(tol[c], **TOLERANCE_STYLE, label="tolerance")
            elif c in tol:
                ax.text(0.02, 0.95, f"tolerance {tol[c]:g} {UNITS[c]}: above this axis", transform=ax.transAxes,
                        fontsize=7, va="top", color=TOLERANCE_STYLE["color"])
            ax.legend(fontsize=7, loc="lower right")
        ax.set_xlabel(f"Cramer-Rao std of {c} ({UNITS[c]})")
        ax.set_ylabel(f"|{c} error| ({UNITS[c]})")
    fig.tight_layout()
    return _fig_png(fig)


def _plot_precision_recall(plt, detections_pr: dict) -> str:
    fig, ax = plt.subplots(figsize=(5, 4))
    for name, (rec, prec) in detections_pr.items():
        ax.plot(rec, prec, label=name)
    ax.set_xlabel("recall")
    ax.set_ylabel("precision")
    ax.set_title("precision-recall at IoU 0.5")
    ax.legend()
    return _fig_png(fig)


def plots(rows: list[dict], metrics: dict, detections_pr=None) -> dict[str, str]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    test = [r for r in rows if r["split"] == "test" and r["ok"]]
    out = {}
    tol = localization_tolerances(metrics)
    out["Error histograms (test split)"] = _plot_error_histograms(plt, test, tol)
    out["X-Y error scatter"] = _plot_xy_scatter(plt, test, tol)
    out["Error per condition"] = _plot_per_condition(plt, test, tol)
    out["Error against camera distance and focal length"] = _plot_distance_focal(plt, test, tol)
    out["Measured error against the Cramer-Rao bound"] = _plot_against_crb(plt, test, tol)
    if detections_pr:
        out["Precision-recall per class"] = _plot_precision_recall(plt, detections_pr)
    return out


def gallery(dataset_root: Path, rows: list[dict], poses: dict | None, detections: dict | None, n: int = 6) -> list[tuple[str, str]]:
    """The worst frames (largest normalised X/Y/alpha error; failures first) with markers drawn."""
    test = [r for r in rows if r["split"] == "test"]

    def badness(r):
        if not r["ok"]:
            return float("inf")
        return max(abs(r[f"err_{c}"]) / (r.get(f"crb_{c}") or 1.0) for c in GATED)

    worst = sorted(test, key=badness, reverse=True)[:n]
    items = []
    for r in worst:
        fid = r["frame_id"]
        if "/" in fid or "\\" in fid or fid in (".", ".."):
            continue
        img = cv2.imread(str(dataset_root / "images" / f"{fid}.png"))
        if img is None:
            raise DatasetError(f"{dataset_root / 'images' / f'{fid}.png'}: missing or unreadable: the report "
                               "draws this frame among the worst (verify the dataset: dockfactory dataset verify)")
        try:
            lab = read_json_file(dataset_root / "labels" / f"{fid}.json", "label")
            item = _gallery_item(img, r, lab, poses, detections)
        except (DatasetError, KeyError, TypeError, ValueError, IndexError):
            continue   # the gallery is an illustration: a frame it cannot draw is left out
        items.append(item)
    return items


def _gallery_item(img, r: dict, lab: dict, poses: dict | None, detections: dict | None) -> tuple[str, str]:
    fid = r["frame_id"]
    for m in lab["markers"]:   # true centres: green circles
        u, v = m["center_px"]
        cv2.circle(img, (int(round(u * 16)), int(round(v * 16))), 9 * 16, (0, 220, 0), 1, cv2.LINE_AA, 4)
    for d in (detections or {}).get("frames", {}).get(fid, []):   # detections: magenta crosses
        u, v = d["center_px"]
        cv2.drawMarker(img, (int(round(u)), int(round(v))), (255, 0, 255), cv2.MARKER_TILTED_CROSS, 10, 1)
    rec = (poses or {}).get("frames", {}).get(fid)
    # the layout reprojected with the estimated poses and focal: yellow dots
    if rec and rec.get("ok") is True and rec.get("cam_from_a") is not None and rec.get("d_from_b") is not None:
        for u, v in reprojected_layout(rec, lab, poses):
            if np.isfinite(u) and np.isfinite(v):
                cv2.circle(img, (int(round(u)), int(round(v))), 3, (0, 255, 255), -1, cv2.LINE_AA)
    h, w = img.shape[:2]
    scale = 640 / w
    img = cv2.resize(img, (640, int(h * scale)), interpolation=cv2.INTER_AREA)
    ok, png = cv2.imencode(".png", img)
    cap = (f"{fid} ({r['condition']}): " + (f"failed: {r['reason']}" if not r["ok"] else
           ", ".join(f"{c} err {r[f'err_{c}']:+.3f} {UNITS[c]}" for c in GATED)))
    return cap, base64.b64encode(png.tobytes()).decode()


def reprojected_layout(rec: dict, lab: dict, poses: dict) -> np.ndarray:
    """(N, 2) delivered-image pixels (NaN behind the camera) of the label ``lab``'s N markers under
    a solved record ``rec``'s poses and focal, through the camera its solve assumed: the poses'
    principal point, pinhole (the single-focal model the solver fitted to the delivered pixels);
    for a true-camera solve (``poses["true_camera"]``: the square-pixel pinhole at fx of the label's
    camera, eval.solve_frames.true_camera_centres) back through the label's principal point, pixel
    aspect (K's fy) and distortion (generator.labels.image_px)."""
    cam = lab["camera"]
    true_camera = bool(poses.get("true_camera"))
    pp = cam["principal_point"] if true_camera else poses.get("principal_point", cam["principal_point"])
    k = intrinsics(rec["focal_px"], pp)
    cam_from_a, d_from_b = np.array(rec["cam_from_a"]), np.array(rec["d_from_b"])
    uv = np.array([project_points(k, cam_from_a @ (d_from_b if m["section"] == "B" else np.eye(4)),
                                  np.array(m["center_section_mm"])[None])[0][0] for m in lab["markers"]])
    uv = uv.reshape(-1, 2)
    if not true_camera:
        return uv
    return image_px(uv, np.array(cam["K"], dtype=float), cam.get("distortion") or [0.0] * 5)


def git_describe() -> str:
    """The commit of a source checkout of dockfactory ("installed" for a wheel install: the folder
    above the package may belong to some other repository, whose commit would be a lie)."""
    checkout = Path(__file__).resolve().parent.parent
    if not (checkout / "pyproject.toml").is_file() or not (checkout / "eval" / "report.py").is_file():
        return "installed (no source checkout)"
    try:
        return subprocess.run(["git", "describe", "--always", "--dirty", "--tags"], capture_output=True, text=True,
                              cwd=checkout, timeout=10).stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


# ----------------------------------------------------------------------------- inputs
# A small schema of what the report reads from metrics.json (and provenance.json): "num" a finite
# number, "num?" a finite number or null, "int", "str", "str?", "bool", "any"; a dict is an
# object with those keys (a key ending in "?" may be absent); ("map", S) an object whose values
# are S; ("list", S) a list of S.
_STATS = {k: "num?" for k in summary_fields() if k != "n"} | {"n": "int"}   # eval.pose_metrics.error_stats
_COMPS = {c: _STATS for c in COMPONENTS}
_RATIOS = ("map", {"bound_rms": "num?", "measured_rmse": "num?", "ratio": "num?", "ratio_low?": "num?",
                   "ratio_high?": "num?"})
METRICS_SCHEMA = {
    "dataset": {"root": "str", "version_id": "str", "name": "str"},
    "poses": {"source": "str?", "path": "str"},
    "centre_noise_px": "num?",
    "centre_noise?": CENTRE_NOISE_SCHEMA,
    "localization": {"n_frames": "int", "n_solved": "int", "overall": _COMPS, "by_condition": ("map", _COMPS),
                     "focal_err_pct": _STATS, "reprojection_rmse_px": {"A": _STATS, "B": _STATS},
                     "crb": _RATIOS, "crb_structured?": _RATIOS, "fit_structured?": _RATIOS,
                     "calibration?": CALIBRATION_SCHEMA},
    "estimation": {"n_frames": "int", "n_solved": "int",
                   "per_pose": ("list", {"pose": "str", "captures": "int"} | {c: "num?" for c in COMPONENTS}),
                   "pooled": {c: {k: "num?" for k in statistics_of("estimation")} for c in COMPONENTS}},
    "failures_test": {"count": "int", "frames": "int", "rate": "num?",
                      "by_condition": ("map", {"failed": "int", "frames": "int"}),
                      "list": ("list", {"frame_id": "str", "condition": "str", "reason": "str"})},
    "oracle?": {"localization": {"overall": {c: {"rmse": "num?"} for c in COMPONENTS},
                                 "calibration?": CALIBRATION_SCHEMA}},
    "detection?": {"map50?": "num?", "map50_95?": "num?",
                   "per_class?": ("map", {"map50?": "num?", "map50_95?": "num?"}),
                   "pr_curves?": ("map", ("list", ("list", "num")))},
    "camera_envelope?": ENVELOPE_SCHEMA,
    "camera_models?": CAMERA_MODELS_SCHEMA,
    "simulated_cameras?": SIMULATED_CAMERAS_SCHEMA,
    "model_check?": MODEL_CHECK_SCHEMA,
    "bounds?": "any",
    "uncertainty_budget?": "any",
    "acceptance": {"accepted": "bool", "verdict?": "str", "decision_rule?": "str", "confidence?": "num",
                   "criteria": ("list", {"name": "str", "statistic": "str", "value": "num?", "threshold": "num",
                                         "unit": "str", "pass": "bool", "paper?": "num?", "note?": "str",
                                         "block?": "str", "lower?": "num?", "upper?": "num?", "bounds_by?": "str?",
                                         "decision?": "str"}),
                   "ungated?": ("list", "str")},
}
PROVENANCE_SCHEMA = {"detections?": "str?", "commands?": ("list", "str"), "model_sha256?": "str?"}


def check_schema(value, schema, path, key: str = "") -> None:
    """Check that a parsed JSON value follows a schema.

    Parameters
    ----------
    value : object
        The parsed JSON value.
    schema : dict, tuple or str
        A dict of keys (``name?`` optional), ("map", sub) / ("list", sub) / ("pair", sub) (a list of
        exactly two), "any", or a leaf type ("num", "int", "str", "bool"; with "?" also null).
    path : path
        The file the value was read from (named in the error).
    key : str
        The value's place in that file (named in the error).

    Returns
    -------
    None

    Raises
    ------
    DatasetError
        "PATH: KEY: problem" where ``value`` does not follow ``schema``.
    """
    if isinstance(schema, dict):
        _check_object(value, schema, path, key)
    elif isinstance(schema, tuple):
        kind, sub = schema
        want = dict if kind == "map" else list
        if not isinstance(value, want):
            _schema_error(path, key, f"expected {'an object' if kind == 'map' else 'a list'}, got {json_kind(value)}")
        if kind == "pair" and len(value) != 2:
            _schema_error(path, key, f"expected 2 values, got {len(value)}")
        items = value.items() if kind == "map" else enumerate(value)
        for k, v in items:
            check_schema(v, sub, path, f"{key}.{k}" if kind == "map" else f"{key}[{k}]")
    elif schema != "any":
        _check_leaf(value, schema, path, key)


def _schema_error(path, key: str, msg: str):
    raise DatasetError(f"{path}: {key or '(top level)'}: {msg}")


def _check_object(value, schema: dict, path, key: str) -> None:
    if not isinstance(value, dict):
        _schema_error(path, key, f"expected an object, got {json_kind(value)}")
    for k, sub in schema.items():
        name, optional = (k[:-1], True) if k.endswith("?") else (k, False)
        if name not in value:
            if optional:
                continue
            raise DatasetError(f"{path}: {key + '.' if key else ''}{name}: missing")
        check_schema(value[name], sub, path, f"{key}.{name}" if key else name)


def _check_leaf(value, schema: str, path, key: str) -> None:
    if schema.endswith("?"):
        if value is None:
            return
        schema = schema[:-1]
    if schema == "num":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            _schema_error(path, key, f"expected a number, got {json_kind(value)}")
        if not np.isfinite(value):
            _schema_error(path, key, f"must be finite, got {value}")
    elif schema == "int":
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            _schema_error(path, key, f"expected a count (integer >= 0), got {json_kind(value)} {value!r:.40}")
    elif schema == "str":
        if not isinstance(value, str):
            _schema_error(path, key, f"expected a string, got {json_kind(value)}")
    elif schema == "bool":
        if not isinstance(value, bool):
            _schema_error(path, key, f"expected true or false, got {json_kind(value)} {value!r:.40}")
    else:
        raise ValueError(f"unknown schema {schema!r}")   # programming error


def checked_verdict(acc: dict, path) -> str:
    """The verdict of the criteria rows the report prints, recomputed from each row's value,
    bounds and threshold under the spec's decision rule; a metrics.json whose pass flags,
    decisions, ``accepted`` or ``verdict`` disagree with its own rows (edited by hand, or written
    by a buggy tool) is refused, never believed."""
    if not acc["criteria"]:
        raise DatasetError(f"{path}: acceptance.criteria: empty (a verdict needs criteria)")
    rule = acc.get("decision_rule", "simple")
    if rule not in DECISION_RULES:
        raise DatasetError(f"{path}: acceptance.decision_rule: {rule!r} is not one of {', '.join(DECISION_RULES)}")
    for i, c in enumerate(acc["criteria"]):
        decision = _recomputed_decision(c, rule)
        if (decision == "pass") != c["pass"] or c.get("decision", decision) != decision:
            raise DatasetError(f"{path}: acceptance.criteria[{i}] ({c['name']}): pass is {str(c['pass']).lower()} "
                               f"(decision {c.get('decision')}) but value {c['value']} against threshold "
                               f"{c['threshold']} ({c['statistic']}, {rule} rule) gives {decision}; refusing an "
                               "inconsistent metrics.json (run dockfactory evaluate again)")
    verdict = overall_verdict(acc["criteria"])
    if (verdict == "ACCEPTED") != acc["accepted"] or acc.get("verdict", verdict) != verdict:
        raise DatasetError(f"{path}: acceptance.accepted / verdict ({str(acc['accepted']).lower()}, "
                           f"{acc.get('verdict')}) contradict its criteria (which give {verdict}); refusing an "
                           "inconsistent metrics.json (run dockfactory evaluate again)")
    return verdict


def _recomputed_decision(c: dict, rule: str) -> str:
    """A criterion row's decision from its own numbers: pose statistics under the rule (with
    their bounds), detection minima and the failure rate on the value."""
    if c.get("block") in ("estimation", "localization") and "decision" in c:
        return decide_criterion(rule, c["value"], c["threshold"], c.get("lower"), c.get("upper"))
    return "pass" if criterion_passes(c["statistic"], c["value"], c["threshold"]) else "fail"


def input_path(text: str, eval_dir: Path, named_by: str) -> Path:
    """The file or folder an evaluation names (``text``, from its metrics.json or
    provenance.json): absolute as it is; relative to the evaluation folder (how evaluate and run
    record them, so that the evaluation travels as one tree and ``report`` runs from any folder),
    else to the current folder (evaluations recorded before). Missing: a one-line DatasetError
    naming the key and both places looked in, never a report with parts silently left out."""
    p = Path(text)
    for candidate in ([p] if p.is_absolute() else [eval_dir / p, p]):
        if candidate.exists():
            return candidate
    where = str(p) if p.is_absolute() else f"{eval_dir / p} or {p.resolve()}"
    raise DatasetError(f"{named_by}: {text} not found ({where}): the report reads it; run report where the "
                       "evaluation's inputs are, or evaluate again")


def _input_json(text: str, eval_dir: Path, what: str, named_by: str):
    """The JSON of the input ``text`` names (:func:`input_path`); a broken one is refused naming
    both files."""
    try:
        return read_json_file(input_path(text, eval_dir, named_by), what)
    except DatasetError as exc:
        raise DatasetError(f"{named_by}: {exc}" if named_by not in str(exc) else str(exc)) from None


def report_date() -> str:
    """The report's date: now (UTC), or ``SOURCE_DATE_EPOCH`` when set (reproducible builds:
    the same evaluation then gives the same bytes)."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH", "").strip()
    when = _dt.datetime.fromtimestamp(int(epoch), _dt.timezone.utc) if epoch.isdigit() \
        else _dt.datetime.now(_dt.timezone.utc)
    return when.isoformat(timespec="seconds")


def _report_provenance(metrics: dict, prov: dict, commands: list[str] | None) -> dict:
    return {
        "dataset_version": metrics["dataset"]["version_id"], "dataset": metrics["dataset"]["root"],
        "model_sha256": prov.get("model_sha256") or "n/a (oracle or no detector)",
        "code_version": git_describe(), "generator_version": generator_version(),
        "software": {p: package_version(p) for p in ("numpy", "torch", "bpy", "opencv-python-headless", "pycocotools", "matplotlib")},
        "date": report_date(),
        "commands": commands or prov.get("commands", []),
    }


def _note(c: dict) -> str:
    return f" ({html.escape(c['note'])})" if c.get("note") else ""


def _decision(c: dict) -> str:
    return c.get("decision", "pass" if c["pass"] else "fail").upper()


def _bounds_cell(c: dict, conf: float) -> str:
    if c.get("upper") is None:
        return "-"
    return (f"{_num(c['lower'])} - {_num(c['upper'])} {c['unit']} "
            f"<span class='note'>({html.escape(c.get('bounds_by') or '')})</span>")


def _criteria_rows(acc: dict) -> str:
    out = []
    conf = acc.get("confidence", 0.95)
    for c in acc["criteria"]:
        decision = _decision(c)
        cls = {"PASS": "pass", "FAIL": "fail"}.get(decision, "undecided")
        out.append(f"<tr class='{cls}'><td>{html.escape(c['name'])}</td><td>{c['statistic']}</td>"
                   f"<td>{_num(c['value'])} {c['unit']}{_note(c)}</td><td>{_bounds_cell(c, conf)}</td>"
                   f"<td>{_num(c['threshold'])} {c['unit']}</td>"
                   f"<td>{_num(c.get('paper'))} {c['unit'] if c.get('paper') is not None else ''}</td>"
                   f"<td><b>{decision}</b></td></tr>")
    return "\n".join(out)


def _rule_text(acc: dict) -> str:
    """How the verdict was decided, in one sentence."""
    conf = acc.get("confidence", 0.95)
    if acc.get("decision_rule", "simple") == "guarded":
        return (f"Decision rule: guarded (ISO 14253-1 style). A pose statistic passes only when its one-sided "
                f"{conf:.0%} upper confidence bound is within its threshold, fails when its {conf:.0%} lower bound "
                f"is beyond it, and is UNDECIDED between (more frames would decide); bounds by {_bounds_methods(acc)} "
                "(the method of each bound in brackets). Detection minima and the failure rate compare the value itself.")
    return ("Decision rule: simple. Each statistic's value is compared with its threshold; its confidence "
            "bounds are shown but do not decide.")


def _bounds_methods(acc: dict) -> str:
    """How the bounds of the verdict's pose statistics are computed (each statistic's
    ``bounds_text``; the default statistic's when no pose criterion is gated)."""
    names = [c["statistic"] for c in acc["criteria"] if c.get("block") in ("estimation", "localization")]
    texts = dict.fromkeys(gate_statistic(n).bounds_text for n in names or [Gate.statistic] if n in STATISTICS)
    return "; ".join(texts)


MIN_N_STATS = 3   # fewer frames print "n too small", not a std of 0 or a 100 % coverage


_MOMENT_HEADERS = {"n": "n", "mean": "bias", "std": "std", "max": "max |e|"}


def _summary_header(field: str) -> str:
    """A statistics table's header of an error summary's field: a gate statistic's own, else the
    moment's (eval.pose_metrics.error_stats)."""
    return STATISTICS[field].header() if field in STATISTICS else _MOMENT_HEADERS[field]


def _stats_table(block: dict, title: str, min_n: int = 1) -> str:
    """A statistics table (units in every header); rows with fewer than ``min_n`` frames say so."""
    fields = summary_fields()
    head = "<tr><th>component</th>" + "".join(f"<th>{html.escape(_summary_header(k))}</th>" for k in fields) + "</tr>"
    rows = []
    for c in COMPONENTS:
        n = block[c].get("n") or 0
        cells = (f"<td>{n}</td><td colspan='{len(fields) - 1}' class='note'>n too small (fewer than {min_n} frames)</td>"
                 if n < min_n else "".join(f"<td>{_num(block[c][k])}</td>" for k in fields))
        rows.append(f"<tr><td>{c} ({UNITS[c]})</td>{cells}</tr>")
    return f"<h3>{html.escape(title)}</h3><table>{head}{''.join(rows)}</table>"


def _html_verdict(metrics: dict, acc: dict, verdict: str) -> list[str]:
    loc = metrics["localization"]
    cls = {"ACCEPTED": "pass", "REJECTED": "fail"}.get(verdict, "undecided")
    return [f"<h1>dockfactory acceptance report: <span class='{cls}'>{verdict}</span></h1>",
            f"<p>Dataset <code>{html.escape(metrics['dataset']['name'])}</code> version <code>{metrics['dataset']['version_id']}</code>; "
            f"poses from <b>{html.escape(str(metrics['poses']['source']))}</b>; test frames {loc['n_frames']} "
            f"(solved {loc['n_solved']}); repeatability captures {metrics['estimation']['n_frames']}.</p>",
            f"<h2>Verdict</h2><p>{html.escape(_rule_text(acc))}</p><table><tr><th>criterion</th><th>statistic</th><th>ours</th>"
            f"<th>{acc.get('confidence', 0.95):.0%} bounds</th><th>threshold</th><th>paper</th><th>result</th></tr>",
            _criteria_rows(acc), "</table>", _ungated_line(acc, "html"),
            "<p class='note'>Estimation precision = pooled spread of repeated estimates of one static pose; localization precision = "
            "error against exact ground truth (test split). RMSE in mm / deg, MSE in mm^2 / deg^2. The paper's localization alpha "
            "figure (0.869 deg) contradicts its own 0.1 deg criterion and is suspect.</p>"]


def _html_localization(metrics: dict) -> list[str]:
    loc = metrics["localization"]
    parts = ["<h2>Localization (test split)</h2>", _stats_table(loc["overall"], "all conditions")]
    for cond, block in loc["by_condition"].items():
        parts.append(_stats_table(block, f"condition: {cond}", MIN_N_STATS))
    parts += html_centre_noise(metrics) + html_bound(metrics)
    if "oracle" in metrics:
        o = metrics["oracle"]["localization"]["overall"]
        parts.append("<h3>Oracle (exact centres + noise of the measured size): separates detector from solver error</h3><table>"
                     "<tr><th>component</th><th>RMSE pipeline</th><th>RMSE oracle</th></tr>"
                     + "".join(f"<tr><td>{c} ({UNITS[c]})</td><td>{_num(loc['overall'][c]['rmse'])}</td><td>{_num(o[c]['rmse'])}</td></tr>" for c in COMPONENTS) + "</table>")
    return parts


def _html_calibration(metrics: dict, rows: list[dict]) -> list[str]:
    """The covariance-calibration section with its QQ plot (eval.report.calibration)."""
    if not metrics["localization"].get("calibration"):
        return []
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    png = plot_qq(plt, rows, _fig_png)
    return html_calibration(metrics, _img(png, "QQ plot of z = error / reported std") if png else None)


def _html_estimation(est: dict) -> str:
    return ("<h2>Estimation (repeatability)</h2><table><tr><th>pose</th><th>captures</th>"
            + "".join(f"<th>std {c}</th>" for c in COMPONENTS) + "</tr>"
            + "".join(f"<tr><td>{p['pose']}</td><td>{p['captures']}</td>" + "".join(f"<td>{_num(p[c])}</td>" for c in COMPONENTS) + "</tr>" for p in est["per_pose"])
            + "<tr><td><b>pooled</b></td><td></td>" + "".join(f"<td><b>{_num(est['pooled'][c]['rmse'])}</b></td>" for c in COMPONENTS) + "</tr></table>")


def _html_failures(metrics: dict) -> list[str]:
    f = metrics["failures_test"]
    rate = f"{100 * f['rate']:.2f} %" if f["rate"] is not None else "no test frames"
    parts = [f"<h2>Failures</h2><p>{f['count']} of {f['frames']} test frames without a pose "
             f"({rate}). By condition: "
             + ", ".join(f"{c}: {v['failed']}/{v['frames']}" for c, v in f["by_condition"].items()) + ".</p>"]
    if f["list"]:
        parts.append("<table><tr><th>frame</th><th>condition</th><th>reason</th></tr>" + "".join(
            f"<tr><td>{x['frame_id']}</td><td>{x['condition']}</td><td>{html.escape(x['reason'])}</td></tr>" for x in f["list"][:50]) + "</table>")
    loc = metrics["localization"]
    loc_f = loc["focal_err_pct"]
    parts.append(f"<p>Focal length error: RMSE {_num(loc_f['rmse'])} %, bias {_num(loc_f['mean'])} %. Reprojection RMSE "
                 f"A {_num(loc['reprojection_rmse_px']['A']['rmse'])} px, B {_num(loc['reprojection_rmse_px']['B']['rmse'])} px.</p>")
    return parts


def _html_detection(det: dict | None) -> list[str]:
    """The detection table: the boxes the pipeline outputs (refined by the edge fit), per class,
    and the network's own boxes when the detections carry them."""
    if not (det and "map50" in det):
        return []
    net = det.get("network_boxes")
    net_row = (f"<tr><td>all, the network's own boxes (before the edge fit)</td><td>{_num(net.get('mAP50'))}</td>"
               f"<td>{_num(net.get('mAP50_95'))}</td></tr>" if net else "")
    return ["<h2>Detection (test split)</h2><table><tr><th>class</th><th>mAP50</th><th>mAP50:95</th></tr>"
            + f"<tr><td>all</td><td>{_num(det['map50'])}</td><td>{_num(det['map50_95'])}</td></tr>"
            + "".join(f"<tr><td>{k}</td><td>{_num(v.get('map50'))}</td><td>{_num(v.get('map50_95'))}</td></tr>" for k, v in det.get("per_class", {}).items())
            + net_row + "</table>"]


def _html_camera_envelope(env: dict | None) -> list[str]:
    if env is None:
        return []
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    png = plot_envelope(plt, env, _fig_png)
    return html_envelope(env, _img(png, "tolerance envelope: gated statistics over principal point offset and k1"))


def _html_figures(figs: dict[str, str], worst: list[tuple[str, str]]) -> list[str]:
    parts = ["<h2>Plots</h2>"]
    for title, b64 in figs.items():
        parts.append(f"<section class='plot'><h3>{html.escape(title)}</h3>{_img(b64, title)}</section>")
    parts.append("<h2>Worst frames</h2><p class='note'>Green circles: true marker centres; magenta crosses: detections; "
                 "yellow dots: every marker reprojected with the estimated poses and focal length.</p>")
    for cap, b64 in worst:
        parts.append(f"<figure>{_img(b64, cap)}<figcaption>{html.escape(cap)}</figcaption></figure>")
    return parts


def _html_provenance(provenance: dict) -> str:
    return "<h2>Provenance</h2><table>" + "".join(
        f"<tr><td>{html.escape(k)}</td><td><code>{html.escape(json.dumps(v) if not isinstance(v, str) else v)}</code></td></tr>"
        for k, v in provenance.items()) + "</table>"


def _html_document(parts: list[str]) -> str:
    css = ("body{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em;color:#222}"
           "table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #bbb;padding:2px 8px;font-size:90%}"
           "tr.pass td:last-child,.pass{color:#17702a}tr.fail td:last-child,.fail{color:#b00020}"
           "tr.undecided td:last-child,.undecided{color:#a05a00}"
           ".note{color:#555;font-size:85%}img{max-width:100%}figure{display:inline-block;margin:4px;max-width:540px}"
           # print (and report --pdf): A4; a heading stays with what follows it, a plot, figure or
           # table row is never cut across pages, a plot fits a third of a page
           "@page{size:A4;margin:14mm}"
           "@media print{body{max-width:none;padding:0;font-size:10pt}h1,h2,h3,h2+.note,h3+.note{break-after:avoid-page}"
           ".plot,figure,tr,img{break-inside:avoid-page}.plot img{max-height:95mm;width:auto}"
           "figure{max-width:48%}figure img{max-height:70mm;width:auto}}")
    return (f"<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'><title>dockfactory acceptance report</title>"
            f"<style>{css}</style></head><body>\n" + "\n".join(parts) + "\n</body></html>\n")


def _ungated_line(acc: dict, fmt: str) -> str:
    """What the verdict does not cover (reported, not gated); empty when the spec gates all."""
    ungated = acc.get("ungated") or []
    if not ungated:
        return ""
    text = "Not gated (reported only): " + ", ".join(ungated) + "."
    return f"<p class='note'>{html.escape(text)}</p>" if fmt == "html" else text + "\n"


def _summary_markdown(verdict: str, acc: dict) -> str:
    conf = acc.get("confidence", 0.95)
    md = [f"## dockfactory acceptance: **{verdict}**", "", _rule_text(acc), "",
          f"| criterion | ours | {conf:.0%} bounds | threshold | paper | result |", "|---|---|---|---|---|---|"]
    for c in acc["criteria"]:
        bounds = f"{_num(c['lower'])} - {_num(c['upper'])}" if c.get("upper") is not None else "-"
        note = f" ({c['note']})" if c.get("note") else ""
        md.append(f"| {c['name']} | {_num(c['value'])} {c['unit']}{note} | {bounds} | {_num(c['threshold'])} {c['unit']} | "
                  f"{_num(c.get('paper'))} | {_decision(c)} |")
    ungated = _ungated_line(acc, "md")
    return "\n".join(md) + "\n" + (f"\n{ungated}" if ungated else "")


def sign_off(eval_dir: Path, signers: dict | None) -> dict:
    """The report's identity and signature block: ``report_id`` (the first 16 hex digits of the
    sha256 over the evaluation's metrics.json, frames.csv and provenance.json: the same inputs give
    the same id), the UTC date it was built, and who prepared and approved it (``signers``:
    "prepared_by", "approved_by"; blank lines to sign by hand when not given)."""
    digest = hashlib.sha256()
    for name in ("metrics.json", "frames.csv", "provenance.json"):
        path = eval_dir / name
        digest.update(name.encode() + b"\0" + (path.read_bytes() if path.is_file() else b""))
    signers = signers or {}
    return {"report_id": digest.hexdigest()[:16], "date": report_date()[:16].replace("T", " ") + " UTC",
            "prepared_by": signers.get("prepared_by") or "", "approved_by": signers.get("approved_by") or ""}


def _html_sign_off(sign: dict) -> str:
    def field(name, value):
        return f"<td>{html.escape(value) if value else '&nbsp;' * 40}</td>"
    return ("<table class='signoff'><tr><th>report id</th><td><code>" + sign["report_id"] + "</code></td>"
            f"<th>date</th><td>{html.escape(sign['date'])}</td></tr><tr><th>prepared by</th>"
            + field("prepared", sign["prepared_by"]) + "<th>approved by</th>" + field("approved", sign["approved_by"])
            + "</tr></table><p class='note'>The ground truth of every figure below is synthetic: rendered scenes with "
              "exact labels (see \"What was simulated\"). A real camera's figures differ by what the simulation "
              "leaves out.</p>")


def build_report(eval_dir, out_html, commands: list[str] | None = None, signers: dict | None = None) -> dict:
    """Build the report of an evaluation folder: ``out_html`` and report.json, report.md beside it.

    Parameters
    ----------
    eval_dir : path
        The evaluation folder (metrics.json, frames.csv, provenance.json of ``dockfactory evaluate``).
    out_html : path
        The HTML file to write.
    commands : list of str, optional
        The commands that made the inputs (the provenance's own when None).
    signers : dict, optional
        The sign-off block's names: see :func:`sign_off`.

    Returns
    -------
    dict
        The summary written to report.json (verdict, criteria, provenance, headline figures).

    Raises
    ------
    DatasetError
        When the folder, a file of it or an input it names is missing, broken or of another shape.
    """
    eval_dir = Path(eval_dir)
    if not eval_dir.is_dir():
        raise DatasetError(f"{eval_dir}: no such evaluation folder (run dockfactory evaluate first)")
    metrics_path = eval_dir / "metrics.json"
    metrics = _read_metrics(metrics_path)
    acc = metrics["acceptance"]
    verdict = checked_verdict(acc, metrics_path)
    rows = read_rows(eval_dir)
    check_rows_match(rows, metrics, eval_dir / "frames.csv")
    prov_path = eval_dir / "provenance.json"
    prov = read_json_file(prov_path, "provenance") if prov_path.exists() else {}
    check_schema(prov, PROVENANCE_SCHEMA, prov_path)
    dataset_root = input_path(metrics["dataset"]["root"], eval_dir, f"{metrics_path}: dataset.root")
    poses, detections = _read_observations(metrics, metrics_path, prov, prov_path, eval_dir)
    provenance = _report_provenance(metrics, prov, commands)
    figs = plots(rows, metrics, (metrics.get("detection") or {}).get("pr_curves"))
    worst = gallery(dataset_root, rows, poses, detections)
    sign = sign_off(eval_dir, signers)
    parts = _html_parts(metrics, rows, verdict, sign) + _html_figures(figs, worst) + [_html_provenance(provenance)]
    write_text_atomic(out_html, _html_document(parts))
    return write_summary(out_html, metrics, verdict, provenance, sign)


def _read_metrics(metrics_path: Path) -> dict:
    """metrics.json, checked against METRICS_SCHEMA (its PR curves and simulated sensors too)."""
    metrics = read_json_file(metrics_path, "metrics")
    check_schema(metrics, METRICS_SCHEMA, metrics_path)
    for name, curve in ((metrics.get("detection") or {}).get("pr_curves") or {}).items():
        if len(curve) != 2 or len(curve[0]) != len(curve[1]):
            raise DatasetError(f"{metrics_path}: detection.pr_curves.{name}: expected [recall list, precision list] "
                               "of equal length")
    for i, unit in enumerate((metrics.get("simulated_cameras") or {}).get("units", [])):
        check_schema(unit["sensor"], sensor_schema(unit["sensor"]), metrics_path, f"simulated_cameras.units[{i}].sensor")
    return metrics


def _read_observations(metrics: dict, metrics_path: Path, prov: dict, prov_path: Path, eval_dir: Path):
    """(poses, detections or None) the evaluation names, validated; errors name the file that named them."""
    poses = _input_json(metrics["poses"]["path"], eval_dir, "poses", f"{metrics_path}: poses.path")
    try:
        validate_poses(poses, metrics["poses"]["path"])
    except DatasetError as exc:
        raise DatasetError(f"{metrics_path}: poses.path: {exc}") from None
    det_path = prov.get("detections")
    detections = _input_json(det_path, eval_dir, "detections", f"{prov_path}: detections") if det_path else None
    if detections is not None:
        try:
            validate_detections(detections, det_path)
        except DatasetError as exc:
            raise DatasetError(f"{prov_path}: detections: {exc}") from None
    return poses, detections


def _html_parts(metrics: dict, rows: list[dict], verdict: str, sign: dict) -> list[str]:
    """The report's sections before its figures, in order."""
    acc = metrics["acceptance"]
    return (_html_verdict(metrics, acc, verdict) + [_html_sign_off(sign)] + _html_localization(metrics)
            + html_budget(metrics) + _html_calibration(metrics, rows)
            + (html_model_check(metrics["model_check"]) if metrics.get("model_check") else [])
            + [_html_estimation(metrics["estimation"])] + _html_failures(metrics)
            + _html_detection(metrics.get("detection")) + _html_camera_envelope(metrics.get("camera_envelope"))
            + (html_camera_models(metrics["camera_models"]) if metrics.get("camera_models") else [])
            + (html_simulated_cameras(metrics["simulated_cameras"]) if metrics.get("simulated_cameras") else []))


def write_summary(out_html, metrics: dict, verdict: str, provenance: dict, sign: dict | None = None) -> dict:
    """report.json (the figures a dashboard reads) and report.md (the verdict in a few lines)
    beside ``out_html``; returns the summary."""
    acc = metrics["acceptance"]
    loc, est = metrics["localization"], metrics["estimation"]
    summary = {"verdict": verdict, "accepted": acc["accepted"], "criteria": acc["criteria"],
               "ungated": acc.get("ungated", []), "provenance": provenance,
               "localization_rmse": {c: loc["overall"][c]["rmse"] for c in COMPONENTS},
               "estimation_spread": {c: est["pooled"][c]["rmse"] for c in COMPONENTS},
               "crb_ratio": {c: v["ratio"] for c, v in loc["crb"].items()},
               "crb_structured_ratio": {c: v["ratio"] for c, v in (loc.get("crb_structured") or {}).items()},
               "centre_noise_used": (metrics.get("centre_noise") or {}).get("used"),
               "covariance_calibration": (loc.get("calibration") or {}).get("overall"),
               "decision_rule": acc.get("decision_rule"), "confidence": acc.get("confidence"), **(sign or {})}
    out_html = Path(out_html)
    write_json_atomic(out_html.with_suffix(".json"), json.loads(json.dumps(summary, default=float)))
    cams = metrics.get("simulated_cameras")
    simulated = (f"\nGround truth: rendered, not measured, through simulated cameras ({cams['statement']}; per unit: "
                 f"report.html, \"What was simulated\").\n" if cams else "")
    signed = (f"\nReport {sign['report_id']}, {sign['date']}; prepared by: {sign['prepared_by'] or '________'}; "
              f"approved by: {sign['approved_by'] or '________'}\n" if sign else "")
    check = metrics.get("model_check") or {}
    model = f"\n{model_check_sentence(check)}\n" if check.get("flagged") else ""
    write_text_atomic(out_html.with_suffix(".md"), _summary_markdown(verdict, acc) + simulated + model + signed
                      + markdown_honesty(metrics))
    return summary
