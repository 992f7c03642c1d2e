"""Bayer refinements measured against each other in the sensor bench: the joint edge fit of every
channel at its own sites (``detector.centre_joint``) with and without its reweighted second fit,
and coverage passes that take the demosaic's widening off the disc's moments (tried, not shipped).
Figures and reasons: bench/results/sensor_effects/README.md.

    python -m bench.sensor.sensor_joint_fit --variant NAME DATASET [DATASET ...] --out RESULTS.json
                                     [any option of bench/sensor/sensor_effects.py]
    python -m bench.sensor.sensor_joint_fit --centres N DATASET [DATASET ...]

The variant replaces the refinement the detector runs when it is told a Bayer pattern (and no JPEG:
``detector.centre_camera.refine_centre_camera``); everything else is ``bench/sensor/sensor_effects.py``.
Variants (:data:`VARIANTS`):

- ``joint``: the shipped coverage passes, then ``centre_joint.fit_disc_joint`` with its first fit
  only (each channel weighted by the inverse of its noise). A refused fit returns the coverage
  centroid.
- ``joint-reweighted``: the same with the second fit (each channel weighted by the inverse RMS of
  its residual in the first): the shipped refinement told a pattern, bit for bit.
- ``joint-quality``: ``joint`` after coverage passes whose moments are less ``DEMOSAIC_BLUR_PX2``
  per axis (:func:`coverage_pass`): the quality's shape term, the fit's first ellipse and the box.
- ``joint-quality-strict``: ``joint-quality``, and a refused fit returns the marker unrefined.

``--centres N``: the centre errors alone on the first N test frames, every refinement on the same
detector boxes (the shipped detector without its refinement), against the labels' outline
centroids: per scene, effect and refinement, the markers left unrefined and the median and RMS
error (px), as a markdown table (:func:`centre_table`). "shipped" there is the refinement of the
code it runs with.

Pixel convention: OpenCV (the centre of the top-left pixel is (0, 0)); values linear (8-bit sRGB
through ``centre._SRGB_TO_LINEAR``).
"""
from __future__ import annotations

import sys
from dataclasses import replace

import numpy as np

from dockfactory.core.camera_chain.cfa import channel_map
from dockfactory.detector import centre, centre_camera
from dockfactory.detector.centre import EDGE_BIAS_PX, Refined
from dockfactory.detector.centre_joint import fit_disc_joint

# px^2 a bilinear demosaic adds per axis to the coverage's second moments: 3 pixels in 4 of a channel
# are interpolated from neighbours 1 px away (0 at own sites; 1 px^2 along the axis of two
# neighbours, on both axes for four diagonal ones): 0.5 on average over the 2x2 block.
DEMOSAIC_BLUR_PX2 = 0.5


def coverage_pass(image: np.ndarray, box, class_id: int, min_quality: float, blur_px2: float):
    """``centre._refine_once`` ((Refined, ``centre._Window`` or None)) with the coverage's second
    moments less ``blur_px2`` px^2 per axis (floored at 1/12) before the quality, the window's
    ellipse and the box are taken from them. ``box``: (4,) [x0, y0, x1, y1] px."""
    result, win = centre._refine_once(image, box, class_id, 0.0 if blur_px2 else min_quality, EDGE_BIAS_PX)
    if win is None or not blur_px2:
        return result, win
    box = np.asarray(box, dtype=np.float64)
    cx, cy = (box[0] + box[2]) / 2, (box[1] + box[3]) / 2
    hw, hh = max((box[2] - box[0]) / 2, 1.0), max((box[3] - box[1]) / 2, 1.0)
    w, fg, bg, noise = centre._soft_coverage(win.s, win.pur, win.rho)
    w = centre._disc_component(w, int(round(cy)) - int(win.ys[0, 0]), int(round(cx)) - int(win.xs[0, 0]))
    vxx, vyy = max(win.cov[0, 0] - blur_px2, 1 / 12), max(win.cov[1, 1] - blur_px2, 1 / 12)
    cov = np.array([[vxx, win.cov[0, 1]], [win.cov[0, 1], vyy]])
    det = vxx * vyy - cov[0, 1] ** 2
    quality = centre._quality(float(w.sum()), det, hw, hh, (fg - bg) / noise) if det > 0 else 0.0
    if quality < min_quality:
        return Refined(center=np.array([cx, cy]), box=box.copy(), quality=quality, refined=False), None
    return (Refined(center=result.center, box=_moment_box(image, result.center, cov), quality=quality,
                    refined=True), replace(win, cov=cov))


