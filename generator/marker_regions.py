"""Label-aware sampling: where a frame's render spends its extra samples (pure, no bpy).

The factory knows before it renders where every marker will land. With ``[render]
marker_samples`` = N > 0 the frame is rendered as configured (``samples``, the denoiser), then
the marker regions are rendered again at N samples per pixel (Cycles' border render, cropped to
the region, in the same worker with the same scene and seed; denoised by ``marker_denoise``) and
blended into the frame (:func:`composite`): the markers, whose edges the centre refinement
measures, are as clean as an N-sample render, at the cost of N samples on a few per cent of the
pixels. docs/rendering.md ("Label-aware sampling") gives the figures.

Each marker's halo (HALO_RADII, HALO_PX, FEATHER_PX) is blended from non-overlapping rectangles
(:func:`merge_boxes`), in render-canvas pixels; the labels are untouched.

Why and how: docs/rendering.md, "Label-aware sampling: the regions".
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.geometry import project_points
from dockfactory.core.layout import RING_BASE_DEPTH_MM, RING_EXTRA_MM, Marker, marker_outline
from dockfactory.core.scene import FrameScene, StaticScene

HALO_RADII = 1.3        # the halo's radius in disc radii (what the refinement reads), at least the ring's
HALO_PX = 1             # the crop's full weight reaches this far beyond the halo's outline
FEATHER_PX = 3          # then falls linearly to 0 over this many pixels
# around each halo: the blend's reach, no more (a border render's pixel draws its filter's samples
# beyond the border as a whole frame's does: its edge pixels are the whole frame's)
REGION_MARGIN_PX = HALO_PX + FEATHER_PX
# A crop render's fixed cost (scene sync, kernel set-up, EXR write and read) in pixel-samples:
# about 0.1 s of 2-core wall time at about 1.2 us per pixel-sample (docs/rendering.md).
CROP_OVERHEAD_PIXEL_SAMPLES = 100_000
OUTLINE_N = 64          # points per projected circle
SUBPIXEL_BITS = 3       # the halo's outline is rasterised at 1/8 px


@dataclass(frozen=True)
class Region:
    """A rectangle of the render canvas: columns [x0, x1), rows [y0, y1) (canvas pixels)."""
    x0: int
    y0: int
    x1: int
    y1: int

    @property
    def area(self) -> int:
        return (self.x1 - self.x0) * (self.y1 - self.y0)

    def overlaps(self, other: "Region") -> bool:
        return self.x0 < other.x1 and other.x0 < self.x1 and self.y0 < other.y1 and other.y0 < self.y1

    def union(self, other: "Region") -> "Region":
        return Region(min(self.x0, other.x0), min(self.y0, other.y0), max(self.x1, other.x1), max(self.y1, other.y1))


def halo_points(marker: Marker, n: int = OUTLINE_N, radius_mm: float | None = None,
                base_depth_mm: float = RING_BASE_DEPTH_MM) -> np.ndarray:
    """(2 n, 3) mm in the marker's section frame: the halo's circle (radius the larger of the
    ring's and HALO_RADII disc radii, or ``radius_mm``) at the disc's top face and at the bottom
    of the ring base, ``base_depth_mm`` below it (what a slanted view of the marker's side shows)."""
    r = max(marker.diameter_mm / 2.0 + RING_EXTRA_MM, HALO_RADII * marker.diameter_mm / 2.0) \
        if radius_mm is None else radius_mm
    circle = marker_outline(dataclasses.replace(marker, diameter_mm=2.0 * r), n)
    normal = np.asarray(marker.normal, dtype=np.float64)
    return np.vstack([circle, circle - base_depth_mm * normal])


def _b_poses(frame: FrameScene) -> list[np.ndarray]:
    """B's poses (4, 4) that the exposure sees: mid-exposure, and while B moves the shutter's open
    and close (a rolling shutter exposes every row between them)."""
    d_from_b = frame.d_from_b_array()
    m = frame.motion
    if m is None or not m.moves():
        return [d_from_b]
    half_s = m.shutter_ms() / 2000.0
    return [d_from_b, m.d_from_b_at(d_from_b, -half_s), m.d_from_b_at(d_from_b, half_s)]


def marker_halos(frame: FrameScene, static: StaticScene) -> list[np.ndarray]:
    """Each marker's halo (k, 2) in render-canvas pixels, over every pose of B the exposure sees,
    in layout order; markers with a point at or behind the camera are left out."""
    cam = frame.camera
    ox, oy, _, _ = cam.canvas()
    k, cam_from_d = cam.pinhole_k(), cam.cam_from_d_array()
    out = []
    for m in static.markers:
        poses = _b_poses(frame) if m.section == "B" else [np.eye(4)]
        uv = np.vstack([project_points(k, cam_from_d @ p, halo_points(m, base_depth_mm=static.marker_base_depth_mm))[0] for p in poses])
        if np.all(np.isfinite(uv)):
            out.append(uv - np.array([ox, oy]))
    return out


def marker_boxes(frame: FrameScene, static: StaticScene, margin_px: float | None = None) -> list[Region]:
    """Every marker halo's bounding rectangle grown by ``margin_px`` (None: REGION_MARGIN_PX),
    pixel-aligned and clipped to the canvas (halos wholly outside it have none), in layout order."""
    margin_px = REGION_MARGIN_PX if margin_px is None else margin_px
    _, _, wc, hc = frame.camera.canvas()
    out = []
    for uv in marker_halos(frame, static):
        lo = np.floor(uv.min(axis=0) - margin_px + 0.5).astype(int)
        hi = np.ceil(uv.max(axis=0) + margin_px + 0.5).astype(int)
        box = Region(max(0, lo[0]), max(0, lo[1]), min(wc, hi[0]), min(hc, hi[1]))
        if box.x1 > box.x0 and box.y1 > box.y0:
            out.append(box)
    return out


def merge_boxes(boxes: list[Region], overhead_px: float) -> tuple[Region, ...]:
    """Regions covering ``boxes`` with no two overlapping: overlapping boxes are merged, and two
    boxes whose union costs less than both apart (each crop counted as its area plus
    ``overhead_px``) too, the largest saving first. Sorted by (y0, x0); the boxes are put in that
    order first, so the result does not depend on the order they come in."""
    regions = sorted(boxes, key=lambda r: (r.y0, r.x0, r.y1, r.x1))
    while True:
        best = None
        for i in range(len(regions)):
            for j in range(i + 1, len(regions)):
                a, b = regions[i], regions[j]
                u = a.union(b)
                saving = np.inf if a.overlaps(b) else a.area + b.area + overhead_px - u.area
                if saving >= 0 and (best is None or saving > best[0]):
                    best = (saving, i, j, u)
        if best is None:
            return tuple(sorted(regions, key=lambda r: (r.y0, r.x0, r.y1, r.x1)))
        _, i, j, u = best
        regions = [r for n, r in enumerate(regions) if n not in (i, j)] + [u]


def marker_regions(frame: FrameScene, static: StaticScene) -> tuple[Region, ...]:
    """The canvas regions the frame renders again at ``frame.render.marker_samples`` (empty when
    that is 0): :func:`marker_boxes`, merged by :func:`merge_boxes` at the crop's fixed cost."""
    n = frame.render.marker_samples
    if n <= 0:
        return ()
    return merge_boxes(marker_boxes(frame, static), CROP_OVERHEAD_PIXEL_SAMPLES / n)


def halo_weights(halos: list[np.ndarray], region: Region) -> np.ndarray:
    """(h, w) float32 in [0, 1] over ``region``: the crop's share of each pixel, 1 within HALO_PX
    of any halo's convex outline (``halos``: (k, 2) canvas pixels each, from
    :func:`marker_halos`), falling linearly to 0 over the next FEATHER_PX (distance from the
    pixel's centre to the outline rasterised at 1/8 px), 0 beyond."""
    w, h = region.x1 - region.x0, region.y1 - region.y0
    inside = np.zeros((h, w), np.uint8)
    scale = 1 << SUBPIXEL_BITS
    for uv in halos:
        local = uv - np.array([region.x0, region.y0])
        if local[:, 0].max() < -REGION_MARGIN_PX or local[:, 0].min() > w + REGION_MARGIN_PX or \
                local[:, 1].max() < -REGION_MARGIN_PX or local[:, 1].min() > h + REGION_MARGIN_PX:
            continue
        hull = cv2.convexHull(np.round(local * scale).astype(np.int32))
        cv2.fillConvexPoly(inside, hull, 1, lineType=cv2.LINE_8, shift=SUBPIXEL_BITS)
    if not inside.any():
        return np.zeros((h, w), np.float32)
    dist = cv2.distanceTransform((inside == 0).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return np.clip((HALO_PX + FEATHER_PX - dist) / FEATHER_PX, 0.0, 1.0).astype(np.float32)


def composite(rgb: np.ndarray, crops: list[np.ndarray], regions: tuple[Region, ...],
              halos: list[np.ndarray]) -> np.ndarray:
    """The frame ``rgb`` (H, W, 3) float32 linear, with each crop (h, w, 3) of ``regions`` blended
    in by :func:`halo_weights` of ``halos``; a new array. ValueError when a crop's shape is not
    its region's (a misplaced border render must not pass silently)."""
    if len(crops) != len(regions):
        raise ValueError(f"{len(crops)} crops for {len(regions)} marker regions")
    out = np.array(rgb, dtype=np.float32, copy=True)
    hc, wc = out.shape[:2]
    for crop, r in zip(crops, regions):
        if crop.shape[:2] != (r.y1 - r.y0, r.x1 - r.x0) or r.x1 > wc or r.y1 > hc:
            raise ValueError(f"crop of shape {crop.shape[:2]} does not fit region {r} of a {wc} x {hc} canvas")
        wgt = halo_weights(halos, r)[..., None]
        tile = out[r.y0:r.y1, r.x0:r.x1]
        out[r.y0:r.y1, r.x0:r.x1] = tile + wgt * (crop[..., :3].astype(np.float32) - tile)
    return out
