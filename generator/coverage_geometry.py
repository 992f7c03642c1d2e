"""The markers' coverage of every pixel from their geometry (pure, no bpy).

Label-aware sampling's control variate (generator.marker_coverage) needs each marker-region
pixel's share of samples on the disc and on the ring at infinitely many samples. For a static,
unoccluded marker the factory knows everything that share depends on, so it is computed, not
rendered: Cycles places a pixel's samples at its centre plus offsets drawn independently in x and
y from its Blackman-Harris filter (support +-``filter_width_px``), so a convex region's share is
an integral over y of the filter's CDF across the region's horizontal slice (Gauss-Legendre in y,
exact in x; by vertical slices where the edge runs nearer horizontal). Modelled: the disc (the
mesh's 96-gon) and the ring base (a 64-gon prism) down to where its walls meet the section's
faceted body. Not modelled (left to the coverage render): occluders, a moving B, depth of field,
part meshes; :func:`geometry_coverages` checks each region's own samples against the geometry.
docs/rendering.md ("The coverage from the geometry") gives the figures.
"""
from __future__ import annotations

import functools

import numpy as np

from dockfactory.core.cv import cv2
from dockfactory.core.geometry import project_points
from dockfactory.core.layout import (DISC_SEGMENTS, RING_EXTRA_MM, RING_SEGMENTS, RING_TOP_MM, SECTION_FACETS,
                                     Marker, marker_basis)
from dockfactory.core.scene import FrameScene, StaticScene

BLACKMAN_HARRIS = (0.35875, 0.48829, 0.14128, 0.01168)
QUADRATURE_NODES = 48       # Gauss-Legendre nodes across the filter's support in y
CDF_TABLE_POINTS = 4097     # the filter's CDF tabulated across its support
SETTLED = 1e-9              # a share this near 0 or 1 is settled: no sample may land elsewhere
SETTLED_TOLERANCE = 1e-3    # a stored share further than this from a settled one is a sample elsewhere
VARIANCE_FLOOR = 1e-4       # added to each edge pixel's binomial variance (shares near 0 or 1)
AGREE_LIMIT = 1.0           # mean squared difference across the edges, in binomial variances


def filter_cdf(u: np.ndarray, width_px: float) -> np.ndarray:
    """P(offset < u) for one axis of Cycles' Blackman-Harris pixel filter of ``width_px``: offsets
    on [-width_px, width_px] (Cycles doubles this filter's width) with density BH(t),
    t = (u / width_px + 1) / 2 in [0, 1]."""
    t = np.clip((np.asarray(u, dtype=np.float64) / width_px + 1.0) / 2.0, 0.0, 1.0)
    a0, a1, a2, a3 = BLACKMAN_HARRIS
    tau = 2.0 * np.pi * t
    return (a0 * t - a1 * np.sin(tau) / (2 * np.pi) + a2 * np.sin(2 * tau) / (4 * np.pi)
            - a3 * np.sin(3 * tau) / (6 * np.pi)) / a0


def filter_density(t: np.ndarray) -> np.ndarray:
    """The Blackman-Harris window (unnormalised) at ``t`` in [-1, 1] of its support."""
    tau = np.pi * (np.asarray(t, dtype=np.float64) + 1.0)
    a0, a1, a2, a3 = BLACKMAN_HARRIS
    return a0 - a1 * np.cos(tau) + a2 * np.cos(2 * tau) - a3 * np.cos(3 * tau)


@functools.lru_cache(maxsize=8)
def filter_quadrature(width_px: float, n: int = QUADRATURE_NODES) -> tuple[np.ndarray, np.ndarray]:
    """(offsets (n,), weights (n,) summing to 1): Gauss-Legendre on the filter's support, each
    weight times the filter's density there (the y integral of a pixel's share)."""
    x, w = np.polynomial.legendre.leggauss(n)
    weights = w * filter_density(x)
    return x * width_px, weights / weights.sum()


def _circle(marker: Marker, radius_mm: float, segments: int, depth_mm: float) -> np.ndarray:
    """(segments, 3) mm in the section frame: the mesh's polygon of ``radius_mm`` at ``depth_mm``
    along the marker's normal from its centre (negative: below the disc's top face)."""
    a = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    local = np.stack([radius_mm * np.cos(a), radius_mm * np.sin(a), np.full_like(a, depth_mm)], axis=1)
    return np.asarray(marker.center_mm) + local @ marker_basis(marker.normal).T


