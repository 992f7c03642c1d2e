"""Part meshes in (core.mesh_files, mesh_gltf, mesh_ply) and markers on them (core.mesh_markers),
without Blender: every format round trips a part (glTF in metres, the others in the stated unit);
hand-written files of each format (a glTF node transform, an OBJ quad and negative indices, an
ASCII STL, a binary PLY) read as written; bad files are one line naming the file; markers cast onto
a cylinder mesh sit where the parametric layout puts them (within the facets' sagitta and angle),
onto a box face with the face's normal, and a marker over an edge or under a rib is refused."""
from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from dockfactory.core.layout import place_marker
from dockfactory.core.mesh_base import MeshError, TriMesh, checked_mesh
from dockfactory.core.mesh_files import mesh_bytes, read_mesh, write_mesh
from dockfactory.core.mesh_markers import place_on_mesh, ray_hits

BOX = TriMesh(np.array([[x, y, z] for x in (0.0, 10.0) for y in (0.0, 20.0) for z in (0.0, 30.0)]),
              np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                        [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]))


def cylinder(radius=300.0, x0=-600.0, x1=0.0, n=256) -> TriMesh:
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    v = np.array([[x, radius * np.sin(t), radius * np.cos(t)] for x in (x0, x1) for t in a])
    tris = [t for i in range(n) for t in ([i, (i + 1) % n, n + (i + 1) % n], [i, n + (i + 1) % n, n + i])]
    return TriMesh(v, np.array(tris))


def _same(a: TriMesh, b: TriMesh) -> float:
    return float(np.abs(np.sort(a.corners().reshape(-1, 9), axis=0) - np.sort(b.corners().reshape(-1, 9), axis=0)).max())


@pytest.mark.parametrize("suffix, tol", [(".glb", 1e-6), (".stl", 1e-5), (".obj", 0.0), (".ply", 0.0)])
def test_every_format_round_trips(tmp_path, suffix, tol):
    write_mesh(BOX, tmp_path / f"p{suffix}")
    assert _same(read_mesh(tmp_path / f"p{suffix}"), BOX) <= tol


def test_units_scale_all_but_gltf(tmp_path):
    write_mesh(BOX, tmp_path / "p.obj")
    assert _same(read_mesh(tmp_path / "p.obj", units="cm"), TriMesh(BOX.vertices * 10, BOX.triangles)) == 0.0
    write_mesh(BOX, tmp_path / "p.glb")   # glTF: metres by its specification, whatever units says
    assert _same(read_mesh(tmp_path / "p.glb", units="in"), BOX) < 1e-6


def test_hand_written_files_read_as_written(tmp_path):
    (tmp_path / "q.obj").write_text("# quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1/1/1 2/2/2 3/3/3 4/4/4\nf -4 -3 -1\n")
    m = read_mesh(tmp_path / "q.obj")
    assert m.triangles.tolist() == [[0, 1, 2], [0, 2, 3], [0, 1, 3]]
    (tmp_path / "t.stl").write_text("solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 2 0 0\n"
                                    "vertex 0 3 0\nendloop\nendfacet\nendsolid t\n")
    assert read_mesh(tmp_path / "t.stl", units="m").vertices.tolist() == [[0, 0, 0], [2000, 0, 0], [0, 3000, 0]]
    head = (b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
            b"property float z\nproperty uchar red\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n")
    body = b"".join(struct.pack("<fffB", *p, 7) for p in ((0, 0, 0), (1, 0, 0), (0, 1, 0))) + struct.pack("<BIII", 3, 0, 1, 2)
    (tmp_path / "b.ply").write_bytes(head + body)
    assert read_mesh(tmp_path / "b.ply").vertices[1].tolist() == [1, 0, 0]


def test_a_gltf_node_transform_is_applied(tmp_path):
    glb = mesh_bytes(BOX, ".glb")
    length = struct.unpack_from("<I", glb, 12)[0]
    doc = json.loads(glb[20:20 + length])
    doc["nodes"] = [{"children": [1], "translation": [1.0, 0.0, 0.0]},
                    {"mesh": 0, "rotation": [0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5)], "scale": [2.0, 2.0, 2.0]}]
    doc["buffers"][0]["uri"] = "p.bin"
    binary = glb[28 + length:]
    (tmp_path / "p.bin").write_bytes(binary)
    (tmp_path / "p.gltf").write_text(json.dumps(doc))
    m = read_mesh(tmp_path / "p.gltf")
    rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])   # 90 deg about Z
    want = 2.0 * BOX.vertices @ rz.T + [1000.0, 0.0, 0.0]
    assert np.abs(m.vertices - want).max() < 1e-4


