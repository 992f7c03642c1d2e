"""The Cramer-Rao ratio carries what its frames can show: measured RMSE over n frames has a
chi-square spread (n degrees of freedom), so the ratio's 95 % interval is printed beside it and
a ratio is called below (or above) the bound only when its whole interval is. A ratio of 0.8 over
9 frames (the demo's Y) is within the spread; 0.5 over 400 frames is a finding."""
import math

import pytest

from dockfactory.eval.acceptance import COMPONENTS
from dockfactory.eval.confidence import chi2_quantile
from dockfactory.eval.evaluate import bound_ratios
from dockfactory.eval.report.calibration import _ratio_note, _ratio_text


def _crb(rmse: float, n: int) -> dict:
    rows = [{f"crb_{c}": 1.0 for c in COMPONENTS} for _ in range(n)]
    overall = {c: {"rmse": rmse, "n": n} for c in COMPONENTS}
    return bound_ratios(rows, overall, "crb")


def test_the_interval_is_the_chi_square_spread_of_the_rmse():
    v = _crb(0.8, 9)["y"]
    assert v["ratio"] == pytest.approx(0.8)
    assert v["ratio_low"] == pytest.approx(math.sqrt(9 * 0.64 / chi2_quantile(0.975, 9)), rel=1e-9)
    assert v["ratio_high"] == pytest.approx(math.sqrt(9 * 0.64 / chi2_quantile(0.025, 9)), rel=1e-9)
    assert v["ratio_low"] == pytest.approx(0.550, abs=0.005) and v["ratio_high"] == pytest.approx(1.46, abs=0.01)
    assert _ratio_text(v) == "0.8 (0.55-1.5)"


def test_a_ratio_is_a_finding_only_beyond_its_interval():
    assert "below" not in _ratio_note(_crb(0.8, 9), None)
    assert "x, y, alpha below 0.9" in _ratio_note(_crb(0.5, 400), None)
    assert "above 1.3" not in _ratio_note(_crb(1.5, 9), None)          # 1.5 over 9 frames: 1.03-2.7
    assert "x, y, alpha above 1.3" in _ratio_note(_crb(1.6, 400), None)


def test_older_metrics_without_the_interval_still_read():
    old = {c: {"bound_rms": 1.0, "measured_rmse": 0.5, "ratio": 0.5} for c in COMPONENTS}
    assert _ratio_text(old["x"]) == "0.5"
    assert "below 0.9" in _ratio_note(old, None)


def _ratios(rmse: float, n: int, bound: float, prefix: str) -> dict:
    rows = [{f"{prefix}_{c}": bound for c in COMPONENTS} for _ in range(n)]
    return bound_ratios(rows, {c: {"rmse": rmse, "n": n} for c in COMPONENTS}, prefix)


def test_with_the_measured_structure_the_notes_read_against_it():
    """Below the independent bound but not below the bound under the measured structure is the
    centres' dependence, not a finding; below that one too is; above the fit's expected RMSE under
    it is the solver's shortfall."""
    crb = _crb(0.7, 400)
    explained = {"crb_structured": _ratios(0.7, 400, 0.7, "crb_structured"),
                 "fit_structured": _ratios(0.7, 400, 0.75, "fit_structured")}
    note = _ratio_note(crb, None, explained)
    assert "x, y, alpha below 0.9 of the bound of independent centres but not of the bound under" in note
    assert "smaller than any unbiased solver's" not in note and "does not reach" not in note
    low = {"crb_structured": _ratios(0.7, 400, 1.0, "crb_structured"),
           "fit_structured": _ratios(0.7, 400, 1.0, "fit_structured")}
    assert "x, y, alpha below 0.9 of the bound under the centres' measured structure" in _ratio_note(crb, None, low)
    high = {"crb_structured": _ratios(0.7, 400, 0.4, "crb_structured"),
            "fit_structured": _ratios(0.7, 400, 0.5, "fit_structured")}
    assert "x, y, alpha above 1.3 of the fit's expected RMSE" in _ratio_note(crb, None, high)
