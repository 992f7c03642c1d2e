"""Marker layout: where the coloured markers sit on sections A and B (pure, no bpy).

A marker is placed by (axial offset from the docking face, angle on the cylinder):
- axial offset ``s_mm`` > 0 is the distance from the seam along the section's axis, so a marker
  of A sits at x = -s and one of B at x = +s in its own section frame;
- angle ``phi_deg`` is measured on the circumference from +Z (the camera side) toward +Y (up).
The marker centre is the centre of the top face of its coloured disc, which is raised
``raise_mm`` above the cylinder along the surface normal.

The default layouts are irregular on purpose: every marker has a distinct set of distances to
the others, so a solver can tell which marker is which from the image alone.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dockfactory.core.names import CLASS_NAMES, SECTIONS  # noqa: F401  (re-exported)

OUTLINE_POINTS = 256  # points on a marker disc's edge (labels, solver outline)

# (s_mm, phi_deg): irregular patterns near the seam on the camera-facing side. The angular span
# (about +-60 deg) matters: at 0.1 px of centre noise the Cramer-Rao bound of X is 0.31 mm RMS
# with it, 0.99 mm with +-36 deg (the depth spread pins the sections' rotation about Y, whose
# error moves the axis 300 mm below the markers); see bench/layout_bound.py.
DEFAULT_LAYOUT_A = ((50.0, -53.0), (100.0, -32.0), (62.0, -7.0), (130.0, 10.0),
                    (47.0, 24.0), (88.0, 44.0), (150.0, -61.0))
DEFAULT_LAYOUT_B = ((52.0, -42.0), (108.0, -19.0), (68.0, 3.0), (140.0, 29.0),
                    (48.0, 41.0), (96.0, 60.0), (158.0, -56.0))
RING_EXTRA_MM = 2.5  # the ring around each coloured disc
RING_TOP_MM = -0.05  # the ring base's top face, this far along the normal from the disc's top face
# the meshes' polygons (blender_scenes.meshes): a disc, a ring base, a section body about its axis;
# the coverage computed from the geometry (generator.coverage_geometry) follows the same polygons
DISC_SEGMENTS, RING_SEGMENTS, SECTION_FACETS = 96, 64, 256
RING_BASE_DEPTH_MM = 2.5  # the ring base (a puck under the disc) reaches this far below the disc's top face
BASE_EMBED_MM = 0.05      # how far a marker's base reaches into the section, where it stands highest over it
# A marker's physical form ([markers] form): a raised puck (the disc on a dark cylinder whose side
# shows at a slant) or a flat printed plate (the disc printed on a thin dark plate, raise_mm thick,
# at most FLAT_MAX_RAISE_MM); both have a planar disc, so the labels are exact for either.
MARKER_FORMS = ("puck", "flat")
FLAT_MAX_RAISE_MM = 0.5
FORM_RAISE_MM = {"puck": 1.0, "flat": 0.1}   # each form's raise_mm when a config leaves it unset
# Grey reflectance range of the ring, per design: a dark ring leaves a Bayer sensor a red disc's
# edge in its red samples alone; a white ring shows it in the green and blue samples too.
RING_REFLECTANCE = {"dark": (0.01, 0.05), "white": (0.70, 0.85)}
RING_DESIGNS = (*RING_REFLECTANCE, "mixed")   # mixed: each frame dark or white, half and half (detector training)


def ring_reflectance(design: str, u: float) -> float:
    """The ring's grey reflectance of ``design`` (one of RING_DESIGNS) from one uniform draw ``u`` in
    [0, 1): the design's range at ``u``; "mixed" takes the dark range for u < 0.5 and the white one
    above, each at its own uniform position, so every design spends the same single draw."""
    if design == "mixed":
        design, u = ("dark", 2.0 * u) if u < 0.5 else ("white", 2.0 * u - 1.0)
    lo, hi = RING_REFLECTANCE[design]
    return lo + u * (hi - lo)


def base_depth_mm(form: str, raise_mm: float, diameter_mm: float, section_radius_mm: float) -> float:
    """How far (mm) a marker's base reaches below its disc's top face, for ``form`` (MARKER_FORMS):
    down to the section where the base stands highest over it (its rim across the cylinder, the
    sagitta r^2 / 2R higher than at its centre line) plus BASE_EMBED_MM, so it never floats; a
    puck at least RING_BASE_DEPTH_MM. ValueError for an unknown form."""
    if form not in MARKER_FORMS:
        raise ValueError(f"marker form must be one of {MARKER_FORMS}, got {form!r}")
    r = diameter_mm / 2.0 + RING_EXTRA_MM
    sagitta = section_radius_mm - float(np.sqrt(max(section_radius_mm ** 2 - r ** 2, 0.0)))
    reach = raise_mm + sagitta + BASE_EMBED_MM
    return max(RING_BASE_DEPTH_MM, reach) if form == "puck" else reach


SECTION_PASS_INDEX = {"A": 201, "B": 202}  # index pass value of each section's body and flange


@dataclass(frozen=True)
class Marker:
    """One marker. ``center_mm`` and ``normal`` are in its section's frame."""

    id: str                      # stable id, e.g. "A3"
    section: str                 # "A" or "B"
    index: int                   # 0-based index within its section
    center_mm: tuple[float, float, float]
    normal: tuple[float, float, float]
    diameter_mm: float

    @property
    def class_id(self) -> int:
        return SECTIONS.index(self.section)

    @property
    def pass_index(self) -> int:
        """Object index written into the render's index pass (1-based, unique per marker)."""
        return 1 + self.index + 100 * self.class_id