def _down_to_cylinder(top: np.ndarray, normal, radius_mm: float, limit_mm: float) -> np.ndarray:
    """``top`` (k, 3) moved down the marker's normal to where that line meets the section's
    surface, at most ``limit_mm``: the ring's side walls show above it. The surface is the body
    mesh's: a prism of SECTION_FACETS flat faces about X (blender_scenes.meshes.tube_x), whose
    faces lie up to R (1 - cos(pi / facets)) inside the cylinder (0.03 mm at R 450 mm, a tenth
    of the walls' height)."""
    n = np.asarray(normal, dtype=np.float64)
    step = 2.0 * np.pi / SECTION_FACETS
    apothem = radius_mm * np.cos(step / 2.0)
    point = top.copy()
    t = np.zeros(len(top))
    for _ in range(2):     # the foot's facet, then again from the foot (a wall crosses at most one edge)
        mid = (np.floor(np.arctan2(point[:, 1], point[:, 2]) / step) + 0.5) * step
        m = np.stack([np.sin(mid), np.cos(mid)], axis=1)                 # the facet's normal in (y, z)
        t = np.clip((np.sum(top[:, 1:] * m, axis=1) - apothem) / (m @ n[1:]), 0.0, limit_mm)
        point = top - t[:, None] * n
    return point


