"""``[sections] mesh_a = "part_a.glb"`` (and ``mesh_b``): a section from the user's CAD part.

A config names a mesh file (glTF / GLB, OBJ, STL, PLY; :mod:`dockfactory.core.mesh_files`)
relative to its folder, in the section's own frame (conventions.md: A's origin at the centre of
its docking face, +X from A toward B, +Z toward the camera; B's the same at its face), in
``mesh_units`` (glTF: metres). Loading the config reads it into ``mesh_a_vertices`` and
``mesh_a_triangles`` (mm), so the config holds the part itself: the version id is its content, a
dataset's stored config re-renders it without the file, and everything downstream (markers cast
onto it, silhouettes, the worker's scene, BOP models) reads the same triangles. With
``[sections] materials = "file"`` the part's glTF materials are read the same way
(``mesh_a_materials``, ``mesh_a_triangle_materials``) and rendered in place of the paint.
"""
from __future__ import annotations


from dockfactory.core.mesh_base import MeshError
from dockfactory.core.mesh_files import read_mesh
from dockfactory.core.user_files import beside_config, short_digest


def resolve_parts(data: dict, config_path) -> tuple[dict, str | None]:
    """(data, note): the config's TOML tables ``data`` with each ``[sections] mesh_a`` / ``mesh_b``
    file read into its vertices and triangles (module docstring), and a one-line note naming the
    files and their sha256 (None, ``data`` unchanged, when none is named). MeshError (config,
    key, file) on a bad file, or when the config also states the triangles."""
    sections = data.get("sections")
    if not isinstance(sections, dict) or not (sections.get("mesh_a") or sections.get("mesh_b")):
        return data, None
    source, out, notes = str(config_path), dict(sections), []
    for sec in ("a", "b"):
        name = sections.get(f"mesh_{sec}")
        if not name:
            continue
        if not isinstance(name, str):
            raise MeshError(f"{source}: [sections] mesh_{sec}: expected a file name, got {name!r}")
        if any(f"mesh_{sec}_{k}" in sections for k in ("vertices", "triangles", "materials", "triangle_materials")):
            raise MeshError(f"{source}: [sections] mesh_{sec}: the config states its triangles too; give one")
        path = beside_config(name, config_path)
        try:
            mesh = read_mesh(path, sections.get("mesh_units", "mm") if isinstance(sections.get("mesh_units"), str)
                             else "mm")
        except MeshError as exc:
            raise MeshError(f"{source}: [sections] mesh_{sec}: {exc}") from None
        out.pop(f"mesh_{sec}")
        out[f"mesh_{sec}_vertices"] = mesh.vertices.tolist()
        out[f"mesh_{sec}_triangles"] = mesh.triangles.tolist()
        if sections.get("materials") == "file":
            if mesh.materials is None:
                raise MeshError(f'{source}: [sections] materials = "file": {name!r} has no materials (only glTF '
                                'files carry them); use materials = "paint"')
            out[f"mesh_{sec}_materials"] = mesh.materials.tolist()
            out[f"mesh_{sec}_triangle_materials"] = mesh.triangle_materials.tolist()
        digest = short_digest(path)
        notes.append(f"[sections] mesh_{sec} = {name!r} (sha256 {digest}..., {len(mesh.triangles)} triangles)")
    return {**data, "sections": out}, " and ".join(notes) + " resolved"
