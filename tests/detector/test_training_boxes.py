"""detector.data: the boxes the network learns. A marker of B that moved during the exposure is a
smear in the image: it learns the box its outline swept (``bbox_swept_px``), not the outline at
mid-exposure; every other marker learns its outline box."""
import numpy as np

from dockfactory.detector.data import frame_from_label, training_box


def _marker(mid, box, cls=1, swept=None):
    m = {"marker_id": mid, "class_id": cls, "bbox_px": box, "center_px": [(box[0] + box[2]) / 2, (box[1] + box[3]) / 2],
         "visible_pixels": 120, "visible_fraction": 1.0, "visibility": 2}
    if swept is not None:
        m["bbox_swept_px"] = swept
    return m


def test_a_moving_marker_learns_its_swept_box_and_a_still_one_its_outline():
    still = _marker("A0", [10.0, 20.0, 30.0, 32.0], cls=0)
    moving = _marker("B0", [100.0, 20.0, 120.0, 32.0], swept=[96.5, 19.0, 123.5, 33.0])
    label = {"frame_id": "000007", "spec": {"condition": "normal"}, "image": {"width": 320, "height": 240},
             "markers": [still, moving, {**_marker("B1", [0, 0, 1, 1]), "visible_pixels": 0}]}
    frame = frame_from_label("/data", label)
    np.testing.assert_array_equal(frame.boxes, [[10.0, 20.0, 30.0, 32.0], [96.5, 19.0, 123.5, 33.0]])
    np.testing.assert_array_equal(frame.classes, [0, 1])
    assert training_box(still) == still["bbox_px"] and training_box(moving) == moving["bbox_swept_px"]