@pytest.mark.parametrize("name, data, message", [
    ("p.step", b"ISO-10303-21;", "expected a mesh file (.glb, .gltf, .obj, .stl, .ply; STEP: convert it"),
    ("p.obj", b"v 0 0 0\nv 1 0 0\nf 1 2 5\n", "a triangle names vertex 4, but there are 2"),
    ("p.obj", b"v 0 0\n", "p.obj:1: a vertex is not three numbers"),
    ("p.stl", b"\x00" * 90, "not an STL file"),
    ("p.glb", b"glTF" + b"\x01\x00\x00\x00" * 2, "not a glTF 2.0 binary"),
    ("p.gltf", b'{"asset": {"version": "2.0"}, "buffers": [{"uri": "../x.bin"}]}', "the glTF's scene holds no mesh"),
    ("p.ply", b"ply\nformat binary_big_endian 1.0\nend_header\n", "only ascii and binary_little_endian"),
    ("p.obj", b"", "no triangles"),
])
def test_a_bad_file_is_one_line(tmp_path, name, data, message):
    (tmp_path / name).write_bytes(data)
    with pytest.raises(MeshError) as err:
        read_mesh(tmp_path / name)
    assert message in str(err.value) and name in str(err.value) and "\n" not in str(err.value)


def test_a_buffer_outside_the_gltfs_folder_is_refused(tmp_path):
    doc = {"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}], "buffers": [{"uri": "../x.bin"}],
           "bufferViews": [{"buffer": 0}], "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}]}
    (tmp_path / "p.gltf").write_text(json.dumps(doc))
    with pytest.raises(MeshError, match=r"buffer 0 points outside the glTF's folder"):
        read_mesh(tmp_path / "p.gltf")


def test_markers_on_a_cylinder_mesh_are_the_parametric_ones():
    mesh, radius = cylinder(), 300.0
    half_facet = np.pi / 256
    for s, phi in ((50.0, -53.0), (100.0, -32.0), (62.0, -7.0), (150.0, 61.0)):
        got, drop = place_on_mesh(mesh, "A", 0, s, phi, 20.0, 1.0, "cyl")
        want = place_marker("A", 0, s, phi, radius, 20.0, 1.0)
        # the facet lies up to R (1 - cos(half facet)) inside the circle, its normal up to half a facet off
        assert np.linalg.norm(np.subtract(got.center_mm, want.center_mm)) < radius * (1 - np.cos(half_facet)) + 0.02
        assert np.degrees(np.arccos(np.clip(np.dot(got.normal, want.normal), -1, 1))) <= np.degrees(half_facet) + 1e-6
        ring = 10.0 + 2.5
        assert radius - np.sqrt(radius ** 2 - ring ** 2) - 0.01 < drop < radius - np.sqrt(radius ** 2 - ring ** 2) + 0.5


def test_a_marker_on_a_box_face_and_over_an_edge_or_under_a_rib():
    box = TriMesh(BOX.vertices * [-20.0, 10.0, 10.0] + [0.0, -100.0, 0.0], BOX.triangles)   # x -200..0, y -100..100, z 0..300
    got, drop = place_on_mesh(box, "A", 3, 100.0, 0.0, 20.0, 1.0, "box")
    assert np.allclose(got.center_mm, [-100.0, 0.0, 301.0]) and np.allclose(got.normal, [0, 0, 1]) and drop == 0.0
    with pytest.raises(MeshError, match=r"box: marker A3 \(s 5 mm, phi 0 deg\): its ring overhangs an edge"):
        place_on_mesh(box, "A", 3, 5.0, 0.0, 20.0, 1.0, "box")
    rib = TriMesh(BOX.vertices * [0.5, 20.0, 1.0] + [-101.0, -200.0, 300.0], BOX.triangles)   # 5 mm wide, 30 high
    both = TriMesh(np.vstack([box.vertices, rib.vertices]), np.vstack([box.triangles, rib.triangles + 8]))
    with pytest.raises(MeshError, match=r"marker A0 \(s 92 mm, phi 0 deg\): the part rises 30.00 mm"):
        place_on_mesh(both, "A", 0, 92.0, 0.0, 20.0, 1.0, "ribbed")
    with pytest.raises(MeshError, match="its ray from the section's axis meets no surface"):
        place_on_mesh(box, "B", 0, 100.0, 0.0, 20.0, 1.0, "box")


def test_ray_hits_both_faces_and_only_ahead():
    t, i = ray_hits(BOX.corners(), [3.0, 12.0, -10.0], [0.0, 0.0, 1.0])
    assert sorted(np.round(t, 9).tolist()) == [10.0, 40.0] and len(set(i.tolist())) == 2


def test_the_shipped_example_parts_are_what_their_script_writes(repo_root, tmp_path):
    from dockfactory.generator.example_parts import FILES, write_example_parts
    write_example_parts(tmp_path)
    for name in FILES.values():
        assert (tmp_path / name).read_bytes() == (repo_root / "configs" / "parts" / name).read_bytes(), name


def test_a_config_names_a_part_and_holds_it(repo_root, tmp_path):
    import tomllib

    from dockfactory.core.config import ConfigError, config_from_dict, load_config
    from dockfactory.core.config_text import load_config_text
    cfg, text = load_config_text(repo_root / "configs" / "octagon_part.toml")
    assert len(cfg.sections.mesh_a_triangles) == len(cfg.sections.mesh_b_triangles) == 84
    assert text.startswith("# octagon_part.toml with [sections] mesh_a = 'parts/octagon_a.glb' (sha256 ")
    assert config_from_dict(tomllib.loads(text)) == cfg == load_config(repo_root / "configs" / "octagon_part.toml")
    a0 = cfg.markers_layout()[0]
    assert a0.normal == pytest.approx((0.0, 0.0, 1.0)) and a0.center_mm[2] == pytest.approx(300 * np.cos(np.pi / 8) + 0.1)   # the flat plate's 0.1 mm
    (tmp_path / "c.toml").write_text('[sections]\nmesh_a = "nope.glb"\n')
    with pytest.raises(MeshError, match=r"c.toml: \[sections\] mesh_a: .*nope.glb: mesh file not found"):
        load_config(tmp_path / "c.toml")
    with pytest.raises(ConfigError, match=r"\[sections\] mesh_a: 'x.glb' is read when a config file is loaded"):
        config_from_dict({"sections": {"mesh_a": "x.glb"}})
    for s_mm, why in (("245.0", "the part rises 10.00 mm"), ("258.0", "the part falls 10.00 mm away")):
        bad = text.replace("layout_a = [[60.0, -6.0]", f"layout_a = [[{s_mm}, -6.0]")   # beside the rib, on it
        (tmp_path / "rib.toml").write_text(bad)
        with pytest.raises(ConfigError, match=rf"marker A0 \(s {s_mm[:-2]} mm, phi -6 deg\): {why}"):
            load_config(tmp_path / "rib.toml")


def test_a_config_holding_a_bad_part_is_one_line():
    from dockfactory.core.config import ConfigError, config_from_dict
    v, t = BOX.vertices.tolist(), BOX.triangles.tolist()
    for sections, message in (({"mesh_a_vertices": v, "mesh_a_triangles": [[0, 1, 8]] + t}, "a vertex beyond the 8"),
                              ({"mesh_a_vertices": v}, "vertices and triangles come together"),
                              ({"mesh_units": "furlong"}, "'furlong' is not one of mm, cm, m, in")):
        with pytest.raises(ConfigError, match=message):
            config_from_dict({"sections": sections})


TWO_COLOURS = np.array([[0.8, 0.05, 0.05, 0.0, 0.6], [0.05, 0.6, 0.05, 1.0, 0.2]])


def test_a_gltfs_materials_round_trip_per_triangle(tmp_path):
    """Each triangle keeps its material through a .glb (a primitive per material); a glTF without
    materials has none; a primitive without a material takes glTF's default (white, metallic 1,
    roughness 1)."""
    coloured = TriMesh(BOX.vertices, BOX.triangles, TWO_COLOURS, np.arange(12) % 2)
    write_mesh(coloured, tmp_path / "c.glb")
    back = read_mesh(tmp_path / "c.glb")
    assert back.materials is not None and back.triangle_materials is not None
    got = {tuple(np.round(tri, 3).ravel()): tuple(back.materials[k]) for tri, k in
           zip(back.corners(), back.triangle_materials)}
    for tri, k in zip(coloured.corners(), coloured.triangle_materials):
        assert got[tuple(np.round(tri, 3).ravel())] == pytest.approx(tuple(TWO_COLOURS[k]), abs=1e-6)
    write_mesh(BOX, tmp_path / "plain.glb")
    assert read_mesh(tmp_path / "plain.glb").materials is None
    doc = json.loads((tmp_path / "c.glb").read_bytes()[20:20 + struct.unpack_from("<I", (tmp_path / "c.glb").read_bytes(), 12)[0]])
    assert [p["material"] for p in doc["meshes"][0]["primitives"]] == [0, 1]
    with pytest.raises(MeshError, match="materials do not index"):
        checked_mesh(BOX.vertices, BOX.triangles, "x.glb", TWO_COLOURS, np.full(12, 2))
    with pytest.raises(MeshError, match=r"x.glb: a material's colour"):
        checked_mesh(BOX.vertices, BOX.triangles, "x.glb", TWO_COLOURS * 2, np.zeros(12))


def test_a_primitive_without_a_material_takes_gltfs_default(tmp_path):
    coloured = TriMesh(BOX.vertices, BOX.triangles, TWO_COLOURS[:1], np.zeros(12, dtype=np.int64))
    data = bytearray(mesh_bytes(coloured, ".glb"))
    n = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(bytes(data[20:20 + n]))
    del doc["meshes"][0]["primitives"][0]["material"]
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (n - len(text))
    data[20:20 + n] = text
    (tmp_path / "d.glb").write_bytes(bytes(data))
    m = read_mesh(tmp_path / "d.glb")
    assert m.materials.tolist() == [[1.0, 1.0, 1.0, 1.0, 1.0]] and set(m.triangle_materials.tolist()) == {0}


def test_a_config_takes_a_parts_materials_from_its_file(repo_root, tmp_path):
    """``[sections] materials = "file"`` holds each part's materials in the config (a dataset's
    stored config renders them without the file); "paint" holds none; a part whose file has no
    materials (STL), an unknown choice or materials stated with "paint" are one line."""
    import tomllib

    from dockfactory.core.config import ConfigError, config_from_dict, load_config
    from dockfactory.core.config_text import load_config_text
    octagon = {k: read_mesh(repo_root / "configs" / "parts" / f"octagon_{k}.glb" if k == "a" else
                            repo_root / "configs" / "parts" / "octagon_b.stl") for k in "ab"}
    (tmp_path / "parts").mkdir()
    for k, m in octagon.items():
        n = len(m.triangles)
        write_mesh(TriMesh(m.vertices, m.triangles, TWO_COLOURS, np.arange(n) % 2), tmp_path / "parts" / f"c_{k}.glb")
    shipped = (repo_root / "configs" / "octagon_part.toml").read_text()
    coloured = shipped.replace("octagon_a.glb", "c_a.glb").replace("octagon_b.stl", "c_b.glb")
    (tmp_path / "f.toml").write_text(coloured.replace("[sections]\n", '[sections]\nmaterials = "file"\n'))
    (tmp_path / "p.toml").write_text(coloured)
    cfg, text = load_config_text(tmp_path / "f.toml")
    s = cfg.sections
    assert np.allclose(np.array(s.mesh_a_materials), TWO_COLOURS, atol=1e-6)
    assert len(s.mesh_a_triangle_materials) == len(s.mesh_a_triangles) and set(s.mesh_a_triangle_materials) == {0, 1}
    assert len(s.mesh_b_triangle_materials) == len(s.mesh_b_triangles)
    assert config_from_dict(tomllib.loads(text)) == cfg
    painted = load_config(tmp_path / "p.toml").sections
    assert painted.materials == "paint" and painted.mesh_a_materials == () and painted.mesh_a_triangle_materials == ()
    (tmp_path / "s.toml").write_text(shipped.replace("[sections]\n", '[sections]\nmaterials = "file"\n'))
    (tmp_path / "parts" / "octagon_a.glb").write_bytes((repo_root / "configs" / "parts" / "octagon_a.glb").read_bytes())
    with pytest.raises(MeshError, match=r"s.toml: \[sections\] materials = \"file\": 'parts/octagon_a.glb' has no materials"):
        load_config(tmp_path / "s.toml")
    with pytest.raises(ConfigError, match=r"\[sections\] materials: 'cad' is not one of paint, file"):
        config_from_dict({"sections": {"materials": "cad"}})
    v, t = BOX.vertices.tolist(), BOX.triangles.tolist()
    with pytest.raises(ConfigError, match=r"mesh_a_materials: stated with materials = \"paint\""):
        config_from_dict({"sections": {"mesh_a_vertices": v, "mesh_a_triangles": t,
                                       "mesh_a_materials": TWO_COLOURS.tolist(), "mesh_a_triangle_materials": [0] * 12}})
    with pytest.raises(ConfigError, match=r"\[sections\] materials: \"file\", but part A has no materials"):
        config_from_dict({"sections": {"mesh_a_vertices": v, "mesh_a_triangles": t, "materials": "file"}})
    with pytest.raises(ConfigError, match="each triangle of the part names one of them"):
        config_from_dict({"sections": {"materials": "file", "mesh_a_materials": TWO_COLOURS.tolist()}})
    with pytest.raises(ConfigError, match="each triangle of the part names one of them"):
        config_from_dict({"sections": {"mesh_a_vertices": v, "mesh_a_triangles": t, "materials": "file",
                                       "mesh_a_materials": TWO_COLOURS.tolist(), "mesh_a_triangle_materials": [0] * 11}})
    with pytest.raises(ConfigError, match=r"mesh_a_materials\[0\]: expected 5 values, got 10"):
        config_from_dict({"sections": {"mesh_a_vertices": v, "mesh_a_triangles": t, "materials": "file",
                                       "mesh_a_materials": [TWO_COLOURS.ravel().tolist()],
                                       "mesh_a_triangle_materials": [0] * 12}})
