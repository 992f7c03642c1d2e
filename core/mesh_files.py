"""Triangle meshes in and out: glTF 2.0 (``.gltf``, ``.glb``), Wavefront OBJ, STL (binary or
ASCII) and PLY (ASCII or binary little-endian); a user's parts come in through these.

One in-memory form, :class:`TriMesh`: vertices (N, 3) float64 in mm and triangles (M, 3) int64
indices, and a glTF's materials (base colour, metallic, roughness per primitive: what
``[sections] materials = "file"`` renders); normals and texture coordinates are left out (the
face normals follow from the triangles), and so are OBJ's, STL's and PLY's colours. Units: glTF is in
metres by its specification; OBJ, STL and PLY carry none, so the caller states them
(``UNITS_MM``). A glTF's node transforms (matrix, or translation / rotation / scale) are applied
through the scene's hierarchy. Polygons of OBJ and PLY are split into triangles as fans.

Files are parsed as data, at most ``MAX_BYTES`` and ``MAX_TRIANGLES``; every problem is a
one-line MeshError naming the file and what is wrong. STEP has no reader here: convert it to
glTF or STL first (docs/configuration.md, "Your parts").
"""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from dockfactory.core.io import write_bytes_atomic
from dockfactory.core.mesh_base import MeshError, TriMesh, checked_mesh, fan
from dockfactory.core.mesh_gltf import glb_bytes, read_gltf
from dockfactory.core.mesh_ply import ply_text, read_ply
from dockfactory.core.user_files import check_regular_file

MAX_BYTES = 64 << 20
UNITS_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
SUFFIXES = (".glb", ".gltf", ".obj", ".stl", ".ply")


# ----------------------------------------------------------------------------- STL

def _read_stl(data: bytes, where: str) -> tuple[np.ndarray, np.ndarray]:
    if len(data) >= 84:
        n = struct.unpack_from("<I", data, 80)[0]
        if len(data) == 84 + 50 * n:
            rec = np.frombuffer(data, dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]),
                                count=n, offset=84)
            return rec["v"].reshape(-1, 3).astype(np.float64), np.arange(3 * n).reshape(-1, 3)
    try:
        words = data.decode("ascii").split()
    except UnicodeDecodeError:
        raise MeshError(f"{where}: neither a binary STL (its size does not match its triangle count) "
                        "nor an ASCII one") from None
    if not words or words[0] != "solid":
        raise MeshError(f"{where}: not an STL file (no 'solid' and no binary triangle count)")
    try:
        verts = [[float(words[i + 1]), float(words[i + 2]), float(words[i + 3])]
                 for i, w in enumerate(words) if w == "vertex"]
    except (ValueError, IndexError):
        raise MeshError(f"{where}: a 'vertex' line of the ASCII STL is not three numbers") from None
    if len(verts) % 3:
        raise MeshError(f"{where}: {len(verts)} vertices, not three per facet")
    return np.array(verts).reshape(-1, 3), np.arange(len(verts)).reshape(-1, 3)


def stl_bytes(mesh: TriMesh) -> bytes:
    """``mesh`` as a binary STL (float32, the face normals computed)."""
    c = mesh.corners()
    n = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    rec = np.zeros(len(c), dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]))
    rec["n"], rec["v"] = n, c
    return b"dockfactory binary STL".ljust(80, b" ") + struct.pack("<I", len(c)) + rec.tobytes()


# ----------------------------------------------------------------------------- OBJ

def _obj_index(token: str, count: int, where: str, line: int) -> int:
    try:
        i = int(token.split("/")[0])
    except ValueError:
        raise MeshError(f"{where}:{line}: face index {token!r} is not an integer") from None
    if i == 0:
        raise MeshError(f"{where}:{line}: face index 0 (OBJ counts from 1)")
    return i - 1 if i > 0 else count + i


def _read_obj(data: bytes, where: str) -> tuple[np.ndarray, np.ndarray]:
    verts, tris = [], []
    for line, text in enumerate(data.decode("utf-8", errors="replace").splitlines(), 1):
        parts = text.split()
        if not parts:
            continue
        if parts[0] == "v":
            try:
                verts.append([float(p) for p in parts[1:4]])
            except ValueError:
                raise MeshError(f"{where}:{line}: a vertex is not three numbers") from None
            if len(verts[-1]) != 3:
                raise MeshError(f"{where}:{line}: a vertex is not three numbers")
        elif parts[0] == "f":
            if len(parts) < 4:
                raise MeshError(f"{where}:{line}: a face needs at least three vertices")
            tris += fan([_obj_index(p, len(verts), where, line) for p in parts[1:]])
    return np.array(verts, dtype=np.float64).reshape(-1, 3), np.array(tris, dtype=np.int64).reshape(-1, 3)


def obj_text(mesh: TriMesh) -> str:
    """``mesh`` as OBJ text (``v`` and ``f`` lines)."""
    return ("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in mesh.vertices.tolist())
            + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in mesh.triangles.tolist()))


# ----------------------------------------------------------------------------- in and out

def read_mesh(path, units: str = "mm") -> TriMesh:
    """The triangles of mesh file ``path`` (module docstring) in mm: OBJ, STL and PLY coordinates
    are in ``units`` (one of UNITS_MM), glTF's in metres whatever ``units`` says. One-line
    MeshError on a missing, oversized or unreadable file, an unknown suffix or unit."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise MeshError(f"{path}: expected a mesh file ({', '.join(SUFFIXES)}; STEP: convert it to glTF or STL)")
    if units not in UNITS_MM:
        raise MeshError(f"{path}: units {units!r}: expected one of {', '.join(UNITS_MM)}")
    check_regular_file(path, "mesh file")
    try:
        if path.stat().st_size > MAX_BYTES:
            raise MeshError(f"{path}: {path.stat().st_size} bytes, more than {MAX_BYTES}: decimate the part first")
        data = path.read_bytes()
    except FileNotFoundError:
        raise MeshError(f"{path}: mesh file not found") from None
    except OSError as exc:
        raise MeshError(f"{path}: cannot read the mesh file ({exc.strerror})") from None
    materials = triangle_materials = None
    if suffix in (".glb", ".gltf"):
        verts, tris, materials, triangle_materials = read_gltf(data, path)
        scale = 1000.0
    else:
        verts, tris = {".obj": _read_obj, ".stl": _read_stl, ".ply": read_ply}[suffix](data, str(path))
        scale = UNITS_MM[units]
    return checked_mesh(verts * scale, tris, str(path), materials, triangle_materials)


def mesh_bytes(mesh: TriMesh, suffix: str) -> bytes:
    """``mesh`` (mm) in the format of file suffix ``suffix``: .glb (metres, with the mesh's
    materials), .stl (binary), .obj and .ply (ASCII), the last three in mm (geometry only)."""
    if suffix == ".glb":
        return glb_bytes(mesh)
    if suffix == ".stl":
        return stl_bytes(mesh)
    if suffix in (".obj", ".ply"):
        return (obj_text(mesh) if suffix == ".obj" else ply_text(mesh)).encode()
    raise MeshError(f"{suffix}: the factory writes .glb, .stl, .obj and .ply")


def write_mesh(mesh: TriMesh, path) -> None:
    """Write ``mesh`` to ``path`` (atomically) in the format its suffix names (:func:`mesh_bytes`)."""
    path = Path(path)
    write_bytes_atomic(path, mesh_bytes(mesh, path.suffix.lower()))
