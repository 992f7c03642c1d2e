"""glTF 2.0 meshes (``.glb``, or ``.gltf`` with its buffers embedded as data URIs or in files
beside it) in and out, for :mod:`dockfactory.core.mesh_files`.

Read: every triangle primitive (mode 4) of every mesh the default scene's nodes reach, its
POSITION accessor and its indices (or none: consecutive triangles), each node's transform
(``matrix``, or ``translation`` / ``rotation`` / ``scale``) applied through the hierarchy. Other
primitive modes, sparse accessors and buffer files outside the glTF's folder are refused. glTF's
unit is the metre (its specification); the caller scales. Materials: each primitive's
``pbrMetallicRoughness`` base colour factor (linear RGB; alpha and textures left out), metallic
and roughness factors, at glTF's defaults where unstated (a primitive without a material takes
glTF's default material); a file with no ``materials`` has none.
"""
from __future__ import annotations

import base64
import json
import struct
from pathlib import Path

import numpy as np

from dockfactory.core.mesh_base import MeshError, TriMesh

GLB_MAGIC, GLB_JSON, GLB_BIN = 0x46546C67, 0x4E4F534A, 0x004E4942
COMPONENTS = {5120: "i1", 5121: "u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
WIDTH = {"SCALAR": 1, "VEC3": 3}


def _glb_chunks(data: bytes, where: str) -> tuple[dict, bytes | None]:
    magic, version, _ = struct.unpack_from("<III", data, 0)
    if magic != GLB_MAGIC or version != 2:
        raise MeshError(f"{where}: not a glTF 2.0 binary (.glb)")
    pos, doc, binary = 12, None, None
    while pos + 8 <= len(data):
        length, kind = struct.unpack_from("<II", data, pos)
        chunk = data[pos + 8:pos + 8 + length]
        if kind == GLB_JSON:
            doc = json.loads(chunk.decode("utf-8"))
        elif kind == GLB_BIN and binary is None:
            binary = chunk
        pos += 8 + length
    if doc is None:
        raise MeshError(f"{where}: the .glb has no JSON chunk")
    return doc, binary


def _buffer(doc: dict, i: int, path: Path, glb_bin: bytes | None) -> bytes:
    uri = doc["buffers"][i].get("uri")
    if uri is None:
        if glb_bin is None:
            raise MeshError(f"{path}: buffer {i} has no data")
        return glb_bin
    if uri.startswith("data:"):
        return base64.b64decode(uri.split(",", 1)[1])
    rel = Path(uri)
    if rel.is_absolute() or ".." in rel.parts:
        raise MeshError(f"{path}: buffer {i} points outside the glTF's folder ({uri!r})")
    try:
        return (path.parent / rel).read_bytes()
    except OSError:
        raise MeshError(f"{path}: buffer {i}: cannot read {uri!r} beside it") from None


def _accessor(doc: dict, i: int, buffers, where: str) -> np.ndarray:
    acc = doc["accessors"][i]
    if "sparse" in acc or acc.get("normalized") or acc["type"] not in WIDTH or acc["componentType"] not in COMPONENTS:
        raise MeshError(f"{where}: accessor {i} ({acc['type']}, component {acc['componentType']}) is not a plain "
                        "VEC3 / SCALAR one")
    view = doc["bufferViews"][acc["bufferView"]]
    dtype, width, count = np.dtype(COMPONENTS[acc["componentType"]]), WIDTH[acc["type"]], acc["count"]
    raw = buffers(view["buffer"])
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    stride = view.get("byteStride") or dtype.itemsize * width
    rows = np.ndarray((count, width), dtype=dtype, buffer=raw, offset=start, strides=(stride, dtype.itemsize))
    return rows.astype(np.float64 if acc["type"] == "VEC3" else np.int64)


def _local(node: dict) -> np.ndarray:
    """The node's 4 x 4 transform (glTF's column-major matrix, or T R S)."""
    if "matrix" in node:
        return np.array(node["matrix"], dtype=np.float64).reshape(4, 4).T
    x, y, z, w = node.get("rotation", (0.0, 0.0, 0.0, 1.0))
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    m = np.eye(4)
    m[:3, :3] = r * np.asarray(node.get("scale", (1.0, 1.0, 1.0)), dtype=np.float64)
    m[:3, 3] = node.get("translation", (0.0, 0.0, 0.0))
    return m


def _primitives(doc: dict, where: str):
    """(world transform, primitive) of every primitive the default scene reaches."""
    scene = doc.get("scenes", [{"nodes": list(range(len(doc.get("nodes", []))))}])[doc.get("scene", 0)]
    stack = [(n, np.eye(4)) for n in scene.get("nodes", [])]
    while stack:
        i, parent = stack.pop()
        node = doc["nodes"][i]
        world = parent @ _local(node)
        stack += [(c, world) for c in node.get("children", [])]
        for prim in doc["meshes"][node["mesh"]]["primitives"] if "mesh" in node else ():
            if prim.get("mode", 4) != 4:
                raise MeshError(f"{where}: a primitive of mode {prim['mode']}: only triangles (mode 4) are read")
            yield world, prim


def _material_row(doc: dict, index) -> tuple[float, ...]:
    """(red, green, blue, metallic, roughness) of material ``index`` (None: glTF's default)."""
    pbr = doc["materials"][index].get("pbrMetallicRoughness", {}) if index is not None else {}
    r, g, b = [float(v) for v in pbr.get("baseColorFactor", (1.0, 1.0, 1.0, 1.0))[:3]]
    return r, g, b, float(pbr.get("metallicFactor", 1.0)), float(pbr.get("roughnessFactor", 1.0))


def _read_doc(doc: dict, path: Path, glb_bin: bytes | None, where: str):
    cache: dict[int, bytes] = {}

    def buffers(i: int) -> bytes:
        if i not in cache:
            cache[i] = _buffer(doc, i, path, glb_bin)
        return cache[i]
    verts, tris, mats, rows, base = [], [], [], {}, 0
    for world, prim in _primitives(doc, where):
        pos = _accessor(doc, prim["attributes"]["POSITION"], buffers, where)
        idx = (_accessor(doc, prim["indices"], buffers, where).ravel() if "indices" in prim
               else np.arange(len(pos)))
        verts.append(pos @ world[:3, :3].T + world[:3, 3])
        tris.append(idx.reshape(-1, 3) + base)
        row = rows.setdefault(prim.get("material"), len(rows))
        mats.append(np.full(len(tris[-1]), row, dtype=np.int64))
        base += len(pos)
    materials = [_material_row(doc, i) for i in rows] if doc.get("materials") else None
    return verts, tris, materials, mats


def read_gltf(data: bytes, path: Path):
    """(vertices (N, 3) metres, triangles (M, 3), materials (K, 5) rows of
    ``mesh_base.MATERIAL_KEYS`` or None, triangle_materials (M,) or None) of a .glb or .gltf
    file's bytes ``data``."""
    where = str(path)
    try:
        doc, glb_bin = _glb_chunks(data, where) if data[:4] == b"glTF" else (json.loads(data.decode("utf-8")), None)
        verts, tris, materials, mats = _read_doc(doc, path, glb_bin, where)
    except MeshError:
        raise
    except (KeyError, IndexError, TypeError, ValueError, struct.error, UnicodeDecodeError) as exc:
        raise MeshError(f"{where}: not a usable glTF 2.0 file ({type(exc).__name__}: {exc})") from None
    if not verts:
        raise MeshError(f"{where}: the glTF's scene holds no mesh")
    if materials is None:
        return np.concatenate(verts), np.concatenate(tris), None, None
    return np.concatenate(verts), np.concatenate(tris), np.array(materials), np.concatenate(mats)


def _primitive_groups(mesh: TriMesh) -> list[np.ndarray]:
    """The triangles of each material in turn (all of them when the mesh has none)."""
    if mesh.materials is None:
        return [mesh.triangles]
    return [mesh.triangles[mesh.triangle_materials == k] for k in range(len(mesh.materials))]


def _material_doc(row) -> dict:
    r, g, b, metallic, roughness = (float(v) for v in row)
    return {"pbrMetallicRoughness": {"baseColorFactor": [r, g, b, 1.0], "metallicFactor": metallic,
                                     "roughnessFactor": roughness}}


def glb_bytes(mesh: TriMesh, metres_per_unit: float = 1e-3) -> bytes:
    """``mesh`` (its units times ``metres_per_unit`` are metres) as a .glb: one node, one mesh,
    float32 positions and uint32 indices, a primitive per material (with its material) when the
    mesh has materials."""
    pos = (mesh.vertices * metres_per_unit).astype("<f4")
    groups = [g.astype("<u4") for g in _primitive_groups(mesh)]
    binary = pos.tobytes() + b"".join(g.tobytes() for g in groups)
    views, accessors, prims, offset = [{"buffer": 0, "byteOffset": 0, "byteLength": pos.nbytes}], [
        {"bufferView": 0, "componentType": 5126, "count": len(pos), "type": "VEC3",
         "min": pos.min(axis=0).tolist(), "max": pos.max(axis=0).tolist()}], [], pos.nbytes
    for k, g in enumerate(groups):
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": g.nbytes})
        accessors.append({"bufferView": k + 1, "componentType": 5125, "count": g.size, "type": "SCALAR"})
        prims.append({"attributes": {"POSITION": 0}, "indices": k + 1,
                      **({"material": k} if mesh.materials is not None else {})})
        offset += g.nbytes
    doc = {"asset": {"version": "2.0", "generator": "dockfactory"}, "scene": 0, "scenes": [{"nodes": [0]}],
           "nodes": [{"mesh": 0}], "meshes": [{"primitives": prims}], "buffers": [{"byteLength": len(binary)}],
           "bufferViews": views, "accessors": accessors}
    if mesh.materials is not None:
        doc["materials"] = [_material_doc(row) for row in mesh.materials]
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    binary += b"\0" * (-len(binary) % 4)
    body = (struct.pack("<II", len(text), GLB_JSON) + text + struct.pack("<II", len(binary), GLB_BIN) + binary)
    return struct.pack("<III", GLB_MAGIC, 2, 12 + len(body)) + body
