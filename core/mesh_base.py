"""A triangle mesh in memory (:class:`TriMesh`), its checks and its one-line error; the readers
and writers are :mod:`dockfactory.core.mesh_files`, the marker placement
:mod:`dockfactory.core.mesh_markers`."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dockfactory.core.errors import DockfactoryError

MAX_TRIANGLES = 200_000


class MeshError(DockfactoryError):
    """A mesh file that cannot be used; the message names the file and the problem."""


MATERIAL_KEYS = ("red", "green", "blue", "metallic", "roughness")   # a material's row: linear base colour, PBR factors


@dataclass(frozen=True, eq=False)
class TriMesh:
    """``vertices`` (N, 3) float64 mm, ``triangles`` (M, 3) int64 indices into them; the file's
    materials when it has them: ``materials`` (K, 5) float64 rows of MATERIAL_KEYS in [0, 1] and
    ``triangle_materials`` (M,) int64 indices into them (both None: no materials)."""
    vertices: np.ndarray
    triangles: np.ndarray
    materials: np.ndarray | None = None
    triangle_materials: np.ndarray | None = None

    def corners(self) -> np.ndarray:
        """(M, 3, 3) mm: each triangle's three vertices."""
        return self.vertices[self.triangles]


def checked_materials(materials, triangle_materials, n_triangles: int, where: str):
    """(materials (K, 5), triangle_materials (M,)) as arrays, or (None, None) when ``materials`` is
    None; MeshError (naming ``where``) when a value is outside [0, 1] or not finite, or a triangle
    names a material the mesh does not have."""
    if materials is None:
        return None, None
    mats = np.asarray(materials, dtype=np.float64)
    idx = np.asarray(triangle_materials, dtype=np.int64).reshape(-1)
    if mats.ndim != 2 or mats.shape[1] != len(MATERIAL_KEYS):
        raise MeshError(f"{where}: a material is not {len(MATERIAL_KEYS)} numbers ({', '.join(MATERIAL_KEYS)})")
    if len(mats) == 0 or not np.all(np.isfinite(mats)) or mats.min() < 0.0 or mats.max() > 1.0:
        raise MeshError(f"{where}: a material's colour, metallic or roughness is not a number in [0, 1]")
    if len(idx) != n_triangles or idx.min() < 0 or idx.max() >= len(mats):
        raise MeshError(f"{where}: the triangles' materials do not index the {len(mats)} materials")
    return mats, idx


def checked_mesh(vertices, triangles, where: str, materials=None, triangle_materials=None) -> TriMesh:
    """A TriMesh of ``vertices`` and ``triangles`` (and the materials, :func:`checked_materials`);
    MeshError (naming ``where``) when it is empty, too large, not finite or indexes a vertex or a
    material it does not have."""
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if len(t) == 0:
        raise MeshError(f"{where}: no triangles")
    if len(t) > MAX_TRIANGLES:
        raise MeshError(f"{where}: {len(t)} triangles, more than {MAX_TRIANGLES}: decimate the part first")
    if not np.all(np.isfinite(v)):
        raise MeshError(f"{where}: a vertex coordinate is not a finite number")
    if t.min() < 0 or t.max() >= len(v):
        raise MeshError(f"{where}: a triangle names vertex {int(t.max() if t.max() >= len(v) else t.min())}, "
                        f"but there are {len(v)}")
    return TriMesh(v, t, *checked_materials(materials, triangle_materials, len(t), where))


def fan(polygon: list[int]) -> list[list[int]]:
    """A polygon's vertex indices split into triangles around its first vertex."""
    return [[polygon[0], polygon[i], polygon[i + 1]] for i in range(1, len(polygon) - 1)]
