"""Mesh builders (bpy). Geometry is made from numpy arrays, in Blender metres."""
from __future__ import annotations

import bpy
import numpy as np

from dockfactory.core.layout import DISC_SEGMENTS, RING_SEGMENTS, SECTION_FACETS


def mesh_object(name: str, verts, faces, smooth: bool = False, collection=None, material_indices=None):
    """An object of ``verts`` (metres) and ``faces``; ``material_indices``: each face's slot in
    the object's materials (set before Blender validates the mesh, so a face it drops takes its
    index with it)."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(map(float, v)) for v in verts], [], [tuple(map(int, f)) for f in faces])
    if material_indices is not None:
        mesh.polygons.foreach_set("material_index", [int(i) for i in material_indices])
    mesh.validate()
    mesh.update()
    if smooth:
        mesh.shade_smooth()
    obj = bpy.data.objects.new(name, mesh)
    (collection or bpy.context.scene.collection).objects.link(obj)
    return obj


def tube_x(name, x0, x1, radius, segments=SECTION_FACETS, caps=True, smooth=True, collection=None):
    """Cylinder along +X from x0 to x1 (metres)."""
    a = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([np.zeros_like(a), radius * np.sin(a), radius * np.cos(a)], axis=1)
    verts = np.concatenate([ring + [x0, 0, 0], ring + [x1, 0, 0]])
    faces = [(i, (i + 1) % segments, segments + (i + 1) % segments, segments + i) for i in range(segments)]
    if caps:
        faces.append(tuple(reversed(range(segments))))
        faces.append(tuple(range(segments, 2 * segments)))
    obj = mesh_object(name, verts, faces, smooth=False, collection=collection)
    if smooth:  # smooth the side only, keep caps flat
        for poly in obj.data.polygons:
            poly.use_smooth = poly.loop_total == 4
    return obj


def disc_z(name, radius, segments=DISC_SEGMENTS, collection=None):
    """Flat disc in the local XY plane facing +Z, centred at the origin."""
    a = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    verts = np.stack([radius * np.cos(a), radius * np.sin(a), np.zeros_like(a)], axis=1)
    return mesh_object(name, verts, [tuple(range(segments))], collection=collection)


def cylinder_z(name, radius, z0, z1, segments=RING_SEGMENTS, smooth=True, collection=None):
    """Closed cylinder along local Z from z0 to z1."""
    a = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([radius * np.cos(a), radius * np.sin(a), np.zeros_like(a)], axis=1)
    verts = np.concatenate([ring + [0, 0, z0], ring + [0, 0, z1]])
    faces = [(i, (i + 1) % segments, segments + (i + 1) % segments, segments + i) for i in range(segments)]
    faces += [tuple(reversed(range(segments))), tuple(range(segments, 2 * segments))]
    obj = mesh_object(name, verts, faces, collection=collection)
    if smooth:
        for poly in obj.data.polygons:
            poly.use_smooth = poly.loop_total == 4
    return obj


def unit_box(name, collection=None):
    """Box spanning [-0.5, 0.5]^3 (scaled per frame)."""
    v = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return mesh_object(name, v, faces, collection=collection)


def unit_cylinder_x(name, segments=32, collection=None):
    """Cylinder along X spanning [-0.5, 0.5], diameter 1 (scaled per frame)."""
    return tube_x(name, -0.5, 0.5, 0.5, segments=segments, collection=collection)


def unit_sphere(name, rings=16, segments=32, collection=None):
    """UV sphere of diameter 1 (scaled per frame into an ellipsoid)."""
    verts = [(0, 0, 0.5)]
    for i in range(1, rings):
        th = np.pi * i / rings
        for j in range(segments):
            ph = 2 * np.pi * j / segments
            verts.append((0.5 * np.sin(th) * np.cos(ph), 0.5 * np.sin(th) * np.sin(ph), 0.5 * np.cos(th)))
    verts.append((0, 0, -0.5))
    faces = []
    for j in range(segments):
        faces.append((0, 1 + j, 1 + (j + 1) % segments))
    for i in range(rings - 2):
        a, b = 1 + i * segments, 1 + (i + 1) * segments
        for j in range(segments):
            faces.append((a + j, b + j, b + (j + 1) % segments, a + (j + 1) % segments))
    last = len(verts) - 1
    base = 1 + (rings - 2) * segments
    for j in range(segments):
        faces.append((base + (j + 1) % segments, base + j, last))
    return mesh_object(name, verts, faces, smooth=True, collection=collection)


def unit_tool(name, collection=None):
    """A spanner-like tool along X in [-0.5, 0.5]: a handle bar and a wider head."""
    verts, faces = [], []

    def box(lo, hi):
        base = len(verts)
        for x in (lo[0], hi[0]):
            for y in (lo[1], hi[1]):
                for z in (lo[2], hi[2]):
                    verts.append((x, y, z))
        for f in [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]:
            faces.append(tuple(base + i for i in f))

    box((-0.5, -0.22, -0.5), (0.25, 0.22, 0.5))   # handle
    box((0.25, -0.5, -0.5), (0.5, 0.5, 0.5))      # head
    return mesh_object(name, verts, faces, collection=collection)
