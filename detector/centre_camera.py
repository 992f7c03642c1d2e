"""Sub-pixel marker centre with what is known of the camera: its Bayer pattern, its colour
subsampling (JPEG, lossy video).

The coverage passes, quality and box are ``detector.centre``'s; the edge fit sees only the values
the sensor sampled: with a Bayer pattern every channel at its own sites
(``detector.centre_joint``), with a JPEG (or any 4:2:0 source) the luma, with both the class's own
channel at its own sites. ``detector/centre.py`` stays untouched by camera handling: its sha256
names the refinement of the weights' noise cards.
Why and how: docs/detector.md, "The centre refinement of a colour camera".
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from dockfactory.core.camera_chain.cfa import channel_map
import dockfactory.detector.centre as centre
from dockfactory.detector.centre import CLASS_CHANNEL, EDGE_BIAS_PX, Refined
from dockfactory.detector.centre_joint import joint_fit, reference_channel


def fit_evidence(image: np.ndarray, win, class_id: int, cfa: str | None, jpeg: bool):
    """The coverage window ``win`` (a ``centre._Window``) with its score replaced by the fit's
    data: with a ``cfa``, the reference channel of ``centre_joint.reference_channel`` (the class's
    own channel on a dark ring) at its own sites, NaN elsewhere; with ``jpeg`` and no ``cfa`` the
    luma; linear, negated when its disc is darker than its ring (a disc on a white ring) so that
    the disc lies above the ring. Also the disc and ring levels of that data (with a ``cfa`` the ring
    level the reference channel's); None when either level has no pixel or the disc does not stand
    out. ValueError for an unknown pattern."""
    y0, x0 = int(win.ys[0, 0]), int(win.xs[0, 0])
    h, w = win.s.shape
    sub = image[y0:y0 + h, x0:x0 + w]
    if cfa is None:
        (level, _), sites, sign = centre.luma_score(sub, win.rho), np.ones(sub.shape[:2], bool), 1.0
    else:
        cmap = channel_map(cfa, *image.shape[:2])[y0:y0 + h, x0:x0 + w]
        lin = centre._SRGB_TO_LINEAR[sub]
        ref = reference_channel(lin, cmap, win.rho, CLASS_CHANNEL[class_id])
        if ref is None:
            return None
        level, sites, sign = lin[..., ref[0]], cmap == ref[0], ref[1]
    level = sign * level
    inner, ring = (win.rho <= 0.5) & sites, (win.rho >= 1.08) & (win.rho <= 1.22) & sites
    if not inner.any() or not ring.any():
        return None
    fg, bg = float(np.percentile(level[inner], 25)), float(np.median(level[ring]) if cfa is None else ref[2][1])
    if not fg > bg:   # the disc does not stand out in this evidence
        return None
    return replace(win, s=np.where(sites, level, np.float32(np.nan)), fg=fg, bg=bg)


def refine_centre_camera(image: np.ndarray, box, class_id: int, cfa: str | None = None, jpeg: bool = False,
                         min_quality: float = 0.3, edge_bias_px: float = EDGE_BIAS_PX) -> Refined:
    """``centre.refine_centre`` for an ``image`` (H, W, 3) uint8 RGB of a camera with Bayer
    pattern ``cfa`` (RGGB, BGGR, GRBG, GBRG; None: three-chip or unknown) that was JPEG-encoded
    (``jpeg``): the same coverage passes, quality and box, the centre from the edge fit on the
    evidence the camera kept (with a pattern and no JPEG every channel at its own sites; see the
    module docstring); with neither, ``centre.refine_centre``
    itself. ``box``: (4,) [x0, y0, x1, y1] px, OpenCV convention. ValueError for an unknown
    pattern."""
    if cfa is None and not jpeg:
        return centre.refine_centre(image, box, class_id, min_quality, edge_bias_px)
    if cfa is not None:
        channel_map(cfa, 2, 2)   # an unknown pattern is refused before any work
    first, win = centre.coverage_passes(image, box, class_id, min_quality, edge_bias_px)
    if win is None:
        return first
    if cfa is not None and not jpeg:
        joint = joint_fit(image, win, class_id, cfa)
        fitted = None if joint is None else (win.centre + joint[0][:2], centre._edge_px(joint[0]))
    else:
        own = fit_evidence(image, win, class_id, cfa, jpeg)
        fit = None if own is None else centre.edge_fit(own)
        fitted = None if fit is None else (fit.centre, fit.edge_px)
    return centre.finish_refined(image, first, win, fitted, min_quality, edge_bias_px)
