"""The label format (``dockfactory.label/1``: one ``labels/<frame_id>.json`` per frame) as a JSON
Schema (draft 2020-12), for users who read the labels with their own tools.

What it holds to: the keys a consumer needs (the frame's spec, image size and pixel convention,
the camera's intrinsics, distortion and pose, the pose of B in A, every marker with its centres,
boxes and visibility, the sections' masks' extents) with their types, units in the
descriptions and value ranges where they are fixed (sections, visibility codes, 4 x 4
transforms). Keys the factory records for itself (``sampled``: the scene's random draws;
``derived``; optional blocks a config turns on, such as ``motion``) are objects whose contents
are not fixed by the schema: they may grow without a new format. ``dockfactory schema labels``
prints it; tests validate every label of a dataset against it.
"""
from __future__ import annotations

NUM = {"type": "number"}
INT = {"type": "integer"}


def _vec(n: int, item=None, what: str = "") -> dict:
    out = {"type": "array", "items": item or NUM, "minItems": n, "maxItems": n}
    return {**out, "description": what} if what else out


MAT4 = {**_vec(4, _vec(4)), "description": "4 x 4 rigid transform, mm (rows)"}
BOX = _vec(4, what="x0, y0, x1, y1 in delivered-image pixels (conventions.md: pixel centres at integers)")
PX = _vec(2, what="u, v in delivered-image pixels")

SPEC = {"type": "object", "required": ["frame_id", "index", "kind", "split", "condition"],
        "properties": {"frame_id": {"type": "string"}, "index": INT, "kind": {"type": "string"},
                       "split": {"enum": ["train", "val", "test", "repeat"]},
                       "condition": {"type": "string"}, "pose_index": INT, "capture": INT, "unit": INT,
                       "run": INT, "run_frame": INT}}

CAMERA = {"type": "object",
          "required": ["K", "focal_px", "principal_point", "cam_from_d", "distortion", "distortion_names"],
          "properties": {"K": {**_vec(3, _vec(3)), "description": "intrinsic matrix, px"},
                         "focal_px": {**NUM, "exclusiveMinimum": 0},
                         "principal_point": PX, "cam_from_d": MAT4,
                         "distortion": {"type": "array", "items": NUM},
                         "distortion_names": {"type": "array", "items": {"type": "string"}},
                         "distortion_model": {"type": "string"}, "unit": INT,
                         "look_at_mm": _vec(3), "distance_mm": NUM}}

MARKER = {"type": "object",
          "required": ["id", "section", "class_id", "center_section_mm", "center_d_mm", "normal_d", "diameter_mm",
                       "center_px", "outline_centroid_px", "bbox_px", "in_frame", "visible_fraction", "visibility"],
          "properties": {"id": {"type": "string"}, "section": {"enum": ["A", "B"]}, "class_id": {"enum": [0, 1]},
                         "pass_index": INT, "center_section_mm": _vec(3), "center_d_mm": _vec(3),
                         "normal_d": _vec(3), "diameter_mm": {**NUM, "exclusiveMinimum": 0},
                         "center_px": {**PX, "description": "the projected disc centre (through the lens)"},
                         "outline_centroid_px": {**PX, "description": "centroid of the disc's image: what a "
                                                 "centre estimator measures"},
                         "bbox_px": BOX, "in_frame": {"type": "boolean"},
                         "visible_fraction": {**NUM, "minimum": 0, "maximum": 1},
                         "visibility": {"enum": [0, 1, 2], "description": "COCO: 0 not labelled, 1 labelled "
                                        "but not visible, 2 visible"},
                         "legible": {"type": "boolean"}, "depth_mm": NUM}}

SECTION = {"type": "object", "required": ["section", "pixels_visible", "visible_fraction"],
           "properties": {"section": {"enum": ["A", "B"]}, "pass_index": INT, "pixels_all": INT,
                          "pixels_visible": INT, "visible_fraction": {**NUM, "minimum": 0, "maximum": 1}}}

POSE = {"type": "object", "required": ["x_mm", "y_mm", "z_mm", "alpha_deg", "beta_deg", "gamma_deg"],
        "properties": {k: NUM for k in ("x_mm", "y_mm", "z_mm", "alpha_deg", "beta_deg", "gamma_deg")},
        "description": "pose of B in D (A's docking frame): mm and degrees (conventions.md)"}

LABEL_SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "$id": "dockfactory.label/1",
    "title": "dockfactory frame label",
    "type": "object",
    "required": ["format", "frame_id", "spec", "image", "camera", "d_from_b", "pose_b_in_d", "markers", "sections"],
    "properties": {
        "format": {"const": "dockfactory.label/1"},
        "frame_id": {"type": "string", "pattern": "^[A-Za-z0-9_-]+$"},
        "spec": SPEC,
        "conditions": {"type": "array", "items": {"type": "string"}},
        "image": {"type": "object", "required": ["width", "height"],
                  "properties": {"width": {**INT, "minimum": 1}, "height": {**INT, "minimum": 1},
                                 "pixel_convention": {"type": "string"}}},
        "camera": CAMERA,
        "d_from_b": MAT4,
        "pose_b_in_d": POSE,
        "markers": {"type": "array", "items": MARKER},
        "sections": {"type": "array", "items": SECTION},
        "sampled": {"type": "object", "description": "the scene's random draws (free form)"},
        "derived": {"type": "object", "description": "figures measured on the rendered image (free form)"},
    },
}

SCHEMAS = {"labels": LABEL_SCHEMA}
