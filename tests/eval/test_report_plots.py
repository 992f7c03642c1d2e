"""eval.report.document's error plots: every panel that shows an error draws its localization tolerance (a
quality engineer reads the errors against what is allowed, not against an axis of their own)."""
import matplotlib
import numpy as np
import pytest

from dockfactory.eval.report import document as report


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    matplotlib.pyplot.close("all")   # the figures the tests keep instead of encoding them

TOL = {"x": 5.0, "y": 4.0, "alpha": 0.1}


def _metrics():
    return {"acceptance": {"criteria": [{"block": "localization", "component": c, "statistic": "rmse",
                                         "threshold": t} for c, t in TOL.items()]}}


def _rows(n=12):
    rng = np.random.default_rng(0)
    return [{"split": "test", "ok": True, "condition": ("normal", "glare")[i % 2], "distance_mm": 1000 + 50 * i,
             "focal_true": 1500 + 20 * i, **{f"err_{c}": float(rng.normal(0, 0.1 * t)) for c, t in TOL.items()},
             **{f"crb_{c}": 0.1 * t for c, t in TOL.items()}} for i in range(n)]


@pytest.mark.parametrize("title", ["Error histograms (test split)", "X-Y error scatter", "Error per condition",
                                   "Error against camera distance and focal length"])
def test_every_error_panel_draws_the_tolerance(monkeypatch, title):
    figures = {}

    def keep(fig):
        figures[len(figures)] = fig
        return "png"

    monkeypatch.setattr(report, "_fig_png", keep)
    names = list(report.plots(_rows(), _metrics()))
    fig = figures[names.index(title)]
    red = report.TOLERANCE_STYLE["color"]
    for ax in fig.axes:
        drawn = [ln for ln in ax.get_lines() if ln.get_color() == red]
        assert drawn, f"{title}: a panel ({ax.get_ylabel() or ax.get_title()}) without its tolerance line"
        values = {abs(float(v)) for ln in drawn for v in (*ln.get_xdata(), *ln.get_ydata())}
        assert values & set(TOL.values()), (title, values)


@pytest.mark.parametrize("scale, drawn", [(0.1, False), (2.0, True)])
def test_the_bound_panels_name_a_tolerance_off_their_scale_and_draw_one_on_it(monkeypatch, scale, drawn):
    figures = []
    monkeypatch.setattr(report, "_fig_png", lambda fig: figures.append(fig) or "png")
    rows = _rows()
    for r in rows:
        for c, t in TOL.items():
            r[f"crb_{c}"] = scale * t
    names = list(report.plots(rows, _metrics()))
    fig = figures[names.index("Measured error against the Cramer-Rao bound")]
    red = report.TOLERANCE_STYLE["color"]
    for ax in fig.axes:
        lines = [ln for ln in ax.get_lines() if ln.get_color() == red]
        texts = [t.get_text() for t in ax.texts if "tolerance" in t.get_text()]
        assert (bool(lines), bool(texts)) == (drawn, not drawn), (scale, ax.get_xlabel())
