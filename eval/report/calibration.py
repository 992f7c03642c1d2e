"""The report's honesty sections: the centre noise the bounds use (metrics["centre_noise"], see
eval.centre_noise), measured error against the Cramer-Rao bound, and whether the solver's
covariance describes its error (metrics["localization"]["calibration"], see eval.uncertainty):
tables for the HTML report and its Markdown summary, and a QQ plot of z = error / reported std."""
from __future__ import annotations

import html
from statistics import NormalDist

import numpy as np

from dockfactory.core.names import COMPONENTS, UNITS
from dockfactory.eval.confidence import chi2_quantile

GATED = ("x", "y", "alpha")
RATIO_RANGE = (0.9, 1.3)      # measured / bound outside it gets a note
Z_RANGE = (0.85, 1.2)         # RMS z outside it gets a note (the target band)
WITHIN_RANGE = (0.92, 0.98)   # so does a fraction within 2 sigma outside this one
Z_CONFIDENCE = 0.95           # two-sided: the interval of RMS z that decides whether a note is a finding
QQ_LIMIT = 8.0                # |z| beyond it is drawn at the edge of the QQ plot

_NOISE = {"n": "int", "rms_px": "num?", "robust_px": "num?"}
CENTRE_NOISE_SCHEMA = {"used": {"name": "str", "value": "num", "n": "int", "source": "str",
                                "by_condition?": ("map", "num")},
                       "overall?": _NOISE, "by_condition?": ("map", _NOISE), "frames?": "int",
                       "outside_gate?": "int", "gate?": {"radius_fraction": "num"},
                       "structure?": {"source": "str", "reason?": "str", "use?": ("map", "int"),
                                      "folds?": ("list", {"frames": "int", "ids": ("list", "str"),
                                                          "moments": ("list", ("list", "num")), "shrinkage": "num",
                                                          "mean_abs_correlation": "num"})}}
_Z = {"n": "int", "rms_z": "num?", "within_2sigma": "num?", "robust_z?": "num?", "max_abs_z?": "num?"}
CALIBRATION_SCHEMA = {"overall": {c: _Z for c in COMPONENTS}, "by_condition": ("map", {c: _Z for c in COMPONENTS}),
                      "expected": {"rms_z": "num", "within_2sigma": "num"}, "without_std": "int"}


def _f(v, fmt: str) -> str:
    return "-" if v is None else format(v, fmt)


def used_sigma_text(metrics: dict) -> str:
    """One sentence: which centre noise the bounds and the oracle use (name, value, n)."""
    cn = metrics.get("centre_noise")
    if not cn:   # a metrics.json of an older evaluate
        return (f"centre noise {_f(metrics.get('centre_noise_px'), '.3g')} px per axis (older metrics file: "
                "not said how it was measured)")
    u = cn["used"]
    text = f"{u['name']} = {u['value']:.3g} px per axis over {u['n']} detections ({u['source']}"
    if cn.get("gate"):
        text += (f"; {cn.get('frames', 0)} solved frames, matched within {cn['gate']['radius_fraction']:g} x the "
                 f"marker's apparent radius, {cn.get('outside_gate', 0)} used markers without a detection there")
    text += ")"
    if u.get("by_condition"):
        text += "; each frame's bound uses its condition's RMS: " + ", ".join(
            f"{c} {v:.3g} px" for c, v in u["by_condition"].items())
    return text


def _ratio_text(v: dict) -> str:
    """The ratio, with its 95 % interval over the frames when the metrics hold one."""
    if v.get("ratio_low") is None or v.get("ratio_high") is None:
        return _f(v.get("ratio"), ".3g")
    return f"{_f(v['ratio'], '.3g')} ({v['ratio_low']:.2g}-{v['ratio_high']:.2g})"


