"""The noise prior a solve is given (solver.refine.scale_with_prior): the shipped weights' noise card
states its robust core, a dataset solve reads it from the detections file and each frame's camera
class scales it by the class's factor (eval.camera_classes), as the class scales the gate's noise."""
from __future__ import annotations

import json

import pytest

from dockfactory.core.resources import shipped_weights
from dockfactory.detector.noise_card import card_figures, noise_card_path
from dockfactory.eval.camera_classes import CAMERA_CLASS_FACTORS
from dockfactory.eval.solve_frames import _dataset_options, class_options
from dockfactory.generator.datasets.reader import Dataset


def test_the_shipped_card_states_its_core():
    card = card_figures(shipped_weights())
    doc = json.loads(noise_card_path(shipped_weights()).read_text())
    assert card.core_px == pytest.approx(doc["robust_px"]) and 0 < card.core_px < card.centre_noise_px


@pytest.mark.parametrize("cls", ["three-chip", "bayer", "jpeg", "bayer-jpeg"])
def test_a_dataset_solve_takes_the_detections_core_at_the_class_s_factor(painted_source, cls):
    ds = Dataset.open(painted_source, full=False)
    dets = {"centre_noise_px": 0.02, "centre_noise_core_px": 0.007, "frames": {}}
    options = _dataset_options(ds, dets, None, None, False, None)
    assert options.refine.noise_prior_px == 0.007 and options.refine.sigma_floor_px == 0.02
    frame_options, factor = class_options(options, [cls], True)
    assert factor == CAMERA_CLASS_FACTORS[cls]
    assert frame_options.refine.noise_prior_px == pytest.approx(0.007 * factor)
    assert class_options(options, [cls], None)[0].refine.noise_prior_px == 0.007     # the oracle: no class
    older = _dataset_options(ds, {"centre_noise_px": 0.02, "frames": {}}, None, None, False, None)
    assert older.refine.noise_prior_px is None                                        # an older detections file


def test_measure_gives_an_image_its_class_s_prior():
    from types import SimpleNamespace

    from dockfactory.measure.images import class_docking_options
    detector = SimpleNamespace(centre_noise_px=0.02, section_shift_px=(0.002, 0.002), noise_core_px=0.007)
    for cls, factor in CAMERA_CLASS_FACTORS.items():
        options = class_docking_options(detector, None, cls)
        assert options.refine.noise_prior_px == pytest.approx(0.007 * factor) and options.refine.sigma_floor_px == 0.02
    none = class_docking_options(SimpleNamespace(centre_noise_px=None, section_shift_px=None, noise_core_px=None),
                                 None, "bayer")
    assert none.refine.noise_prior_px is None
