"""The shipped design card is what its fit writes from the committed sensor-bench results: the
card cannot drift from the code and inputs that made it (bench.design.design_fit, run in a
subprocess: it pins the label arithmetic of its own process)."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from dockfactory.core.resources import shipped_design_card

ROOT = Path(__file__).resolve().parents[2]
SHIPPED_FIT = ["--scenes", "a,b,d", "--sources", "joint_abd_48.json", "shortfall/white_abd_48.json", "joint_abd_48.json",
               "--ring-dark", "shortfall/dark_abd_48.json", "--jpeg95", "jpeg95_abd_48.json",
               "shortfall/white95_abd_48.json", "--sensor", "sensor_wells_abd_48.json",
               "--provisional", "ring_factor.white.none,ring_factor.white.rggb", "--white-jpeg-own-twin"]


def _fit(args, out: Path) -> dict:
    subprocess.run([sys.executable, "-m", "bench.design.design_fit", *args, "--card-out", str(out)],
                   cwd=ROOT, check=True, capture_output=True)
    return json.loads(out.read_text())


@pytest.mark.slow
def test_the_shipped_card_is_its_fit_of_the_committed_inputs(tmp_path):
    """Every figure of models/design_predictor.json equals the fit's (to the digit it is written
    with); without --white-jpeg-own-twin only the white Bayer JPEG figures differ (taken through the
    dark ring's JPEG factor of another bench), and they are larger: the option is what the card uses."""
    shipped = json.loads(shipped_design_card().read_text())
    assert _fit(SHIPPED_FIT, tmp_path / "card.json") == shipped
    assert shipped["provisional"] == ["ring_factor.white.none", "ring_factor.white.rggb"]
    mixed = _fit([a for a in SHIPPED_FIT if a != "--white-jpeg-own-twin"], tmp_path / "mixed.json")
    differ = {k for k in shipped if mixed.get(k) != shipped[k]}
    assert differ == {"jpeg_factor", "jpeg_factor_above", "fitted_on"}
    assert mixed["jpeg_factor"]["dark"] == shipped["jpeg_factor"]["dark"]
    assert mixed["jpeg_factor"]["white"]["none"] == shipped["jpeg_factor"]["white"]["none"]
    assert mixed["jpeg_factor"]["white"]["rggb"] > 1.3 * shipped["jpeg_factor"]["white"]["rggb"]