def _outside(v: dict | None, side: int) -> bool:
    """The ratio lies below (side -1) or above (+1) RATIO_RANGE, beyond its own sampling interval
    when the metrics hold one (a ratio under 1 over a few frames is no finding)."""
    if not v or v.get("ratio") is None:
        return False
    if side < 0:
        return (v.get("ratio_high") if v.get("ratio_high") is not None else v["ratio"]) < RATIO_RANGE[0]
    return (v.get("ratio_low") if v.get("ratio_low") is not None else v["ratio"]) > RATIO_RANGE[1]


def _ratio_note(crb: dict, cn: dict | None, loc: dict | None = None) -> str:
    """The notes under the bound table: the disc model, the structure, and the ratios outside
    RATIO_RANGE beyond their sampling, each read against the bound under the centres' measured
    structure when ``loc`` holds one (eval.centre_structure), else the independent bound."""
    notes = [t for t in (disc_model_text(cn), structure_text(cn)) if t]
    structured = (loc or {}).get("crb_structured")
    if structured:
        return " ".join(notes + _structured_notes(crb, structured, loc.get("fit_structured") or {}))
    low = [c for c in GATED if _outside(crb.get(c), -1)]
    high = [c for c in GATED if _outside(crb.get(c), 1)]
    axis = ((cn or {}).get("overall") or {}).get("rms_axis_px")
    if low:
        model = ("the disc noise model" if (cn or {}).get("disc_model") else
                 "isotropic, independent centre noise of this size")
        notes.append(f"{', '.join(low)} below {RATIO_RANGE[0]} (its whole 95 % interval): smaller than the bound of {model}, so the "
                     "detector's noise is not that" + (f" (RMS x {axis[0]:.3g} px, y {axis[1]:.3g} px)" if axis else "") + ".")
    if high:
        notes.append(f"{', '.join(high)} above {RATIO_RANGE[1]} (its whole 95 % interval): the solver does not reach the bound.")
    return " ".join(notes)


def _structured_notes(crb: dict, structured: dict, fit: dict) -> list[str]:
    """Notes on the ratios when the bound under the measured structure is known."""
    notes = []
    explained = [c for c in GATED if _outside(crb.get(c), -1) and not _outside(structured.get(c), -1)]
    low = [c for c in GATED if _outside(structured.get(c), -1)]
    high = [c for c in GATED if _outside(fit.get(c), 1)]
    if explained:
        notes.append(f"{', '.join(explained)} below {RATIO_RANGE[0]} of the bound of independent centres but not of the "
                     "bound under their measured structure: the centres are not independent (each marker's own noise, "
                     "shared errors), not a solver beating a bound.")
    if low:
        notes.append(f"{', '.join(low)} below {RATIO_RANGE[0]} of the bound under the centres' measured structure (its "
                     "whole 95 % interval): the errors are smaller than any unbiased solver's under that noise; the noise "
                     "measured is not the test frames' (a finding to chase).")
    if high:
        notes.append(f"{', '.join(high)} above {RATIO_RANGE[1]} of the fit's expected RMSE under the measured structure "
                     "(its whole 95 % interval): the solver does not reach what its weighting gives under that noise at the "
                     "bound's scale (heavy tails the scale leaves out, or errors the centres do not carry).")
    return notes


def structure_text(cn: dict | None) -> str:
    """One sentence on the centres' measured structure (eval.centre_structure), or ""."""
    st = (cn or {}).get("structure")
    if not st:
        return ""
    if not st.get("folds"):
        return f"The centres' structure was not measured ({st.get('reason', 'no frames')}): the bound treats them as independent."
    folds = st["folds"]
    return (f"The centres' structure (each marker's own noise and the correlations between a frame's centres) was measured "
            f"on {st['source']} ({' and '.join(str(f['frames']) for f in folds)} frames; off-diagonal shrunk "
            f"{', '.join(format(f['shrinkage'], '.2f') for f in folds)}, mean |correlation| "
            f"{', '.join(format(f['mean_abs_correlation'], '.3f') for f in folds)}).")


