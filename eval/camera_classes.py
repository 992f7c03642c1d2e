"""Camera classes: what a Bayer camera or JPEG input adds to the centre noise the card states.

The noise card (detector.noise_card) is measured on three-chip renders. A frame's camera class
(:func:`camera_class`: a Bayer pattern told, a JPEG, both, or neither) scales the noise its fit may
show (``CAMERA_CLASS_FACTORS``: eval.fit_gate's second test) and sets the common offset of a
section's centres its pose carries (``CLASS_SECTION_SHIFT_PX``: the demosaic and the chroma move a
section's centres together, which no residual shows; eval.section_shift). Both were measured on the
same frames of two scenes through each camera (bench/results/fit_gate/README.md, "A noise per
camera class" and "The class's test"); each is the larger of the two scenes.
"""
from __future__ import annotations

__all__ = ["CAMERA_CLASS_FACTORS", "CLASS_SECTION_SHIFT_PX", "camera_class", "class_section_shift",
           "classes_section_shift", "classes_factor"]

# The pooled per-axis RMS of the residuals through the class's camera over the three-chip camera's
# (the larger of the two scenes, and of the bilinear and VNG demosaics for "bayer").
CAMERA_CLASS_FACTORS = {"three-chip": 1.0, "bayer": 5.5, "jpeg": 10.2, "bayer-jpeg": 14.1}
# The section shift (px per axis, x, y) of the class's centres (eval.section_shift.section_shift_stats).
CLASS_SECTION_SHIFT_PX = {"three-chip": (0.0, 0.0), "bayer": (0.0060, 0.0), "jpeg": (0.0280, 0.0171),
                          "bayer-jpeg": (0.0440, 0.0451)}


def camera_class(cfa: str | None, jpeg: bool) -> str:
    """The camera class of a frame (a key of CAMERA_CLASS_FACTORS): "bayer" when its Bayer pattern
    is told (``cfa``), "jpeg" when it is a JPEG (or its chroma is subsampled), both, or "three-chip"."""
    if cfa is not None:
        return "bayer-jpeg" if jpeg else "bayer"
    return "jpeg" if jpeg else "three-chip"


def class_section_shift(cls: str, card_shift_px) -> tuple[float, float] | None:
    """The section shift (x, y) px a frame of camera class ``cls`` carries: per axis the larger of
    the card's (``card_shift_px``, None: none measured) and the class's; None when both are none
    (the three-chip class without a card's shift)."""
    own = CLASS_SECTION_SHIFT_PX[cls]
    if card_shift_px is None:
        return None if not any(own) else own
    return tuple(max(float(c), o) for c, o in zip(card_shift_px, own))


def classes_section_shift(classes, card_shift_px) -> tuple[float, float] | None:
    """The section shift (x, y) px of frames of the camera classes ``classes`` solved together (a
    run sharing its intrinsics): per axis the largest of their :func:`class_section_shift`; None
    when none has one."""
    shifts = [class_section_shift(c, card_shift_px) for c in classes]
    shifts = [v for v in shifts if v is not None]
    return tuple(max(v[i] for v in shifts) for i in (0, 1)) if shifts else None


def classes_factor(classes) -> float:
    """The gate's class factor of frames of the camera classes ``classes`` solved together (a run
    sharing its intrinsics): the largest of their CAMERA_CLASS_FACTORS (its residuals are as noisy
    as its noisiest camera's); 1.0 for none."""
    return max((CAMERA_CLASS_FACTORS[c] for c in classes), default=1.0)