def _moment_box(image: np.ndarray, centre_px: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """(4,) px: half-extents 2 sqrt(variance) + ``EDGE_BIAS_PX`` around ``centre_px``, clipped."""
    h_img, w_img = image.shape[:2]
    half = np.array([cov[0, 0], cov[1, 1]]) ** 0.5 * 2 + EDGE_BIAS_PX
    return np.clip(np.concatenate([centre_px - half, centre_px + half]), -0.5,
                   np.array([w_img, h_img, w_img, h_img]) - 0.5)


# name -> (moments less px^2, reweighted second fit, a refused fit leaves the marker unrefined)
VARIANTS = {"joint": (0.0, False, False), "joint-reweighted": (0.0, True, False),
            "joint-quality": (DEMOSAIC_BLUR_PX2, False, False),
            "joint-quality-strict": (DEMOSAIC_BLUR_PX2, False, True)}


def refine_variant(name: str, image: np.ndarray, box, class_id: int, cfa: str | None = None,
                   jpeg: bool = False, min_quality: float = 0.3) -> Refined:
    """``centre_camera.refine_centre_camera``'s contract, the variant ``name`` with a pattern and no
    JPEG, the shipped refinement otherwise."""
    if cfa is None or jpeg:
        return centre_camera.refine_centre_camera(image, box, class_id, cfa, jpeg, min_quality)
    blur, reweight, strict = VARIANTS[name]
    channel_map(cfa, 2, 2)
    first, win = coverage_pass(image, box, class_id, min_quality, blur)
    if not first.refined:
        return first
    second, win2 = coverage_pass(image, first.box, class_id, min_quality, blur)
    if second.refined:
        first, win = second, win2
    fitted = fit_disc_joint(image, win, class_id, cfa, reweight)
    if fitted is None:
        return replace(first, refined=False) if strict else first
    return Refined(center=fitted, box=_moment_box(image, fitted, win.cov), quality=first.quality, refined=True)


def _refiners() -> dict:
    """Refinement name -> f(image, box, class_id, cfa): the shipped one, the class's own channel at
    its own sites (the rule the shipped one keeps for a JPEG of a known pattern) and every variant."""
    out = {"shipped": lambda i, b, c, cfa: centre_camera.refine_centre_camera(i, b, c, cfa),
           "own-sites": lambda i, b, c, cfa: centre_camera.refine_centre_camera(i, b, c, cfa, cfa is not None)}
    for name in VARIANTS:
        out[name] = (lambda n: lambda i, b, c, cfa: refine_variant(n, i, b, c, cfa))(name)
    return out


def centre_table(roots: list[str], frames: int, effects=("three-chip", "bayer-bilinear", "bayer-mhc")) -> str:
    """Markdown: per dataset, effect and refinement (``_refiners``, told RGGB; a three-chip image
    through the plain refinement too), markers left unrefined / detections, median and RMS centre
    error (px) of the fully visible markers (``sensor_effects.centre_errors``, an unrefined one at
    its box centre)."""
    from bench.sensor import sensor_effects as se
    from dockfactory.core.resources import shipped_weights
    from dockfactory.detector.infer import MarkerDetector
    from dockfactory.generator.datasets.reader import Dataset
    from dockfactory.generator.exr import read_passes
    detector = MarkerDetector(shipped_weights(), refine=False)
    lines = ["| scene | effect | refinement | unrefined | median px | RMS px |",
             "| --- | --- | --- | --- | --- | --- |"]
    for root in roots:
        ds = Dataset.open(root, full=False)
        for effect in effects:
            images = {}
            for fid in ds.frames("test")[:frames]:
                image = se.delivered(read_passes(ds.root / "exr" / f"{fid}.exr").rgb, ds.labels[fid], effect)
                images[fid] = (image, detector.detect(image))
            named = [("plain", None, "shipped")] if effect == "three-chip" else []
            for label, cfa, name in named + [(n, "RGGB", n) for n in _refiners()]:
                refine, errs, unrefined, n = _refiners()[name], [], 0, 0
                for fid, (image, dets) in images.items():
                    rows = []
                    for d in dets:
                        r = refine(image, np.array(d["bbox_detector_px"]), d["class_id"], cfa)
                        rows.append({"class_id": d["class_id"], "center_px": r.center.tolist()})
                        unrefined, n = unrefined + (not r.refined), n + 1
                    errs += [np.hypot(dx, dy) for _, dx, dy in se.centre_errors(rows, ds.labels[fid])]
                e = np.array(errs)
                lines.append(f"| {ds.config.dataset.name} | {effect} | {label} | {unrefined}/{n} | "
                             f"{np.median(e):.3f} | {np.sqrt(np.mean(e ** 2)):.3f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--centres" in argv:
        i = argv.index("--centres")
        print(centre_table(argv[:i] + argv[i + 2:], int(argv[i + 1])))
        return 0
    if "--variant" not in argv or argv.index("--variant") + 1 >= len(argv):
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        return 2
    i = argv.index("--variant")
    name = argv[i + 1]
    if name not in VARIANTS:
        print(f"--variant must be one of {', '.join(VARIANTS)}, got {name!r}", file=sys.stderr)
        return 2
    from bench.sensor import sensor_effects
    from dockfactory.detector import infer
    infer.refine_centre_camera = lambda *a, **k: refine_variant(name, *a, **k)
    return sensor_effects.main(argv[:i] + argv[i + 2:])


if __name__ == "__main__":
    sys.exit(main())