def disc_model_text(cn: dict | None) -> str:
    """One sentence on the disc noise model behind the bound (eval.centre_noise_disc), or ""."""
    disc = ((cn or {}).get("disc_model") or {})
    overall = disc.get("overall") or {}
    if overall.get("fisher_px") is None:
        return ""
    return (f"Each centre's noise is shaped by its disc's image (solver.disc_noise) at the scale of the Fisher "
            f"information of the used centres: {overall['fisher_px']:.3g} px for a round "
            f"{disc['model']['reference_radius_px']:g} px disc (their RMS: {_f(overall.get('rms_px'), '.3g')} px; "
            "gross errors raise the RMS, not the bound).")


def html_centre_noise(metrics: dict) -> list[str]:
    """The centre noise used and its per-condition table (RMS and robust sigma)."""
    cn = metrics.get("centre_noise") or {}
    parts = [f"<p>Centre noise used by the bounds, the oracle and the camera sweeps: {html.escape(used_sigma_text(metrics))}.</p>"]
    if cn.get("overall"):
        rows = [("all", cn["overall"])] + list(cn.get("by_condition", {}).items())
        parts.append("<table><tr><th>condition</th><th>detections</th><th>RMS (px)</th><th>robust 1.4826 MAD (px)</th>"
                     "<th>RMS x / y (px)</th><th>mean x / y (px)</th></tr>" + "".join(
                         f"<tr><td>{html.escape(c)}</td><td>{s['n']}</td><td>{_f(s['rms_px'], '.3g')}</td>"
                         f"<td>{_f(s['robust_px'], '.3g')}</td><td>{_axes(s.get('rms_axis_px'))}</td>"
                         f"<td>{_axes(s.get('mean_px'))}</td></tr>" for c, s in rows) + "</table>")
    return parts


def _axes(v) -> str:
    return "-" if not v else f"{v[0]:.3g} / {v[1]:.3g}"


STRUCTURED_COLUMNS = (("crb_structured", "bound under the measured structure"),
                      ("fit_structured", "the fit's expected RMSE under it"))


def _bound_cells(loc: dict, c: str, sep: str) -> str:
    """The bound and ratio cells of component ``c``: independent, then the structured pair when measured."""
    cells = [_f(loc["crb"][c]["bound_rms"], ".4g"), _ratio_text(loc["crb"][c])]
    for key, _ in STRUCTURED_COLUMNS:
        if loc.get(key):
            v = loc[key].get(c) or {}
            cells += [_f(v.get("bound_rms"), ".4g"), _ratio_text(v) if v else "-"]
    return sep.join(cells)


def _bound_headers(loc: dict) -> list[str]:
    heads = ["bound, independent centres (RMS)", "ratio (95 % interval over the frames)"]
    for key, name in STRUCTURED_COLUMNS:
        if loc.get(key):
            heads += [name, "ratio"]
    return heads


def html_bound(metrics: dict) -> list[str]:
    loc = metrics["localization"]
    note = _ratio_note(loc["crb"], metrics.get("centre_noise"), loc)
    heads = "".join(f"<th>{h}</th>" for h in ["component", "measured RMSE"] + _bound_headers(loc))
    return ["<h3>Measured against the Cramer-Rao bound</h3><table><tr>" + heads + "</tr>"
            + "".join(f"<tr><td>{c}</td><td>{_f(v['measured_rmse'], '.4g')}</td><td>{_bound_cells(loc, c, '</td><td>')}"
                      "</td></tr>" for c, v in loc["crb"].items())
            + "</table><p class='note'>Bound from each frame's exact geometry (the markers its fit used) and the "
              f"centre noise above. {html.escape(note)}</p>"]


MIN_N_Z = 3   # fewer frames: "n too small" (one frame printed RMS z and "100 % within 2 sigma")


