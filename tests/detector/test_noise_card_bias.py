"""detector.noise_card.centre_bias_px: the detector bias measure's uncertainty budget uses, the
detection-weighted mean of the card's per-condition mean offsets; None when not measured."""
import json
import shutil

import pytest

from dockfactory.core.resources import shipped_weights
from dockfactory.detector.noise_card import centre_bias_px, noise_card_path


def test_the_shipped_cards_bias_is_the_weighted_mean_of_its_conditions():
    card = json.loads(noise_card_path(shipped_weights()).read_text())
    per = card["by_condition"].values()
    n = sum(v["n"] for v in per)
    want = tuple(sum(v["n"] * v["mean_px"][k] for v in per) / n for k in (0, 1))
    assert centre_bias_px(shipped_weights()) == pytest.approx(want, rel=1e-12)
    assert all(abs(b) < 0.05 for b in want)   # hundredths of a pixel: the edge fit's residual bias


def test_no_card_or_no_means_is_none(tmp_path):
    w = tmp_path / "w.pt"
    shutil.copy(shipped_weights(), w)
    assert centre_bias_px(w) is None                        # no card next to the weights
    card = json.loads(noise_card_path(shipped_weights()).read_text())
    card["by_condition"] = {c: {**v, "mean_px": None} for c, v in card["by_condition"].items()}
    noise_card_path(w).write_text(json.dumps(card))
    assert centre_bias_px(w) is None                        # the card measured no offset
    card["by_condition"] = {"normal": {"n": 3, "mean_px": [0.1, "x"]}}
    noise_card_path(w).write_text(json.dumps(card))
    assert centre_bias_px(w) is None
