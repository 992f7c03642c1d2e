"""``dockfactory measure``: the pose of B in A from real images or a stream, without labels.

Modules: :mod:`~dockfactory.measure.images` (image files: detect, identify, solve, records,
overlays), with :mod:`~dockfactory.measure.read` (what the user knows of the camera, the image
checks), :mod:`~dockfactory.measure.image_header` (an image's kind and size before decoding),
:mod:`~dockfactory.measure.pool` (worker processes), :mod:`~dockfactory.measure.store` (results
written as each image finishes), :mod:`~dockfactory.measure.overlay` and
:mod:`~dockfactory.measure.verdict` (uncertainty budget and conformity per image); the stream path
:mod:`~dockfactory.measure.stream` (video files and cameras), with
:mod:`~dockfactory.measure.stream_pool`, :mod:`~dockfactory.measure.kalman` (the display filter),
:mod:`~dockfactory.measure.roi`, :mod:`~dockfactory.measure.selfcal` and
:mod:`~dockfactory.measure.chroma`. Importing the package loads neither torch nor a detector.
"""
from dockfactory.measure.images import MAX_WORKERS, MeasureOptions, measure
from dockfactory.measure.read import CameraInput
from dockfactory.measure.stream import StreamOptions, measure_stream

__all__ = [
    # image files
    "measure", "MeasureOptions", "CameraInput", "MAX_WORKERS",
    # a video file or a camera
    "measure_stream", "StreamOptions",
]