def _z_cells(s: dict) -> str:
    if (s.get("n") or 0) < MIN_N_Z:
        return f"<td>{s['n']}</td><td colspan='4' class='note'>n too small (fewer than {MIN_N_Z} frames)</td>"
    return (f"<td>{s['n']}</td><td>{_f(s['rms_z'], '.3g')}</td><td>{_f(s.get('robust_z'), '.3g')}</td>"
            f"<td>{_f(s['within_2sigma'], '.1%')}</td><td>{_f(s.get('max_abs_z'), '.3g')}</td>")


def html_calibration(metrics: dict, qq_img: str | None) -> list[str]:
    """Is the reported covariance honest: z statistics per component, overall, per condition and
    for the oracle; the QQ plot."""
    cal = metrics["localization"].get("calibration")
    if not cal:
        return []
    exp = cal["expected"]
    head = ("<tr><th>frames</th><th>component</th><th>n</th><th>RMS z</th><th>robust z</th><th>within 2 sigma</th>"
            "<th>max |z|</th></tr>")
    rows = [f"<tr><td>all</td><td>{c}</td>{_z_cells(cal['overall'][c])}</tr>" for c in COMPONENTS]
    rows += [f"<tr><td>{html.escape(k)}</td><td>{c}</td>{_z_cells(b[c])}</tr>"
             for k, b in cal["by_condition"].items() for c in GATED]
    o_cal = ((metrics.get("oracle") or {}).get("localization") or {}).get("calibration")
    if o_cal:
        rows += [f"<tr><td>oracle</td><td>{c}</td>{_z_cells(o_cal['overall'][c])}</tr>" for c in GATED]
    parts = ["<h2>Is the reported covariance honest?</h2>",
             f"<p>z = (estimate - truth) / std, the std from each pose record's covariance (same units: mm, deg). "
             f"A covariance that describes the error gives RMS z {exp['rms_z']:g} and {exp['within_2sigma']:.1%} of "
             f"frames within 2 sigma; RMS z above 1 means the reported std is too small. Solved frames without a "
             f"usable std: {cal['without_std']}. The oracle rows (exact centroids plus noise the solver is told) "
             "check the computation itself.</p>", f"<table>{head}{''.join(rows)}</table>",
             f"<p><b>{html.escape(calibration_note(cal))}</b></p>" if calibration_note(cal) else ""]
    if qq_img:
        parts.append(qq_img)
    return parts


def rms_z_interval(rms_z: float, n: int) -> tuple[float, float] | None:
    """(low, high): the two-sided ``Z_CONFIDENCE`` interval of the scale s of z ~ N(0, s^2) (s = 1
    for a calibrated covariance) from the RMS ``rms_z`` of ``n`` scores (chi-square with n degrees
    of freedom); None without scores. It holds 1 whenever the RMS reads within the range a
    calibrated covariance gives: over 9 frames 0.55-1.45, over 48 frames 0.80-1.20."""
    if not n or rms_z is None:
        return None
    ss, tail = n * rms_z ** 2, (1 - Z_CONFIDENCE) / 2
    return float(np.sqrt(ss / chi2_quantile(1 - tail, n))), float(np.sqrt(ss / chi2_quantile(tail, n)))


def calibration_note(cal: dict) -> str:
    """Which gated components' reported std is too small or too large (empty when none). A
    component outside the target band (``Z_RANGE``, ``WITHIN_RANGE``) is a finding only when the
    interval of its RMS z (:func:`rms_z_interval`) excludes 1 on that side; otherwise the note says
    that its frames are too few to tell, so that a 9-frame statistic is not read as a defect."""
    found = {"small": [], "large": [], "undecided": []}
    for c in GATED:
        s = cal["overall"][c]
        if s["rms_z"] is None or s["within_2sigma"] is None:
            continue
        side = ("small" if s["rms_z"] > Z_RANGE[1] or s["within_2sigma"] < WITHIN_RANGE[0] else
                "large" if s["rms_z"] < Z_RANGE[0] or s["within_2sigma"] > WITHIN_RANGE[1] else None)
        if side is None:
            continue
        lo, hi = rms_z_interval(s["rms_z"], s["n"])
        shown = (f"{c} (RMS z {s['rms_z']:.2f}, {Z_CONFIDENCE:.0%} interval {lo:.2f}-{hi:.2f} over {s['n']} "
                 f"frames, {s['within_2sigma']:.0%} within 2 sigma)")
        proven = lo > 1 if side == "small" else hi < 1
        found[side if proven else "undecided"].append(shown)
    texts = {"small": "Reported std too small (a gate on it accepts too much): ",
             "large": "Reported std too large (conservative): ",
             "undecided": "Outside the target band, but too few frames to tell from a calibrated covariance: "}
    return " ".join(texts[k] + ", ".join(v) + "." for k, v in found.items() if v)