def place_marker(section: str, index: int, s_mm: float, phi_deg: float, radius_mm: float,
                 diameter_mm: float, raise_mm: float) -> Marker:
    """Marker on a cylinder of ``radius_mm`` whose axis is X; see the module docstring."""
    if section not in SECTIONS:
        raise ValueError(f"section must be one of {SECTIONS}, got {section!r}")
    phi = np.radians(phi_deg)
    normal = np.array([0.0, np.sin(phi), np.cos(phi)])
    x = -s_mm if section == "A" else s_mm
    center = np.array([x, 0.0, 0.0]) + (radius_mm + raise_mm) * normal
    return Marker(id=f"{section}{index}", section=section, index=index,
                  center_mm=tuple(float(v) for v in center),
                  normal=tuple(float(v) for v in normal), diameter_mm=float(diameter_mm))


def build_layout(pattern_a, pattern_b, radius_mm: float, diameter_mm: float,
                 raise_mm: float = 1.0) -> tuple[Marker, ...]:
    """All markers of A then B from (s_mm, phi_deg) patterns."""
    markers = []
    for section, pattern in (("A", pattern_a), ("B", pattern_b)):
        for i, (s, phi) in enumerate(pattern):
            markers.append(place_marker(section, i, s, phi, radius_mm, diameter_mm, raise_mm))
    return tuple(markers)


def marker_points(markers, section: str | None = None) -> np.ndarray:
    """Centres (N, 3) mm in each marker's section frame, optionally of one section only."""
    return np.array([m.center_mm for m in markers if section is None or m.section == section],
                    dtype=np.float64).reshape(-1, 3)


def layout_problems(markers, min_spacing_factor: float = 1.5,
                    signature_tol_mm: float = 2.0) -> list[str]:
    """Reasons a layout is unusable (empty when fine).

    Checks per section: at least 6 markers, discs do not overlap (centre spacing at least
    ``min_spacing_factor`` diameters), markers are not all coplanar, and every marker's sorted
    distances to the others differ from every other marker's by more than ``signature_tol_mm``
    somewhere (no symmetry that would make two markers interchangeable).
    """
    problems = []
    for section in SECTIONS:
        ms = [m for m in markers if m.section == section]
        if len(ms) < 6:
            problems.append(f"section {section}: {len(ms)} markers, at least 6 needed")
            continue
        p = marker_points(ms)
        d = np.linalg.norm(p[:, None] - p[None], axis=-1)
        diam = max(m.diameter_mm for m in ms)
        close = np.argwhere(np.triu(d < min_spacing_factor * diam, 1))
        for i, j in close:
            problems.append(f"section {section}: markers {ms[i].id} and {ms[j].id} are "
                            f"{d[i, j]:.1f} mm apart (< {min_spacing_factor} diameters)")
        centred = p - p.mean(axis=0)
        if np.linalg.svd(centred, compute_uv=False)[-1] < 1e-6 * max(1.0, np.abs(centred).max()):
            problems.append(f"section {section}: markers are coplanar")
        sig = np.sort(d, axis=1)
        for i in range(len(ms)):
            for j in range(i + 1, len(ms)):
                if np.max(np.abs(sig[i] - sig[j])) <= signature_tol_mm:
                    problems.append(f"section {section}: markers {ms[i].id} and {ms[j].id} have "
                                    f"the same distance signature (symmetric layout)")
    return problems


def marker_basis(normal) -> np.ndarray:
    """(3, 3) rotation whose columns are the marker's x, y and its unit ``normal`` (+Z): the frame
    its meshes are built in (blender_scenes.scene_builder) and its outline drawn in."""
    n = np.asarray(normal, dtype=np.float64)
    x = np.cross([1.0, 0.0, 0.0], n) if abs(n[0]) < 0.9 else np.cross([0.0, 1.0, 0.0], n)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(n, x), n], axis=1)


def marker_outline(marker: Marker, n: int = OUTLINE_POINTS) -> np.ndarray:
    """Edge of the coloured disc (n, 3) mm in the marker's section frame."""
    basis = marker_basis(marker.normal)
    x, y = basis[:, 0], basis[:, 1]
    a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    r = marker.diameter_mm / 2.0
    return np.asarray(marker.center_mm) + r * (np.cos(a)[:, None] * x + np.sin(a)[:, None] * y)
