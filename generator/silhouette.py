"""A section's silhouette as a renderer samples it (pure numpy): its solids' points and the pixels
whose centre lies inside their images.

A parametric section is two convex solids of revolution sharing the docking axis: the flange (radius R + the
flange height, from the docking face over the flange width) and the body (radius R, from the
flange's back to the far end). Their union is not convex: the convex hull of all their circles
also covers the sliver between the flange's rim and the far end, which no renderer draws
(bench/results/tool_checks/README.md measures it). So the silhouette is the union of the images of the two solids, each the convex hull of its
projected circles (through a lens: that hull's outline, distorted), filled at pixel centres.

A section from a part mesh is the union of its triangles' images.

Pixel convention (OpenCV): pixel (c, r) has its centre at x = c, y = r.
"""
from __future__ import annotations

import numpy as np

from dockfactory.core.scene import StaticScene

SEGMENTS = 128   # points on each circle: the vertices of the BOP export's model rims too


def section_silhouette(static: StaticScene, section: str, n: int = SEGMENTS) -> np.ndarray:
    """Points (3 n, 3) mm in the section frame: the flange's two rim circles (radius R + flange
    height, at the docking face and the flange's back) and the body's far-end circle (radius R).
    Every point of the section projects inside the convex hull of their images. A part mesh: its
    vertices."""
    part = static.part(section)
    if part is not None:
        return np.asarray(part.vertices, dtype=np.float64)
    a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    sign = -1.0 if section == "A" else 1.0
    rings = []
    for x, r in ((0.0, static.radius_mm + static.flange_height_mm),
                 (sign * static.flange_width_mm, static.radius_mm + static.flange_height_mm),
                 (sign * static.length_mm, static.radius_mm)):
        rings.append(np.stack([np.full(n, x), r * np.sin(a), r * np.cos(a)], axis=1))
    return np.concatenate(rings)


def silhouette_parts(static: StaticScene, sec: str) -> list[np.ndarray]:
    """The section's two convex solids as points (2 n, 3) mm in its frame, each the convex hull of
    its points: the flange (its two rim circles) and the body (circles of radius R at the flange's
    back and at the far end). A part mesh: its triangles (each convex; their union is the part)."""
    part = static.part(sec)
    if part is not None:
        return list(part.corners())
    pts = section_silhouette(static, sec)
    n = len(pts) // 3
    far = pts[2 * n:]
    near = far.copy()
    near[:, 0] = pts[n, 0]   # the flange's back face
    return [pts[:2 * n], np.vstack([near, far])]


def fill_centres(poly: np.ndarray, w: int, h: int) -> np.ndarray:
    """(h, w) bool: the pixels whose centre lies inside the closed polygon ``poly`` (N, 2) (even-odd
    rule; a centre on a left edge is inside, on a right edge outside): a scanline fill at the
    pixel centres' rows."""
    mask = np.zeros((h, w + 1), np.int32)
    p, q = poly, np.roll(poly, -1, axis=0)
    rows = np.arange(h, dtype=np.float64)
    lo, hi = np.minimum(p[:, 1], q[:, 1]), np.maximum(p[:, 1], q[:, 1])
    cross = (rows[None, :] >= lo[:, None]) & (rows[None, :] < hi[:, None])   # (edges, rows), half-open
    e, r = np.nonzero(cross)
    if len(r) == 0:
        return mask[:, :w].astype(bool)
    t = (rows[r] - p[e, 1]) / (q[e, 1] - p[e, 1])
    x = p[e, 0] + t * (q[e, 0] - p[e, 0])
    order = np.lexsort((x, r))
    r, x = r[order], x[order]
    start, end = np.ceil(x[0::2]), np.ceil(x[1::2])   # crossings pair up row by row (even-odd)
    start, end = np.clip(start, 0, w).astype(int), np.clip(end, 0, w).astype(int)
    np.add.at(mask, (r[0::2], start), 1)
    np.add.at(mask, (r[1::2], end), -1)
    return np.cumsum(mask, axis=1)[:, :w] > 0


def outlines_mask(outlines: list[np.ndarray], w: int, h: int) -> np.ndarray:
    """(h, w) bool: the union of the pixel-centre fills of ``outlines`` (each (N, 2), OpenCV px;
    fewer than 3 points: empty)."""
    mask = np.zeros((h, w), bool)
    for poly in outlines:
        if len(poly) >= 3:
            mask |= fill_centres(np.asarray(poly, dtype=np.float64), w, h)
    return mask


def mask_pixels(mask: np.ndarray) -> tuple[int, list[float] | None]:
    """(pixel count, pixel-edge box [x0, y0, x1, y1] in OpenCV's continuous frame, None if empty)
    of the (H, W) bool ``mask``."""
    ys, xs = np.nonzero(mask)
    if len(xs) == 0:
        return 0, None
    return int(len(xs)), [float(xs.min()) - 0.5, float(ys.min()) - 0.5, float(xs.max()) + 0.5, float(ys.max()) + 0.5]