def marker_outlines(marker: Marker, static: StaticScene, section_radius_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """(disc (96, 3), ring solid (2 * 64, 3)) mm in the section frame: the disc's polygon, and
    the ring base's top polygon with the feet of its side walls on the section (its silhouette is
    their outline's, :func:`slices`)."""
    r = marker.diameter_mm / 2.0
    disc = _circle(marker, r, DISC_SEGMENTS, 0.0)
    top = _circle(marker, r + RING_EXTRA_MM, RING_SEGMENTS, RING_TOP_MM)
    feet = _down_to_cylinder(top, marker.normal, section_radius_mm, static.marker_base_depth_mm + RING_TOP_MM)
    return disc, np.vstack([top, feet])


def geometry_applies(frame: FrameScene, static: StaticScene, marker: Marker) -> bool:
    """Whether :func:`region_coverage` models ``marker`` in ``frame``: on a parametric section
    (not a part mesh), B still during the exposure, no depth of field. Occluders are the caller's
    to find (the crop's own samples disagree with the geometry there)."""
    if static.part(marker.section) is not None or frame.camera.f_number > 0:
        return False
    return not (marker.section == "B" and frame.motion is not None and frame.motion.moves())


def project_outline(frame: FrameScene, marker: Marker, points_mm: np.ndarray) -> np.ndarray:
    """(k, 2) render-canvas pixels (OpenCV convention: pixel centres at integers) of points in
    ``marker``'s section frame; NaN for points at or behind the camera."""
    cam = frame.camera
    ox, oy, _, _ = cam.canvas()
    pose = cam.cam_from_d_array() @ (frame.d_from_b_array() if marker.section == "B" else np.eye(4))
    uv, _ = project_points(cam.pinhole_k(), pose, points_mm)
    return uv - np.array([ox, oy])


def convex_outline(points_uv: np.ndarray) -> np.ndarray:
    """(k, 2) px: the convex hull of ``points_uv`` (m, 2), counter-clockwise in the image. The
    ring solid's outline (its top face and walls) is convex to far below the filter's scale: the
    section curves the walls' feet by a few hundredths of a millimetre across a marker."""
    origin = points_uv.mean(axis=0)
    idx = cv2.convexHull((points_uv - origin).astype(np.float32), returnPoints=False).ravel()
    return points_uv[idx]


def slices(polygon: np.ndarray, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(x_left, x_right), each shaped like ``ys``: the horizontal slice of the convex ``polygon``
    (k, 2) px at each y; x_left > x_right where the line misses it. The outline is split at its
    top and bottom vertices into two chains monotone in y, each interpolated."""
    y = polygon[:, 1]
    top, bottom = int(np.argmin(y)), int(np.argmax(y))
    k = len(polygon)
    order = np.roll(np.arange(k), -top)
    split = (bottom - top) % k
    one, other = polygon[order[:split + 1]], polygon[np.append(order[split:], top)][::-1]
    ys = np.asarray(ys, dtype=np.float64)
    xa = np.interp(ys, one[:, 1], one[:, 0])
    xb = np.interp(ys, other[:, 1], other[:, 0])
    missed = (ys < y[top]) | (ys > y[bottom])
    return np.where(missed, np.inf, np.minimum(xa, xb)), np.where(missed, -np.inf, np.maximum(xa, xb))


def _bands(edge_x: np.ndarray, live: np.ndarray, weights: np.ndarray, x0: float, w: int,
           width_px: float) -> np.ndarray:
    """(h, w): sum over nodes of weight * F(edge_x - c) at the columns c = x0 + 0 .. w - 1
    (:func:`filter_cdf`; ``edge_x`` (h, n), nodes where ``live`` is False add nothing). F is 1
    left of edge - width and 0 right of edge + width: that plateau goes in by a running sum, the
    few columns of the ramp between are evaluated."""
    h = edge_x.shape[0]
    wt = np.where(live, weights[None, :], 0.0)
    start = np.ceil(edge_x - width_px - x0)
    start = np.where(live, start, 0.0)
    rows = np.broadcast_to(np.arange(h)[:, None], edge_x.shape)
    plateau = np.zeros((h, w + 1))
    np.add.at(plateau, (rows, np.clip(start, 0, w).astype(int)), -wt)
    plateau[:, 0] += wt.sum(axis=1)
    out = np.cumsum(plateau, axis=1)[:, :w]
    table = _cdf_table(width_px)
    for k in range(int(np.ceil(2.0 * width_px)) + 1):
        c = start + k
        ok = live & (c >= 0) & (c < w)
        u = edge_x[ok] - (x0 + c[ok])
        val = wt[ok] * np.interp(u, table[0], table[1])
        np.add.at(out, (rows[ok], c[ok].astype(int)), val)
    return out


@functools.lru_cache(maxsize=8)
def _cdf_table(width_px: float, n: int = CDF_TABLE_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """:func:`filter_cdf` tabulated on ``n`` points across its support (linear interpolation
    between them errs by under 1e-7)."""
    u = np.linspace(-width_px, width_px, n)
    return u, filter_cdf(u, width_px)


def _row_shares(polygon, rows: np.ndarray, cols: np.ndarray, width_px: float, nodes: int) -> np.ndarray:
    """(len(rows), len(cols)): the share of each pixel inside the convex ``polygon`` (k, 2) px,
    integrated exactly across each horizontal slice and by quadrature over y. The quadrature
    errs where the slices appear or vanish abruptly (an edge near horizontal): :func:`shares`."""
    offsets, weights = filter_quadrature(width_px, nodes)
    xl, xr = slices(polygon, rows[:, None] + offsets[None, :])            # (h, n)
    live = xr >= xl
    return (_bands(np.where(live, xr, 0.0), live, weights, cols[0], len(cols), width_px)
            - _bands(np.where(live, xl, 0.0), live, weights, cols[0], len(cols), width_px))


def shares(polygon, region, width_px: float, nodes: int = QUADRATURE_NODES) -> np.ndarray:
    """(h, w) float64: each pixel's expected share of samples inside the convex ``polygon``
    (k, 2) px (``region``: canvas rectangle, generator.marker_regions.Region), under Cycles' pixel
    filter of ``width_px`` (:func:`filter_cdf`): by horizontal slices where the region's edge
    runs nearer vertical, by vertical slices (the same with x and y swapped) where it runs
    nearer horizontal, weighted by the squared components of the shares' gradient."""
    rows = np.arange(region.y0, region.y1, dtype=np.float64)
    cols = np.arange(region.x0, region.x1, dtype=np.float64)
    by_rows = _row_shares(polygon, rows, cols, width_px, nodes)
    swapped = polygon[:, ::-1]
    by_cols = _row_shares(swapped, cols, rows, width_px, nodes).T
    gy, gx = np.gradient(by_rows) if min(by_rows.shape) > 1 else (np.zeros_like(by_rows),) * 2
    w = gx * gx / np.maximum(gx * gx + gy * gy, 1e-30)
    return w * by_rows + (1.0 - w) * by_cols


def frame_outlines(frame: FrameScene, static: StaticScene, markers=None) -> list[tuple[np.ndarray, np.ndarray]]:
    """(disc polygon, ring solid's convex outline), each (k, 2) render-canvas pixels, of every
    one of ``markers`` (default: the static scene's) wholly in front of the camera."""
    out = []
    for m in static.markers if markers is None else markers:
        disc, ring = (project_outline(frame, m, p) for p in marker_outlines(m, static, static.radius_mm))
        if np.all(np.isfinite(disc)) and np.all(np.isfinite(ring)):
            out.append((disc, convex_outline(ring)))
    return out


def _reaches(outline: np.ndarray, region, width_px: float) -> bool:
    """Whether the filter of ``width_px`` at some pixel of ``region`` reaches ``outline``'s box."""
    return not (outline[:, 0].max() < region.x0 - width_px or outline[:, 0].min() > region.x1 + width_px or
                outline[:, 1].max() < region.y0 - width_px or outline[:, 1].min() > region.y1 + width_px)


def region_coverage(outlines, region, width_px: float) -> np.ndarray:
    """(h, w, 2) float32: the disc and ring shares of every pixel of ``region`` (canvas pixels)
    from ``outlines`` (:func:`frame_outlines`; those not reaching the region add nothing) under
    the pixel filter of ``width_px`` (the frame's ``render.filter_width_px``). Valid only where
    :func:`geometry_applies` and nothing else hides the markers."""
    h, w = region.y1 - region.y0, region.x1 - region.x0
    out = np.zeros((h, w, 2), np.float64)
    for disc, ring in outlines:
        if not _reaches(ring, region, width_px):
            continue
        d = shares(disc, region, width_px)
        out[..., 0] += d
        out[..., 1] += shares(ring, region, width_px) - d
    return np.clip(out, 0.0, 1.0).astype(np.float32)


def samples_agree(sampled: np.ndarray, exact: np.ndarray, samples: int) -> bool:
    """Whether a region's own sampled coverage (h, w, 2: the share of its samples on the disc and
    the ring) can have come from the ``exact`` shares at ``samples`` per pixel: no pixel the
    geometry puts wholly inside or outside each class has a sample elsewhere (an occluder, a hole
    in the model), and over the pixels across an edge the squared differences average at most
    :data:`AGREE_LIMIT` binomial variances (Cycles' stratified samples stay far under one)."""
    s, c = sampled.astype(np.float64), exact.astype(np.float64)
    settled = np.all((c <= SETTLED) | (c >= 1.0 - SETTLED), axis=-1)
    if np.any(np.abs(s - c)[settled] > SETTLED_TOLERANCE):
        return False
    edge = ~settled
    if not edge.any():
        return True
    var = c * (1.0 - c) / max(samples, 1) + VARIANCE_FLOOR
    return float(np.mean(((s - c) ** 2 / var)[edge])) <= AGREE_LIMIT


def geometry_coverages(frame: FrameScene, static: StaticScene, regions, sampled) -> list:
    """For each of ``regions`` (generator.marker_regions.Region): its (h, w, 2) coverage from the
    geometry (:func:`region_coverage`) where every marker reaching it is one
    :func:`geometry_applies` to and the region's own sampled coverage (``sampled``: (h, w, 2)
    arrays in region order) agrees (:func:`samples_agree`); None where the coverage must be
    rendered."""
    width = frame.render.filter_width_px
    applies = [geometry_applies(frame, static, m) for m in static.markers]
    outlines = frame_outlines(frame, static)
    every = frame_outlines(frame, static, [m for m, ok in zip(static.markers, applies) if not ok])
    out = []
    for region, own in zip(regions, sampled):
        if any(_reaches(ring, region, width) for _, ring in every):
            out.append(None)
            continue
        exact = region_coverage(outlines, region, width)
        out.append(exact if samples_agree(own, exact, frame.render.marker_samples) else None)
    return out
