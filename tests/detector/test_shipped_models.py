"""Every weights file under models/ loads as data (``weights_only``), builds a detector, and carries
a noise card that is still its own: the card names the file's sha256 and the current centre
refinement's, so a retrained file or a changed refinement without a re-measured card fails here."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from dockfactory.core.io import sha256_file
from dockfactory.detector.infer import MarkerDetector
from dockfactory.detector.noise_card import NOISE_FORMAT, centre_noise_px, noise_card_path, refinement_sha256

MODELS = Path(__file__).resolve().parents[2] / "models"
WEIGHTS = sorted(MODELS.glob("*.pt"))


def test_the_folder_holds_the_default_and_the_alternatives():
    assert {"yolov5n_se_markers.pt", "yolov5s_se_markers.pt", "yolov5n_se_rings_markers.pt"} <= {p.name for p in WEIGHTS}


@pytest.mark.parametrize("weights", WEIGHTS, ids=lambda p: p.name)
def test_weights_load_as_data_and_name_their_dataset(weights):
    doc = torch.load(weights, weights_only=True, map_location="cpu")
    assert doc["format"] == "dockfactory.detector.weights/1"
    assert len(doc["dataset_version"]) == 16 and doc["model_config"]["num_classes"] == 2


@pytest.mark.parametrize("weights", WEIGHTS, ids=lambda p: p.name)
def test_noise_card_is_current(weights):
    card = json.loads(noise_card_path(weights).read_text())
    assert card["format"] == NOISE_FORMAT
    assert card["weights_sha256"] == sha256_file(weights)
    assert card["refinement_sha256"] == refinement_sha256()
    assert 0.005 < centre_noise_px(weights) < 0.3      # px per axis: a centre noise (the refinement's median error on converged renders is about 0.006 px), not a box noise


@pytest.mark.parametrize("weights", WEIGHTS, ids=lambda p: p.name)
def test_weights_find_a_drawn_marker(weights):
    """A red disc in a dark ring on grey, 16 px across: found as RedA within a pixel of its centre."""
    img = np.full((480, 640, 3), 150, np.uint8)
    yy, xx = np.mgrid[:480, :640]
    r = np.hypot(xx - 320.3, yy - 240.6)
    img[r <= 10] = (25, 25, 25)
    img[r <= 8] = (200, 20, 20)
    dets = [d for d in MarkerDetector(weights).detect(img) if d["score"] >= 0.25]
    assert dets, "nothing found"
    best = max(dets, key=lambda d: d["score"])
    assert best["class_id"] == 0
    assert np.hypot(best["center_px"][0] - 320.3, best["center_px"][1] - 240.6) < 1.0
