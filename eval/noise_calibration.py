"""Measure a detector's centre noise on a labelled split and write its noise card (the floor of
the solver's covariance, detector.noise_card): detect the split, solve it, and take the RMS per
axis of the centres the solver used against the exact image centroids (eval.centre_noise), and
the common offset of a section's centres in a frame (eval.section_shift).

Use a split the evaluation does not judge (val by default): the card then carries no
information about the test frames.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

from dockfactory.core.errors import DockfactoryError
from dockfactory.core.names import MIN_SCORE
from dockfactory.detector.noise_card import write_noise_card
from dockfactory.eval.centre_noise import centre_noise_block
from dockfactory.eval.section_shift import section_shift_block
from dockfactory.eval.simulated_cameras import dataset_camera
from dockfactory.eval.solve_frames import solve_dataset


def calibrate_noise_card(ds, weights, split: str = "val", min_score: float = MIN_SCORE,
                         progress: bool = False) -> dict:
    """Measure the centre noise of weights on labelled frames and write their noise card.

    Parameters
    ----------
    ds : Dataset
        The opened dataset; the detector is told each frame's camera (Bayer, JPEG).
    weights : str or Path
        The weights measured; the card is written beside them.
    split, min_score, progress : str, float, bool
        The split detected and solved, the detection score kept, a progress line.

    Returns
    -------
    dict
        What the card holds: ``card`` (its path), ``centre_noise_px`` (px per axis) and details.

    Raises
    ------
    DockfactoryError
        No frames in the split, or no solved frame with a matched centre (one line).
    """
    from dockfactory.detector.infer import detect_dataset  # torch
    if not ds.frames((split,)):
        raise DockfactoryError(f"{ds.root}: no frames in the {split} split to measure the centre noise on")
    with tempfile.TemporaryDirectory() as tmp:
        dets = detect_dataset(ds, weights, Path(tmp) / "dets.json", split=split, conf_threshold=min_score,
                              progress=progress, camera=dataset_camera(ds))
    poses = solve_dataset(ds, (split,), detections=dets, min_score=min_score)
    block = centre_noise_block(ds, poses, dets, min_score, splits=(split,))
    shift = section_shift_block(ds, poses, dets, min_score, splits=(split,))
    overall = block["overall"]
    if not overall["n"]:
        raise DockfactoryError(f"{ds.root}: no solved {split} frame with a matched centre: no noise to measure")
    details = {"axis_px": overall["rms_axis_px"], "robust_px": overall["robust_px"], "n": overall["n"],
               "outside_gate": block["outside_gate"],
               "measured_on": {"dataset": str(ds.root), "dataset_version": ds.version_id, "split": split,
                               "frames": block["frames"]},
               "method": block["method"], "by_condition": block["by_condition"],
               "section_shift_px": shift["shift_axis_px"], "section_shift": shift}
    card = write_noise_card(weights, overall["rms_px"], details)
    return {"card": str(card), "centre_noise_px": overall["rms_px"], **details}
