"""Build the static docking scene once per worker (bpy). Units: Blender metres = mm / 1000."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import bpy
import numpy as np

from dockfactory.blender_scenes import coverage
from dockfactory.blender_scenes import materials as mats
from dockfactory.blender_scenes import meshes
from dockfactory.core.layout import RING_EXTRA_MM, RING_TOP_MM, SECTION_PASS_INDEX, marker_basis
from dockfactory.core.scene import (
    CLUTTER_KINDS,
    CLUTTER_SLOTS,
    FLOOR_GAP_MM,
    OCCLUDER_KINDS,
    StaticScene,
    floor_y_mm,
)

MM = 0.001


@dataclass
class SceneHandles:
    """The Blender objects and materials a frame update touches."""
    scene: object
    camera: object
    b_root: object
    lights: dict = field(default_factory=dict)
    props: dict = field(default_factory=dict)      # (kind, slot) -> object
    prop_materials: dict = field(default_factory=dict)
    paint_a: object = None
    paint_b: object = None
    marker_red: object = None
    marker_blue: object = None
    ring: object = None
    floor: object = None
    wall: object = None
    world: object = None


def _matrix(rotation, translation_m):
    from mathutils import Matrix
    m = np.eye(4)
    m[:3, :3] = rotation
    m[:3, 3] = translation_m
    return Matrix(m.tolist())


def configure_render(scene, width, height, threads, exr_path):
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device = "CPU"
    c.use_adaptive_sampling = False
    c.use_light_tree = False          # per frame: [render] light_tree (frame_update, crops)
    c.use_auto_tile = False           # one tile: no tiling overhead at 1280 x 960
    c.caustics_reflective = False
    c.caustics_refractive = False
    c.diffuse_bounces, c.glossy_bounces = 1, 1
    c.transmission_bounces = c.volume_bounces = c.transparent_max_bounces = 0
    c.denoiser = "OPENIMAGEDENOISE"
    c.denoising_prefilter = "NONE"
    c.denoising_input_passes = "RGB_ALBEDO_NORMAL"
    c.denoising_use_gpu = False
    r = scene.render
    r.threads_mode = "FIXED" if threads > 0 else "AUTO"
    if threads > 0:
        r.threads = threads
    r.resolution_x, r.resolution_y, r.resolution_percentage = width, height, 100
    r.pixel_aspect_x = r.pixel_aspect_y = 1.0
    # No persistent data: with it Cycles updates its copy of the scene incrementally between
    # frames, and that copy kept traces of earlier frames (a worker whose first frame had the
    # lamp prop in view rendered a later specular-glare frame with different noise in 84-100 %
    # of its pixels). Without it every render syncs the scene afresh from Blender's data, which
    # apply_frame makes a function of the frame alone. Cost, measured side by side (alternating
    # runs, 2 threads, busy 2-core machine): 5.85 s CPU/frame off vs 6.05 on at 1280 x 960,
    # 0.344 vs 0.340 at 320 x 240, i.e. within noise.
    r.use_persistent_data = False
    r.film_transparent = False
    r.use_compositing = False
    r.use_sequencer = False
    scene.view_settings.view_transform = "Standard"
    vl = scene.view_layers[0]
    vl.use_pass_combined = True
    vl.use_pass_z = True
    vl.use_pass_object_index = True
    coverage.register_coverage_pass(vl)
    s = r.image_settings
    s.media_type = "MULTI_LAYER_IMAGE"      # must precede file_format in Blender 5
    s.file_format = "OPEN_EXR_MULTILAYER"
    s.color_depth = "16"
    s.exr_codec = "NONE"                     # scratch file on tmpfs: fastest to write and read
    r.filepath = exr_path
    r.use_file_extension = False


def _section_cradles(static: StaticScene, sec: str, sign: int, support) -> list:
    """The two cradles under section ``sec`` (in the section's frame)."""
    r_m = static.radius_mm * MM
    cradles = []
    for x_mm in (sign * 0.25 * static.length_mm, sign * 0.8 * static.length_mm):
        cradle = meshes.unit_box(f"cradle_{sec}_{x_mm:.0f}")
        cradle.data.materials.append(support)
        height_mm = FLOOR_GAP_MM + 120.0  # from the floor to 120 mm up the section's underside
        cradle.scale = (0.12, height_mm * MM, 1.5 * r_m)
        cradle.location = (x_mm * MM, (floor_y_mm(static.radius_mm) + height_mm / 2) * MM, 0)
        cradles.append(cradle)
    return cradles


def _file_materials(part, sec: str) -> list:
    """The part's own materials (``[sections] materials = "file"``): the paint's shader at each
    material's base colour, metallic and roughness, without grime or texture; set once, never per
    frame."""
    out = []
    for k, (r, g, b, metallic, roughness) in enumerate(part.materials):
        mat = mats.paint_material(f"part_{sec}_{k}")
        mats.set_paint(mat, (r, g, b), metallic, roughness, 0.0, 0.0, 1.0, (0.0, 0.0, 0.0))
        out.append(mat)
    return out


def _build_part(static: StaticScene, sec: str, paint, parent) -> None:
    """A section's part mesh (core.scene.PartMesh, its section frame), flat-shaded in the paint or
    in its own materials: exactly the triangles the labels use; no flange, band or cradles of the
    parametric section."""
    part = static.part(sec)
    own = part.triangle_materials if part.materials else None
    obj = meshes.mesh_object(f"section_{sec}", np.asarray(part.vertices) * MM, part.triangles, material_indices=own)
    for mat in _file_materials(part, sec) if part.materials else [paint]:
        obj.data.materials.append(mat)
    obj.pass_index = SECTION_PASS_INDEX[sec]
    if parent is not None:
        obj.parent = parent


def _build_section(static: StaticScene, sec: str, sign: int, paint, face, support, parent) -> None:
    """Body, flange, paint band and cradles of one section; section A in D: x in [-L, 0], section
    B in its own frame: x in [0, L] (parented to ``parent``); a part mesh instead when it has one."""
    if static.part(sec) is not None:
        _build_part(static, sec, paint, parent)
        return
    r_m, l_m = static.radius_mm * MM, static.length_mm * MM
    fh, fw = static.flange_height_mm * MM, static.flange_width_mm * MM
    body = meshes.tube_x(f"section_{sec}", min(0, sign * l_m), max(0, sign * l_m), r_m)
    flange = meshes.tube_x(f"flange_{sec}", min(0, sign * fw), max(0, sign * fw), r_m + fh, segments=256)
    band = meshes.tube_x(f"band_{sec}", min(sign * 0.45 * l_m, sign * 0.45 * l_m + sign * 0.02),
                         max(sign * 0.45 * l_m, sign * 0.45 * l_m + sign * 0.02), r_m + 0.002)
    body.data.materials.append(paint)
    band.data.materials.append(paint)
    flange.data.materials.append(face)
    objs = [body, flange, band]
    for o in objs:
        o.pass_index = SECTION_PASS_INDEX[sec]
    objs += _section_cradles(static, sec, sign, support)
    if parent is not None:
        for o in objs:
            o.parent = parent


def _build_marker(m, disc_material, ring_material, b_root, base_depth_mm: float) -> tuple[object, object]:
    """A marker's disc and the ring base under it, reaching ``base_depth_mm`` below the disc's top
    face (a puck, or a flat plate: core.layout.base_depth_mm); B's markers are parented to ``b_root``.
    Returns (disc, ring base)."""
    rot = marker_basis(m.normal)
    centre = np.array(m.center_mm) * MM
    disc = meshes.disc_z(f"marker_{m.id}", m.diameter_mm / 2 * MM)
    disc.data.materials.append(disc_material)
    disc.pass_index = m.pass_index
    disc.matrix_basis = _matrix(rot, centre)
    base = meshes.cylinder_z(f"ring_{m.id}", (m.diameter_mm / 2 + RING_EXTRA_MM) * MM,
                             -base_depth_mm * MM, RING_TOP_MM * MM)  # top just below the disc
    base.data.materials.append(ring_material)
    base.pass_index = SECTION_PASS_INDEX[m.section]
    base.matrix_basis = _matrix(rot, centre)
    if m.section == "B":
        disc.parent = b_root
        base.parent = b_root
    return disc, base


def _build_floor_and_wall(static: StaticScene) -> tuple[object, object]:
    """(floor material, wall material) of the floor plane and the back wall."""
    floor_y = floor_y_mm(static.radius_mm) * MM
    floor = meshes.mesh_object("floor", [(-20, floor_y, -20), (20, floor_y, -20), (20, floor_y, 20),
                                         (-20, floor_y, 20)], [(3, 2, 1, 0)])
    floor_mat = mats.paint_material("floor")
    floor.data.materials.append(floor_mat)
    wall = meshes.mesh_object("wall", [(-20, floor_y, -5), (20, floor_y, -5), (20, 8, -5), (-20, 8, -5)],
                              [(0, 1, 2, 3)])
    wall_mat = mats.diffuse_material("wall")
    wall.data.materials.append(wall_mat)
    return floor_mat, wall_mat


def _build_props(static: StaticScene, handles: SceneHandles) -> None:
    """Hidden occluder and clutter slots plus the lamp prop, registered in ``handles``."""
    builders = {"cable": meshes.unit_cylinder_x, "bar": meshes.unit_box, "tool": meshes.unit_tool,
                "blob": meshes.unit_sphere, "box": meshes.unit_box, "drum": meshes.unit_cylinder_x}
    slots = {k: static.max_occluders for k in OCCLUDER_KINDS}
    slots.update({k: math.ceil(CLUTTER_SLOTS / len(CLUTTER_KINDS)) + 1 for k in CLUTTER_KINDS})
    for kind, count in slots.items():
        for slot in range(count):
            obj = builders[kind](f"{kind}_{slot}")
            mat = mats.diffuse_material(f"{kind}_{slot}_mat", gloss=0.15, roughness=0.4)
            obj.data.materials.append(mat)
            obj.hide_render = True
            handles.props[(kind, slot)] = obj
            handles.prop_materials[(kind, slot)] = mat
    lamp = meshes.unit_sphere("lamp_0")
    lamp_mat = mats.emission_material("lamp_mat")
    lamp.data.materials.append(lamp_mat)
    lamp.hide_render = True
    lamp.visible_shadow = False
    handles.props[("lamp", 0)] = lamp
    handles.prop_materials[("lamp", 0)] = lamp_mat


def _build_lights_and_camera(scene, handles: SceneHandles) -> None:
    """The hidden key, fill and glare disk lights and the scene camera, registered in ``handles``."""
    for name in ("key", "fill", "glare"):
        data = bpy.data.lights.new(name, type="AREA")
        data.shape = "DISK"
        obj = bpy.data.objects.new(name, data)
        scene.collection.objects.link(obj)
        obj.hide_render = True
        handles.lights[name] = obj
    cam_data = bpy.data.cameras.new("camera")
    cam_data.sensor_fit = "HORIZONTAL"
    cam_data.clip_start, cam_data.clip_end = 0.05, 100.0
    cam = bpy.data.objects.new("camera", cam_data)
    scene.collection.objects.link(cam)
    scene.camera = cam
    handles.camera = cam


def build_scene(static: StaticScene, width: int, height: int, threads: int, exr_path: str) -> SceneHandles:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    configure_render(scene, width, height, threads, exr_path)
    world = mats.world(scene)

    paint_a, paint_b = mats.paint_material("paint_A"), mats.paint_material("paint_B")
    red = mats.diffuse_material("marker_red", (0.6, 0.02, 0.02))
    blue = mats.diffuse_material("marker_blue", (0.02, 0.05, 0.6))
    ring = mats.diffuse_material("marker_ring", (0.02, 0.02, 0.02))
    for mat, cls in ((red, coverage.DISC_CLASS), (blue, coverage.DISC_CLASS), (ring, coverage.RING_CLASS)):
        coverage.add_class_output(mat, cls)
    face = mats.diffuse_material("docking_face", (0.08, 0.08, 0.09), gloss=0.6, roughness=0.3)
    support = mats.diffuse_material("cradle", (0.05, 0.12, 0.2))

    b_root = bpy.data.objects.new("B_root", None)
    scene.collection.objects.link(b_root)
    for sec, sign, paint, parent in (("A", -1, paint_a, None), ("B", 1, paint_b, b_root)):
        _build_section(static, sec, sign, paint, face, support, parent)
    pucks = [_build_marker(m, red if m.section == "A" else blue, ring, b_root, static.marker_base_depth_mm)
             for m in static.markers]
    floor_mat, wall_mat = _build_floor_and_wall(static)

    handles = SceneHandles(scene=scene, camera=None, b_root=b_root, paint_a=paint_a, paint_b=paint_b,
                           marker_red=red, marker_blue=blue, ring=ring, floor=floor_mat,
                           wall=wall_mat, world=world)
    _build_props(static, handles)
    _build_lights_and_camera(scene, handles)
    coverage.coverage_material()
    coverage.set_classes(scene.objects, [d for d, _ in pucks], [b for _, b in pucks])
    return handles
