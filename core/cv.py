"""OpenCV for the project, without its loader's mark on the caller's environment.

``import cv2`` prepends its wheel's library folder to ``LD_LIBRARY_PATH`` (for child processes
only: the running process's loader read the variable at its start), so importing a dockfactory
module would change what the user's own subprocesses load. Every project module takes ``cv2``
from here: imported once, the variable put back as it was. (detector/centre.py keeps a plain
``import cv2``: its source's sha256 names the refinement of the shipped noise cards; the detector
package imports this module before it.)
"""
import os

_BEFORE = os.environ.get("LD_LIBRARY_PATH")

import cv2  # noqa: E402

if _BEFORE is None:
    os.environ.pop("LD_LIBRARY_PATH", None)
else:
    os.environ["LD_LIBRARY_PATH"] = _BEFORE

__all__ = ["cv2"]
