"""Names and defaults that every layer shares, each defined once and imported where used.

- Splits of a dataset.
- Sections and detector classes: class id k is section ``SECTIONS[k]``, named ``CLASS_NAMES[k]``,
  whose marker colour is strongest in RGB channel ``CLASS_CHANNELS[k]`` (red on A, blue on B).
- Pose components of ``d_from_b``: ``POSE_NAMES`` (the keys of every pose dict a tool writes),
  the short ``COMPONENTS`` of acceptance specs and reports, and their units.
- Thresholds shared by several stages: the detector score a detection needs to be used, the NMS
  IoU, the chroma a marker needs to be legible.
"""
from __future__ import annotations

SECTIONS = ("A", "B")
CLASS_NAMES = ("RedA", "BlueB")       # detector class ids 0 and 1
CLASS_CHANNELS = (0, 2)               # RGB channel of each class's colour: RedA -> R, BlueB -> B

SPLITS = ("train", "val", "test", "repeat")   # a dataset's splits; repeat = the repeatability captures

COMPONENTS = ("x", "y", "z", "alpha", "beta", "gamma")
UNITS = {"x": "mm", "y": "mm", "z": "mm", "alpha": "deg", "beta": "deg", "gamma": "deg"}
POSE_KEYS = {c: f"{c}_{UNITS[c]}" for c in COMPONENTS}     # "x" -> "x_mm", "alpha" -> "alpha_deg"
POSE_NAMES = tuple(POSE_KEYS[c] for c in COMPONENTS)       # x_mm, y_mm, z_mm, alpha_deg, ...

MIN_SCORE = 0.25     # detections below this score are not used (detect, solve, evaluate, recall)
NMS_IOU = 0.45       # non-maximum suppression IoU of the detector
MIN_CHROMA = 0.03    # a marker whose colour is washed out below this chroma is not legible
MARKER_CLASS_AOV = "marker_class"   # the render's colour AOV of marker coverage: R disc, G ring (blender_scenes.coverage)
