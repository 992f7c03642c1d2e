"""The BOP export's object models: each section's body and flange as a triangle mesh with vertex
normals, written as ASCII PLY (mm, section frame) in the layout bop_toolkit's ``inout.load_ply``
reads (``x y z nx ny nz`` per vertex, triangles as ``vertex_indices``).

A section is five surfaces of revolution about its X axis: the docking face (a disc at x = 0 of
radius R + flange height), the flange's rim (a cylinder), the flange's back (an annulus at the
flange width), the body (a cylinder of radius R) and the far end (a disc at the section length),
extending toward -X for A and +X for B. Each surface has its own vertices, so a vertex on a sharp
edge appears once per surface with that surface's normal: radial on the cylinders, +-X on the
discs and the annulus (outward, away from the solid); the triangles wind counter-clockwise seen
from outside (their right-hand normal is the outward one).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from dockfactory.core.io import write_text_atomic
from dockfactory.generator.silhouette import SEGMENTS   # the rims' vertices are the silhouette's points


def _ring(x: float, r: float, a: np.ndarray) -> np.ndarray:
    return np.stack([np.full(len(a), x), r * np.sin(a), r * np.cos(a)], 1)


def _band(p: np.ndarray, q: np.ndarray, normals: np.ndarray, outward: np.ndarray):
    """Vertices (2n, 3), normals (2n, 3) and triangles (2n, 3) of the band between rings ``p`` and
    ``q`` (n, 3) with vertex normals ``normals`` (2n, 3), wound so that triangle normals point
    along ``outward`` (a function of the triangle's first vertex, (3,) direction)."""
    n = len(p)
    i = np.arange(n)
    j = (i + 1) % n
    tris = np.concatenate([np.stack([i, j, j + n], 1), np.stack([i, j + n, i + n], 1)])
    verts = np.vstack([p, q])
    return verts, normals, _outward(verts, tris, outward)


def _outward(verts: np.ndarray, tris: np.ndarray, outward) -> np.ndarray:
    """``tris`` with each triangle's winding flipped where its normal points against ``outward(v0)``."""
    a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    flip = np.einsum("ij,ij->i", np.cross(b - a, c - a), outward(a, (a + b + c) / 3)) < 0
    tris = tris.copy()
    tris[flip] = tris[flip][:, [0, 2, 1]]
    return tris


def _disc(x: float, r: float, a: np.ndarray, normal_x: float):
    """A disc at ``x`` of radius ``r`` facing ``normal_x`` (+-1): a fan around its centre."""
    n = len(a)
    verts = np.vstack([_ring(x, r, a), [[x, 0.0, 0.0]]])
    i = np.arange(n)
    tris = np.stack([np.full(n, n), i, (i + 1) % n], 1)
    normals = np.tile([normal_x, 0.0, 0.0], (n + 1, 1))
    return verts, normals, _outward(verts, tris, lambda v, c: np.tile([normal_x, 0.0, 0.0], (len(v), 1)))


def _radial(v: np.ndarray, c=None) -> np.ndarray:
    out = v.copy()
    out[:, 0] = 0.0
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def section_surfaces(radius: float, length: float, flange_w: float, flange_h: float, section: str,
                     n: int = SEGMENTS) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The five surfaces (module docstring) of section ``section`` ("A" or "B"): each (vertices
    (V, 3) mm, unit normals (V, 3), triangles (F, 3) indices into its own vertices)."""
    sign = -1.0 if section == "A" else 1.0
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    rim = radius + flange_h
    out = [_disc(0.0, rim, a, -sign), _disc(sign * length, radius, a, sign)]
    for x0, x1, r in ((0.0, sign * flange_w, rim), (sign * flange_w, sign * length, radius)):
        p, q = _ring(x0, r, a), _ring(x1, r, a)
        out.append(_band(p, q, _radial(np.vstack([p, q])), _radial))
    p, q = _ring(sign * flange_w, rim, a), _ring(sign * flange_w, radius, a)
    back = np.tile([sign, 0.0, 0.0], (2 * n, 1))
    out.append(_band(p, q, back, lambda v, c: np.tile([sign, 0.0, 0.0], (len(v), 1))))
    return out


def section_mesh(radius: float, length: float, flange_w: float, flange_h: float, section: str,
                 n: int = SEGMENTS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices (V, 3) mm, unit vertex normals (V, 3) and triangles (F, 3) of a section's body
    and flange in its section frame: the surfaces of :func:`section_surfaces`, concatenated."""
    verts, normals, tris, base = [], [], [], 0
    for v, nrm, t in section_surfaces(radius, length, flange_w, flange_h, section, n):
        verts.append(v)
        normals.append(nrm)
        tris.append(t + base)
        base += len(v)
    return np.vstack(verts), np.vstack(normals), np.vstack(tris)


def part_model(vertices, triangles) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices (3 F, 3) mm, unit normals (3 F, 3) and triangles (F, 3) of a part mesh
    (core.config_parts) for the BOP models: each triangle with its own three vertices carrying its
    face normal (the part is drawn flat-shaded, as the factory renders it)."""
    corners = np.asarray(vertices, dtype=np.float64)[np.asarray(triangles, dtype=np.int64)]
    n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    return corners.reshape(-1, 3), np.repeat(n, 3, axis=0), np.arange(3 * len(corners)).reshape(-1, 3)


def write_ply(path: Path, verts: np.ndarray, normals: np.ndarray, faces: np.ndarray) -> None:
    """ASCII PLY of a triangle mesh with vertex normals (mm), atomically."""
    head = (f"ply\nformat ascii 1.0\ncomment dockfactory section model, mm\nelement vertex {len(verts)}\n"
            f"property float x\nproperty float y\nproperty float z\n"
            f"property float nx\nproperty float ny\nproperty float nz\nelement face {len(faces)}\n"
            f"property list uchar int vertex_indices\nend_header\n")
    body = "".join(f"{x:.4f} {y:.4f} {z:.4f} {a:.6f} {b:.6f} {c:.6f}\n"
                   for (x, y, z), (a, b, c) in zip(verts, normals))
    body += "".join(f"3 {a} {b} {c}\n" for a, b, c in faces)
    write_text_atomic(path, head + body)


def read_ply(path: Path) -> dict[str, np.ndarray]:
    """A PLY written by :func:`write_ply`: {"pts": (V, 3), "normals": (V, 3), "faces": (F, 3)}."""
    lines = Path(path).read_text().splitlines()
    n = int(next(l for l in lines if l.startswith("element vertex")).split()[-1])
    start = lines.index("end_header") + 1
    vert = np.array([[float(v) for v in l.split()] for l in lines[start:start + n]])
    faces = np.array([[int(v) for v in l.split()[1:]] for l in lines[start + n:] if l.strip()])
    return {"pts": vert[:, :3], "normals": vert[:, 3:6], "faces": faces}
