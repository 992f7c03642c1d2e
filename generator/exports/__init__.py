"""The dataset's exports: a writer per format of ``[export] formats`` and ``dataset export``, each
writing ``exports/<format>/`` of an intact, complete dataset.

Modules: :mod:`~dockfactory.generator.exports.coco` (COCO keypoints), ``coco_results`` (a detections
document as COCO results rows), ``yolo``, ``yolo_pose``, ``bop`` (the BOP layout with masks, depth
and models), ``cameras`` (OpenCV, ROS and COLMAP calibrations per frame), ``video`` (each run as a
video with its labels), ``files`` (placing a dataset's files in an export: hard links, DVC cache
links or copies).

``WRITERS`` is the registry: each name of ``core.names.EXPORT_FORMATS`` (what ``[export] formats``
and render write; the config checks its names there) and of ``ON_DEMAND`` (written by ``dataset
export`` only) to the facade's ``export_<name>`` (``-`` read as ``_``): a name without a writer
fails at import.
"""
from dockfactory.core.names import EXPORT_FORMATS
from dockfactory.generator.exports.bop import export_bop
from dockfactory.generator.exports.cameras import export_cameras
from dockfactory.generator.exports.coco import coco_from_labels, export_coco
from dockfactory.generator.exports.coco_results import coco_results
from dockfactory.generator.exports.video import export_video, export_video_lossless
from dockfactory.generator.exports.yolo import export_yolo
from dockfactory.generator.exports.yolo_pose import export_yolo_pose

ON_DEMAND = ("video", "video_lossless")   # datasets with [runs]: one video per docking run
WRITERS = {name: globals()["export_" + name.replace("-", "_")] for name in EXPORT_FORMATS + ON_DEMAND}

__all__ = [
    # the writers of exports/<format>/
    "export_coco", "export_yolo", "export_yolo_pose", "export_bop", "export_cameras", "export_video",
    "export_video_lossless",
    # COCO dicts without a dataset folder
    "coco_from_labels", "coco_results",
]
