"""The shipped example part (configs/parts/, written by ``python -m dockfactory.generator.example_parts
configs/parts``): an octagonal section, a non-circular part a user might bring from CAD, with a
flange at its docking face and a raised rib around it, as a triangle mesh in its section's frame
(mm). A's runs from its docking face toward -X, B's toward +X. Prisms along X of convex polygons
in (Y, Z), overlapping where they meet (the renderer and the ray casts see their union).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from dockfactory.core.mesh_base import TriMesh
from dockfactory.core.mesh_files import write_mesh

CIRCUMRADIUS_MM = 300.0   # the octagon's corners; its faces are 277 mm from the axis
LENGTH_MM = 900.0
FLANGE_MM = (20.0, 15.0)   # axial width, how far it stands out
RIB_MM = (260.0, 8.0, 10.0)   # axial position of its middle, width, height
FILES = {"A": "octagon_a.glb", "B": "octagon_b.stl"}


def octagon(circumradius: float) -> np.ndarray:
    """(8, 2) (y, z) corners of an octagon with a face toward +Z (the camera side)."""
    a = np.radians(22.5 + 45.0 * np.arange(8))
    return circumradius * np.stack([np.sin(a), np.cos(a)], axis=1)


def prism_x(polygon: np.ndarray, x0: float, x1: float) -> TriMesh:
    """The closed prism of a convex (y, z) ``polygon`` (K, 2) between x0 and x1 (mm)."""
    k = len(polygon)
    verts = np.vstack([np.column_stack([np.full(k, x), polygon]) for x in (x0, x1)])
    sides = [t for i in range(k) for t in ([i, (i + 1) % k, k + (i + 1) % k], [i, k + (i + 1) % k, k + i])]
    caps = [[0, i + 1, i] for i in range(1, k - 1)] + [[k, k + i, k + i + 1] for i in range(1, k - 1)]
    return TriMesh(verts, np.array(sides + caps))


def joined(parts: list[TriMesh]) -> TriMesh:
    """One mesh of ``parts`` (their triangles side by side)."""
    base = np.cumsum([0] + [len(p.vertices) for p in parts[:-1]])
    return TriMesh(np.vstack([p.vertices for p in parts]), np.vstack([p.triangles + b for p, b in zip(parts, base)]))


def octagon_section(section: str) -> TriMesh:
    """Section ``section`` ("A" or "B") of the example part in its frame (mm)."""
    sign = -1.0 if section == "A" else 1.0
    apothem_scale = 1.0 / np.cos(np.radians(22.5))   # circumradius per mm of face distance
    width, stand = FLANGE_MM
    rib_x, rib_w, rib_h = RIB_MM
    pieces = [(CIRCUMRADIUS_MM, 0.0, LENGTH_MM), (CIRCUMRADIUS_MM + stand * apothem_scale, 0.0, width),
              (CIRCUMRADIUS_MM + rib_h * apothem_scale, rib_x - rib_w / 2, rib_x + rib_w / 2)]
    return joined([prism_x(octagon(r), *sorted((sign * a, sign * b))) for r, a, b in pieces])


def write_example_parts(folder) -> list[Path]:
    """Write both sections' files (FILES) into ``folder``; their paths."""
    folder = Path(folder)
    out = []
    for section, name in FILES.items():
        write_mesh(octagon_section(section), folder / name)
        out.append(folder / name)
    return out


if __name__ == "__main__":
    for path in write_example_parts(sys.argv[1] if len(sys.argv) > 1 else "configs/parts"):
        print(path)
