"""Frames without a pose in the design predictor: a camera class that leaves a share of honest
frames without a pose (the card's ``no_pose_rate``) cannot pass a block all of whose frames must
be posed; the card's table is read by format and quality, checked in one line, and measured from
the class bench's rows."""
from __future__ import annotations

import math

import numpy as np
import pytest

from bench.design.no_pose_rates import card_table, effect_class, pooled_rates
from dockfactory.core.config import load_config
from dockfactory.core.errors import DockfactoryError
from design_cards import card_with
from dockfactory.core.resources import resolve_config
from dockfactory.eval.acceptance import load_acceptance
from dockfactory.eval.design_rank import all_posed_probability, design_row
from dockfactory.eval.design_space import Camera, Design, DesignSpace, Lens

RATES = {"png": {"none": 0.0, "rggb": 0.002}, "jpeg90": {"none": 0.03, "rggb": 0.2}, "jpeg95": {"none": 0.01, "rggb": 0.1}}


def _card(tmp_path, table):
    return card_with(tmp_path, "no_pose_rate", table)


def _design(cfa: str, fmt: str) -> Design:
    return Design(Camera("cam", 1440, 1080, 3.45, cfa, "imx273"), Lens(8.0), (1300.0, 2000.0), 20.0, "dark", 7, fmt)


@pytest.mark.parametrize("fmt, cfa, rate", [("png", "rggb", 0.002), ("jpeg90", "none", 0.03), ("jpeg93", "rggb", 0.2),
                                            ("jpeg95", "none", 0.01), ("jpeg100", "rggb", 0.1)])
def test_the_card_gives_the_rate_of_the_highest_quality_at_or_below_the_design_s(tmp_path, fmt, cfa, rate):
    card = _card(tmp_path, RATES)
    got, key = card.no_pose_rate_of(_design(cfa, fmt))
    assert got == rate and key.startswith("no_pose_rate.")


def test_without_the_table_no_frame_is_predicted_without_a_pose(tmp_path):
    assert _card(tmp_path, None).no_pose_rate_of(_design("rggb", "jpeg90")) == (0.0, "")
    only95 = _card(tmp_path, {"jpeg95": {"none": 0.1, "rggb": 0.1}})
    assert only95.no_pose_rate_of(_design("none", "jpeg90")) == (0.0, "")
    assert only95.no_pose_rate_of(_design("rggb", "png")) == (0.0, "")


@pytest.mark.parametrize("table, needle", [
    ({"png": {"none": 1.0, "rggb": 0.0}}, "no_pose_rate.png.none: expected a share in [0, 1)"),
    ({"png": {"none": -0.1, "rggb": 0.0}}, "no_pose_rate.png.none: expected a non-negative number"),
    ({"tiff": {"none": 0.0, "rggb": 0.0}}, "no_pose_rate.tiff: expected 'png' or 'jpegQ'"),
    ({"jpeg90": {"none": 0.1}}, "no_pose_rate.jpeg90: expected a table of none, rggb"),
    ([0.1], "no_pose_rate: expected a table of png / jpegQ"),
])
def test_a_bad_no_pose_table_is_one_line(tmp_path, table, needle):
    with pytest.raises(DockfactoryError) as exc:
        _card(tmp_path, table)
    assert needle in str(exc.value) and "\n" not in str(exc.value)


def test_all_posed_is_the_binomial_chance_of_no_refusal():
    rng = np.random.default_rng(0)
    sims = (rng.random((200_000, 48)) < 0.03).any(axis=1)
    assert all_posed_probability(0.03, 48) == pytest.approx(1 - sims.mean(), abs=0.005)
    assert all_posed_probability(0.0, 48) == 1.0


def _row(card, fmt: str):
    cfg = load_config(resolve_config("quick"))
    spec = load_acceptance(resolve_config("acceptance"))
    space = DesignSpace("space.toml", resolve_config("quick"), None, 48, (0, 0), 48, 0, 0.0, (), (), {})
    return design_row(_design("none", fmt), space, cfg, spec, card)


def test_a_design_s_pass_chance_is_its_pose_chance_times_every_frame_posed(tmp_path):
    """The same JPEG design under a card without and with a 3 % share of frames without a pose:
    P(accept) and P(localization) fall by 0.97^48, P(reject) rises to 1 - 0.97^48 (1 - P(reject
    of the poses)), the RMSE predicted is unchanged."""
    without, with_rate = _row(_card(tmp_path, None), "jpeg90"), _row(_card(tmp_path, RATES), "jpeg90")
    q = 0.97 ** 48
    assert with_rate["predicted_rmse"] == without["predicted_rmse"]
    assert with_rate["p_accept"] == pytest.approx(without["p_accept"] * q, rel=1e-12)
    assert with_rate["p_localization"] == pytest.approx(without["p_localization"] * q, rel=1e-12)
    assert 1 - with_rate["p_reject"] == pytest.approx((1 - without["p_reject"]) * q, rel=1e-12)
    assert with_rate["no_pose"]["rate_per_frame"] == 0.03 and without["no_pose"]["rate_per_frame"] == 0.0
    assert math.isclose(with_rate["no_pose"]["p_all_test_posed"], q)


def test_the_rates_pool_the_honest_rows_per_class_and_format():
    tables = [{"dataset": d, "effect": e, "fault": f, "frames": 48, "ok": ok} for d, e, f, ok in [
        ("a", "three-chip", "as is", 48), ("b", "three-chip", "as is", 47), ("a", "bayer-vng", "as is", 46),
        ("a", "bayer-bilinear", "as is", 48), ("a", "three-chip-jpeg95", "as is", 45), ("a", "bayer-jpeg95", "as is", 40),
        ("a", "three-chip", "cropped 160/120 px", 0), ("a", "blur1.2", "as is", 10)]]
    rates = pooled_rates(tables)
    assert set(rates) == {("png", "none"), ("png", "rggb"), ("jpeg95", "none"), ("jpeg95", "rggb")}
    assert rates[("png", "none")]["rate"] == pytest.approx(1 / 96) and rates[("png", "rggb")]["rate"] == pytest.approx(2 / 96)
    assert rates[("png", "none")]["per_scene"] == {"a": 0.0, "b": pytest.approx(1 / 48)}
    lo, hi = rates[("jpeg95", "rggb")]["wilson95"]
    assert lo < 8 / 48 < hi
    assert card_table(rates) == {"png": {"none": 0.0104, "rggb": 0.0208}, "jpeg95": {"none": 0.0625, "rggb": 0.1667}}
    assert effect_class("sampling-rggb") is None and effect_class("three-chip-jpeg90") == ("jpeg90", "none")
