"""PLY meshes (ASCII or binary little-endian) in and out, for :mod:`dockfactory.core.mesh_files`:
the ``vertex`` element's x, y, z and the ``face`` element's index list (``vertex_indices`` or
``vertex_index``); other elements and properties are read past. Big-endian PLY is refused."""
from __future__ import annotations

import numpy as np

from dockfactory.core.mesh_base import MeshError, TriMesh, fan

PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
             "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
             "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def _header(data: bytes, where: str) -> tuple[str, list, int]:
    """(format, [(element, count, [(property, type or (count type, item type))])], body offset)."""
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise MeshError(f"{where}: not a PLY file (no 'ply' ... 'end_header')")
    body = data.index(b"\n", end) + 1
    fmt, elements = None, []
    for line in data[:end].decode("ascii", errors="replace").splitlines()[1:]:
        w = line.split()
        if not w or w[0] in ("comment", "obj_info"):
            continue
        try:
            if w[0] == "format":
                fmt = w[1]
            elif w[0] == "element":
                elements.append((w[1], int(w[2]), []))
            elif w[0] == "property" and w[1] == "list":
                elements[-1][2].append((w[4], (PLY_TYPES[w[2]], PLY_TYPES[w[3]])))
            elif w[0] == "property":
                elements[-1][2].append((w[2], PLY_TYPES[w[1]]))
        except (IndexError, KeyError, ValueError):
            raise MeshError(f"{where}: PLY header line {line.strip()!r} is not understood") from None
    if fmt not in ("ascii", "binary_little_endian"):
        raise MeshError(f"{where}: PLY format {fmt!r}: only ascii and binary_little_endian are read")
    return fmt, elements, body


def _face_list(props: list, where: str) -> int:
    names = [n for n, _ in props]
    for key in ("vertex_indices", "vertex_index"):
        if key in names and isinstance(props[names.index(key)][1], tuple):
            return names.index(key)
    raise MeshError(f"{where}: the PLY face element has no vertex_indices list")


def _read_ascii(data: bytes, elements: list, body: int, where: str):
    tokens, pos, verts, tris = data[body:].split(), 0, None, []
    for name, count, props in elements:
        for _ in range(count):
            row = []
            for _, kind in props:
                n = int(tokens[pos]) if isinstance(kind, tuple) else 1
                pos += isinstance(kind, tuple)
                row.append([float(t) for t in tokens[pos:pos + n]] if isinstance(kind, tuple) else float(tokens[pos]))
                pos += n
            if name == "vertex":
                verts = [] if verts is None else verts
                verts.append([row[[p for p, _ in props].index(k)] for k in ("x", "y", "z")])
            elif name == "face":
                tris += fan([int(i) for i in row[_face_list(props, where)]])
    return np.array(verts or [], dtype=np.float64).reshape(-1, 3), np.array(tris, dtype=np.int64).reshape(-1, 3)


def _read_binary(data: bytes, elements: list, body: int, where: str):
    pos, verts, tris = body, np.zeros((0, 3)), []
    for name, count, props in elements:
        if all(not isinstance(k, tuple) for _, k in props):
            rec = np.frombuffer(data, dtype=np.dtype([(n, "<" + k) for n, k in props]), count=count, offset=pos)
            pos += rec.nbytes
            if name == "vertex":
                verts = np.stack([rec[k].astype(np.float64) for k in ("x", "y", "z")], axis=1)
            continue
        if name != "face" or len(props) != 1:
            raise MeshError(f"{where}: PLY element {name!r} with list properties: only a face list is read")
        count_t, item_t = (np.dtype("<" + t) for t in props[0][1])
        for _ in range(count):
            n = int(np.frombuffer(data, count_t, 1, pos)[0])
            pos += count_t.itemsize
            tris += fan(np.frombuffer(data, item_t, n, pos).astype(np.int64).tolist())
            pos += n * item_t.itemsize
    return verts, np.array(tris, dtype=np.int64).reshape(-1, 3)


def read_ply(data: bytes, where: str) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (N, 3), triangles (M, 3)) of PLY file bytes ``data``; MeshError naming ``where``."""
    fmt, elements, body = _header(data, where)
    if not any(n == "vertex" for n, _, _ in elements) or not any(n == "face" for n, _, _ in elements):
        raise MeshError(f"{where}: a PLY mesh needs a vertex and a face element")
    try:
        reader = _read_ascii if fmt == "ascii" else _read_binary
        return reader(data, elements, body, where)
    except (IndexError, ValueError, KeyError):
        raise MeshError(f"{where}: the PLY body is shorter than its header says, or not numbers") from None


def ply_text(mesh: TriMesh) -> str:
    """``mesh`` as ASCII PLY."""
    head = (f"ply\nformat ascii 1.0\ncomment dockfactory\nelement vertex {len(mesh.vertices)}\n"
            "property double x\nproperty double y\nproperty double z\n"
            f"element face {len(mesh.triangles)}\nproperty list uchar int vertex_indices\nend_header\n")
    return (head + "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in mesh.vertices.tolist())
            + "".join(f"3 {a} {b} {c}\n" for a, b, c in mesh.triangles.tolist()))
