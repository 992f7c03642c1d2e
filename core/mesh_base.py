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


@dataclass(frozen=True, eq=False)
class TriMesh:
    """``vertices`` (N, 3) float64 mm, ``triangles`` (M, 3) int64 indices into them."""
    vertices: np.ndarray
    triangles: np.ndarray

    def corners(self) -> np.ndarray:
        """(M, 3, 3) mm: each triangle's three vertices."""
        return self.vertices[self.triangles]


def checked_mesh(vertices, triangles, where: str) -> TriMesh:
    """A TriMesh of ``vertices`` and ``triangles``; MeshError (naming ``where``) when it is empty,
    too large, not finite or indexes a vertex it does not have."""
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
    return TriMesh(v, t)


def fan(polygon: list[int]) -> list[list[int]]:
    """A polygon's vertex indices split into triangles around its first vertex."""
    return [[polygon[0], polygon[i], polygon[i + 1]] for i in range(1, len(polygon) - 1)]