def plot_qq(plt, rows: list[dict], fig_png) -> str | None:
    """QQ plot of z against standard normal quantiles for X, Y, alpha (None without z)."""
    test = [r for r in rows if r["split"] == "test" and r["ok"]]
    if not any(r.get("z_x") is not None for r in test):
        return None
    fig, axes = plt.subplots(1, 3, figsize=(11, 3.6))
    for ax, c in zip(axes, GATED):
        z = np.sort([r[f"z_{c}"] for r in test if r.get(f"z_{c}") is not None])
        if z.size == 0:
            continue
        q = np.array([NormalDist().inv_cdf((i + 0.5) / z.size) for i in range(z.size)])
        lim = max(3.0, min(QQ_LIMIT, float(np.abs(np.r_[z, q]).max()) * 1.05))
        ax.scatter(q, np.clip(z, -lim, lim), s=10, c="#4477aa")
        ax.plot([-lim, lim], [-lim, lim], "k--", lw=0.8, label="calibrated (z ~ N(0, 1))")
        for y in (-2, 2):
            ax.axhline(y, color="#999", lw=0.6, ls=":")
        beyond = int(np.sum(np.abs(z) > lim))
        ax.set_ylim(-lim, lim)
        ax.set_title(f"{c}: RMS z {np.sqrt(np.mean(z ** 2)):.2f}, {np.mean(np.abs(z) <= 2):.0%} within 2 sigma"
                     + (f" ({beyond} clipped)" if beyond else ""), fontsize=9)
        ax.set_xlabel("standard normal quantile")
        ax.set_ylabel(f"z of {c} (sorted)")
        ax.legend(fontsize=7)
    fig.tight_layout()
    return fig_png(fig)


def markdown_honesty(metrics: dict) -> str:
    """The centre noise used, measured / bound and the z table, for report.md."""
    loc = metrics["localization"]
    md = ["", f"Centre noise used: {used_sigma_text(metrics)}.", "",
          "| " + " | ".join(["component", "measured RMSE"] + _bound_headers(loc)) + " |",
          "|" + "---|" * (2 + len(_bound_headers(loc)))]
    md += [f"| {c} ({UNITS[c]}) | {_f(v['measured_rmse'], '.4g')} | {_bound_cells(loc, c, ' | ')} |"
           for c, v in loc["crb"].items() if c in GATED]
    note = _ratio_note(loc["crb"], metrics.get("centre_noise"), loc)
    if note:
        md += ["", note]
    cal = loc.get("calibration")
    if cal:
        md += ["", f"Covariance calibration (z = error / reported std; calibrated: RMS z 1, "
               f"{cal['expected']['within_2sigma']:.1%} within 2 sigma):", "",
               "| frames | component | n | RMS z | within 2 sigma |", "|---|---|---|---|---|"]
        scopes = [("all", cal["overall"])] + list(cal["by_condition"].items())
        md += [f"| {k} | {c} | {b[c]['n']} | {_f(b[c]['rms_z'], '.3g')} | {_f(b[c]['within_2sigma'], '.1%')} |"
               for k, b in scopes for c in GATED]
        if calibration_note(cal):
            md += ["", calibration_note(cal)]
    return "\n".join(md) + "\n"
