"""Markers on a part's mesh: each layout coordinate (axial offset ``s_mm``, angle ``phi_deg``;
:mod:`dockfactory.core.layout`) is cast as a ray from the section's axis, (x, 0, 0) with x = -s on
A and +s on B, outward along (0, sin phi, cos phi), and the marker stands where it leaves the part
for the last time (the outer skin), its disc tangent to the triangle hit (the normal turned
outward), its top ``raise_mm`` above it: on a cylinder mesh this is the parametric placement up to
the facets' angle.

The surface under the marker is checked along its ring's rim (``RIM_SAMPLES`` rays cast back
along the normal): the part may not rise above the disc's plane there (a rib or an inside corner
would pierce the marker) by more than ``raise_mm``, nor fall away by more than ``MAX_DROP`` of the
ring's radius (a step or an edge: a marker is mounted flat; a cylinder's curvature falls 0.26 mm
under a 12.5 mm ring on 300 mm); the deepest drop is returned so the marker's base can reach down
to the part (it never floats). Pure numpy.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from dockfactory.core.layout import RING_EXTRA_MM, Marker, place_marker
from dockfactory.core.mesh_base import MeshError, TriMesh

RIM_SAMPLES = 24
EPS = 1e-12
MAX_DROP = 0.25   # the part may fall away under a ring by at most this fraction of its radius


def ray_hits(corners: np.ndarray, origin, direction) -> tuple[np.ndarray, np.ndarray]:
    """(t (K,), triangle index (K,)) of every triangle of ``corners`` (M, 3, 3) the ray
    origin + t direction (t > 0) meets (Moller-Trumbore, both faces), in no order."""
    o, d = np.asarray(origin, dtype=np.float64), np.asarray(direction, dtype=np.float64)
    v0, e1, e2 = corners[:, 0], corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > EPS
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = o - v0
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ d) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (u >= -1e-9) & (v >= -1e-9) & (u + v <= 1.0 + 1e-9) & (t > 1e-9)
    return t[hit], np.nonzero(hit)[0]


def face_normal(corners: np.ndarray, i: int) -> np.ndarray:
    """Unit normal of triangle ``i`` of ``corners`` (its winding's)."""
    n = np.cross(corners[i, 1] - corners[i, 0], corners[i, 2] - corners[i, 0])
    return n / max(float(np.linalg.norm(n)), EPS)


def _rim_heights(corners, centre, normal, radius: float) -> np.ndarray:
    """Height (mm, + above the tangent plane at ``centre``) of the part at RIM_SAMPLES points of a
    circle of ``radius`` in that plane, each the outermost surface met by a ray cast back along
    -``normal`` from well above; -inf where the ray meets nothing (the marker overhangs an edge)."""
    a = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(normal, a)
    above = 10.0 * radius
    out = []
    for ang in np.linspace(0.0, 2 * np.pi, RIM_SAMPLES, endpoint=False):
        start = centre + radius * (np.cos(ang) * a + np.sin(ang) * b) + above * normal
        t, _ = ray_hits(corners, start, -normal)
        out.append(above - t.min() if len(t) else -np.inf)
    return np.array(out)


def place_on_mesh(mesh: TriMesh, section: str, index: int, s_mm: float, phi_deg: float,
                  diameter_mm: float, raise_mm: float, where: str) -> tuple[Marker, float]:
    """(marker, drop mm): the marker of layout coordinate (``s_mm``, ``phi_deg``) on ``mesh`` (its
    section frame, mm) and how far the part drops below its disc's plane under its ring's rim.
    MeshError naming ``where`` and the marker when its ray meets no surface, the ring overhangs
    an edge, or the part rises into the marker."""
    corners = mesh.corners()
    phi = np.radians(phi_deg)
    direction = np.array([0.0, np.sin(phi), np.cos(phi)])
    origin = np.array([-s_mm if section == "A" else s_mm, 0.0, 0.0])
    name = f"{where}: marker {section}{index} (s {s_mm:g} mm, phi {phi_deg:g} deg)"
    t, tri = ray_hits(corners, origin, direction)
    if not len(t):
        raise MeshError(f"{name}: its ray from the section's axis meets no surface of the part")
    k = int(np.argmax(t))
    surface = origin + t[k] * direction
    normal = face_normal(corners, int(tri[k]))
    normal = normal if normal @ direction > 0 else -normal
    heights = _rim_heights(corners, surface, normal, diameter_mm / 2.0 + RING_EXTRA_MM)
    if not np.all(np.isfinite(heights)):
        raise MeshError(f"{name}: its ring overhangs an edge of the part: move it or use a smaller marker")
    if -heights.min() > MAX_DROP * (diameter_mm / 2.0 + RING_EXTRA_MM):
        raise MeshError(f"{name}: the part falls {-heights.min():.2f} mm away under its ring (a step or an edge; "
                        f"at most {MAX_DROP:g} of the ring's radius): a marker stands flat on the part; move it")
    if heights.max() > raise_mm:
        raise MeshError(f"{name}: the part rises {heights.max():.2f} mm above its disc's plane within its ring "
                        f"(more than raise_mm {raise_mm:g}): a rib or a corner would pierce it; move it")
    centre = surface + raise_mm * normal
    marker = Marker(id=f"{section}{index}", section=section, index=index,
                    center_mm=tuple(float(v) for v in centre), normal=tuple(float(v) for v in normal),
                    diameter_mm=float(diameter_mm))
    return marker, float(max(0.0, -heights.min()))


def _section_mesh(sections, section: str) -> TriMesh | None:
    v, t = (getattr(sections, f"mesh_{section.lower()}_{k}") for k in ("vertices", "triangles"))
    return TriMesh(np.array(v, dtype=np.float64), np.array(t, dtype=np.int64)) if t else None


@lru_cache(maxsize=32)
def layout_on_parts(sections, markers) -> tuple[tuple[Marker, ...], dict[str, float]]:
    """(markers of A then B, {section: the largest drop under a ring, mm}) of a config's
    [sections] and [markers] tables: a section with a part mesh (``mesh_a_vertices`` ...) gets
    its markers cast onto it (:func:`place_on_mesh`), the others the cylinder's
    (:func:`dockfactory.core.layout.place_marker`; no drop entry). MeshError names the marker."""
    out, drops = [], {}
    for section, pattern in (("A", markers.layout_a), ("B", markers.layout_b)):
        mesh = _section_mesh(sections, section)
        for i, (s_mm, phi) in enumerate(pattern):
            if mesh is None:
                out.append(place_marker(section, i, s_mm, phi, sections.radius_mm, markers.diameter_mm,
                                        markers.raise_mm))
                continue
            marker, drop = place_on_mesh(mesh, section, i, s_mm, phi, markers.diameter_mm, markers.raise_mm,
                                         f"[sections] mesh_{section.lower()}")
            out.append(marker)
            drops[section] = max(drops.get(section, 0.0), drop)
    return tuple(out), drops
