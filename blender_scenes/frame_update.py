"""Apply one frozen FrameScene to the built Blender scene (bpy): transforms, lights, materials."""
from __future__ import annotations

import bpy
import numpy as np
from mathutils import Matrix

from dockfactory.blender_scenes import materials as mats
from dockfactory.blender_scenes.scene_builder import MM, SceneHandles
from dockfactory.core.geometry import (
    blender_camera_intrinsics,
    blender_world_from_camera,
)
from dockfactory.core.scene import FrameScene

DENOISE_QUALITY = {"fast": "FAST", "balanced": "BALANCED", "high": "HIGH"}

# What a frame leaves behind must not depend on the frames before it: every property apply_frame
# ever changes is set on every frame, and an object a frame does not use is hidden *and* parked
# in one fixed state (identity transform, these values), never left as the last frame that used
# it had it.
PARKED_DENOISE_QUALITY = "HIGH"
PARKED_COLOR = (0.5, 0.5, 0.5)
# Timing of a frame without motion: Blender's own defaults, never read by a render without motion
# blur. A moving frame is rendered at MOTION_FRAME with the shutter open for exactly one scene
# frame, MOTION_FPS / fps_base frames per second making that frame last the shutter's time.
PARKED_FRAME, PARKED_FPS, PARKED_FPS_BASE, PARKED_SHUTTER, PARKED_ROLLING_DURATION = 1, 24, 1.0, 0.5, 0.1
MOTION_FRAME, MOTION_FPS = 1, 1000
MOTION_ACTION = "B_motion"


def _blender_matrix(d_from_x, scale_xyz_mm=None) -> Matrix:
    m = np.array(d_from_x, dtype=float)
    m[:3, 3] *= MM
    if scale_xyz_mm is not None:
        m[:3, :3] = m[:3, :3] @ np.diag(np.asarray(scale_xyz_mm) * MM)
    return Matrix(m.tolist())


def apply_render_settings(scene, frame: FrameScene) -> None:
    """Cycles samples, seed, bounces, adaptive sampling, filter and denoising of the frame, and no
    border (every one set on every frame, also those the frame switches off)."""
    c = scene.cycles
    rs = frame.render
    c.samples = rs.samples
    c.seed = frame.render_seed
    c.max_bounces = rs.max_bounces
    c.use_adaptive_sampling = rs.adaptive_threshold > 0
    c.adaptive_threshold = rs.adaptive_threshold
    c.adaptive_min_samples = rs.adaptive_min_samples
    c.filter_width = rs.filter_width_px
    c.use_denoising = rs.denoise != "off"
    c.denoising_quality = DENOISE_QUALITY.get(rs.denoise, PARKED_DENOISE_QUALITY)
    c.denoising_prefilter = rs.denoise_prefilter.upper()
    c.sampling_pattern = rs.sampling_pattern.upper()
    c.use_light_tree = rs.light_tree == "on"
    park_border(scene.render)


def park_border(render) -> None:
    """No border render: the whole canvas (Blender's defaults)."""
    render.use_border = False
    render.use_crop_to_border = False
    render.border_min_x = render.border_min_y = 0.0
    render.border_max_x = render.border_max_y = 1.0


PARKED_FOCUS_M = 10.0     # depth of field off: Blender's values, never read by the render
PARKED_F_NUMBER = 2.8


def _apply_camera(h: SceneHandles, cam) -> None:
    """Pose, the render canvas (the overscan a distorted camera is resampled from: resolution and
    principal point) with the unit's physical focal length, and depth of field; every value set
    on every frame."""
    h.camera.matrix_world = Matrix(blender_world_from_camera(cam.cam_from_d_array(), MM).tolist())
    ox, oy, wc, hc = cam.canvas()
    render = h.scene.render
    render.resolution_x, render.resolution_y = wc, hc
    # the sensor grows with the canvas so that the lens (mm) and with it the aperture stay the unit's
    pp = (cam.principal_point[0] - ox, cam.principal_point[1] - oy)
    intr = blender_camera_intrinsics(cam.focal_px, pp, wc, hc, cam.sensor_width_mm * wc / cam.width)
    h.camera.data.lens = intr["lens_mm"]
    h.camera.data.sensor_width = intr["sensor_width_mm"]
    h.camera.data.shift_x = intr["shift_x"]
    h.camera.data.shift_y = intr["shift_y"]
    dof = h.camera.data.dof
    on = cam.f_number > 0
    dof.use_dof = on
    dof.focus_distance = cam.focus_distance_mm * MM if on else PARKED_FOCUS_M
    dof.aperture_fstop = cam.f_number if on else PARKED_F_NUMBER


def _apply_lights(h: SceneHandles, frame: FrameScene) -> None:
    """Place and switch on the frame's lights; the others are hidden and parked."""
    lights = {light.name: light for light in frame.lights}
    unknown = sorted(set(lights) - set(h.lights))
    if unknown:
        raise ValueError(f"frame {frame.spec.frame_id}: no light named {unknown[0]!r}")
    for name, obj in h.lights.items():
        light = lights.get(name)
        on = light is not None and light.power_w > 0
        if on and light.kind != obj.data.type:
            raise ValueError(f"frame {frame.spec.frame_id}: light {name} is {light.kind}, the scene's is "
                             f"{obj.data.type}")
        obj.hide_render = not on
        obj.matrix_world = _blender_matrix(light.d_from_light) if on else Matrix.Identity(4)
        obj.data.energy = light.power_w if on else 0.0
        obj.data.size = light.size_mm * MM if on else 0.0
        obj.data.color = light.color if on else (1.0, 1.0, 1.0)


def _apply_appearance(h: SceneHandles, a) -> None:
    """Paint, marker, floor, wall and world colours of the frame's appearance ``a``."""
    for mat, color in ((h.paint_a, a.section_color_a), (h.paint_b, a.section_color_b)):
        mats.set_paint(mat, color, a.metallic, a.roughness, a.roughness_variation, a.grime,
                       a.texture_scale, a.texture_offset)
    mats.set_paint(h.floor, a.floor_color, 0.0, 0.8, 0.2, 0.5, a.texture_scale * 0.3, a.texture_offset)
    mats.set_diffuse(h.marker_red, color=a.marker_red)
    mats.set_diffuse(h.marker_blue, color=a.marker_blue)
    mats.set_diffuse(h.ring, color=a.ring_color)
    mats.set_diffuse(h.wall, color=a.wall_color)
    mats.set_world(h.world, a.world_color, a.world_strength)


def _apply_props(h: SceneHandles, frame: FrameScene) -> None:
    """Show the frame's props from the pooled objects; hide and park every pooled object it does
    not use."""
    used = {}
    for p in frame.props:
        key = (p.kind, p.slot)
        if key not in h.props:
            raise ValueError(f"frame {frame.spec.frame_id}: no pooled object for {p.kind} slot {p.slot}")
        if key in used:
            raise ValueError(f"frame {frame.spec.frame_id}: two props in {p.kind} slot {p.slot}")
        used[key] = p
    for key, obj in h.props.items():
        p = used.get(key)
        obj.hide_render = p is None
        obj.matrix_world = Matrix.Identity(4) if p is None else _blender_matrix(p.d_from_prop, p.size_mm)
        color = PARKED_COLOR if p is None else p.color
        if key[0] == "lamp":
            mats.set_emission(h.prop_materials[key], color, 0.0 if p is None else p.emission)
        else:
            mats.set_diffuse(h.prop_materials[key], color=color)


def _clear_b_motion(h: SceneHandles) -> None:
    """Remove B's keyframes and their action (what a moving frame leaves behind)."""
    h.b_root.animation_data_clear()
    action = bpy.data.actions.get(MOTION_ACTION)
    if action is not None:
        bpy.data.actions.remove(action)


def _key_b_motion(h: SceneHandles, d_from_b_open, d_from_b_close, frames: tuple[float, float]) -> None:
    """Keyframe B's root (the parent of every object of section B: body, flange, band, cradles,
    markers and their rings) at ``frames`` (shutter open, close) with B's translation there,
    interpolated linearly (Blender 5 layered action: one slot, one keyframe strip)."""
    action = bpy.data.actions.new(MOTION_ACTION)
    slot = action.slots.new(id_type="OBJECT", name=h.b_root.name)
    channels = action.layers.new("motion").strips.new(type="KEYFRAME").channelbag(slot, ensure=True)
    for axis in range(3):
        curve = channels.fcurves.new("location", index=axis)
        for frame_no, d_from_b in zip(frames, (d_from_b_open, d_from_b_close)):
            key = curve.keyframe_points.insert(frame_no, float(d_from_b[axis, 3]) * MM)
            key.interpolation = "LINEAR"
    anim = h.b_root.animation_data_create()
    anim.action = action
    anim.action_slot = slot


def _apply_motion(h: SceneHandles, frame: FrameScene) -> None:
    """B at mid-exposure, and when it moves during the exposure Cycles' motion blur: the shutter
    is one scene frame centred on MOTION_FRAME, B keyed at its open and close, with a rolling
    shutter (top row first) the exposure's share of it per row. Every value set on every frame;
    keyframes of an earlier frame are removed."""
    scene, render, m = h.scene, h.scene.render, frame.motion
    _clear_b_motion(h)
    h.b_root.matrix_world = _blender_matrix(frame.d_from_b)
    moving = m is not None and m.moves()
    rolling = moving and m.readout_ms > 0
    scene.frame_current = MOTION_FRAME if moving else PARKED_FRAME
    scene.frame_subframe = 0.0
    render.use_motion_blur = moving
    render.motion_blur_position = "CENTER"
    render.motion_blur_shutter = 1.0 if moving else PARKED_SHUTTER
    render.fps = MOTION_FPS if moving else PARKED_FPS
    render.fps_base = m.shutter_ms() if moving else PARKED_FPS_BASE   # one frame = the shutter's ms
    scene.cycles.rolling_shutter_type = "TOP" if rolling else "NONE"
    scene.cycles.rolling_shutter_duration = m.exposure_ms / m.shutter_ms() if rolling else PARKED_ROLLING_DURATION
    if moving:
        half_s = m.shutter_ms() / 2000.0
        _key_b_motion(h, m.d_from_b_at(frame.d_from_b, -half_s), m.d_from_b_at(frame.d_from_b, half_s),
                      (MOTION_FRAME - 0.5, MOTION_FRAME + 0.5))


def apply_frame(h: SceneHandles, frame: FrameScene) -> None:
    """Set the scene to ``frame``: every property this changes is set on every frame, so the
    scene afterwards depends on ``frame`` alone (:func:`scene_state`), whatever came before."""
    apply_render_settings(h.scene, frame)
    _apply_motion(h, frame)
    _apply_camera(h, frame.camera)
    _apply_lights(h, frame)
    _apply_appearance(h, frame.appearance)
    _apply_props(h, frame)


# --- the Blender state a frame leaves behind (tests: it must not depend on earlier frames) ------

# RNA properties that are bookkeeping, not scene content
_VOLATILE = {"rna_type", "session_uid", "users", "is_evaluated", "original", "is_runtime_data",
             "is_missing", "use_fake_user", "use_extra_user", "is_embedded_data", "tag", "is_library_indirect",
             "library_weak_reference", "preview", "filepath", "is_dirty", "mode", "select", "is_active"}


def _plain(v):
    if isinstance(v, (bool, int, float, str)) or v is None:
        return v
    if isinstance(v, set):
        return sorted(v)
    try:
        return [_plain(x) for x in v]
    except TypeError:
        return repr(v)


def _is_id(struct_type) -> bool:
    while struct_type is not None:
        if struct_type.identifier == "ID":
            return True
        struct_type = struct_type.base
    return False


def _rna_values(struct, prefix: str, out: dict, depth: int = 0) -> None:
    """Every value property of ``struct`` and of its nested (non-ID) structs, into ``out``."""
    for prop in struct.bl_rna.properties:
        pid = prop.identifier
        if pid in _VOLATILE:
            continue
        if prop.type == "POINTER":
            if depth < 2 and not _is_id(prop.fixed_type):
                sub = getattr(struct, pid, None)
                if sub is not None:
                    _rna_values(sub, f"{prefix}.{pid}", out, depth + 1)
            elif _is_id(prop.fixed_type):
                ref = getattr(struct, pid, None)
                out[f"{prefix}.{pid}"] = None if ref is None else ref.name
            continue
        if prop.type == "COLLECTION":
            continue
        try:
            out[f"{prefix}.{pid}"] = _plain(getattr(struct, pid))
        except (AttributeError, RuntimeError):
            pass


def _node_tree_values(nt, prefix: str, out: dict) -> None:
    for node in nt.nodes:
        _rna_values(node, f"{prefix}.{node.name}", out, depth=2)
        for kind, sockets in (("in", node.inputs), ("out", node.outputs)):
            for i, sock in enumerate(sockets):
                if hasattr(sock, "default_value"):
                    out[f"{prefix}.{node.name}.{kind}{i}"] = _plain(sock.default_value)
    out[f"{prefix}.links"] = sorted(
        f"{ln.from_node.name}:{ln.from_socket.identifier}->{ln.to_node.name}:{ln.to_socket.identifier}"
        for ln in nt.links)


def scene_state(h: SceneHandles) -> dict:
    """Every property of the Blender scene a render can read (render and Cycles settings, objects,
    lights, camera, materials and world with their node values), as plain values by path.

    ``apply_frame`` sets every property it ever changes on every frame, so this state after
    ``apply_frame(h, frame)`` is a function of the static scene and ``frame`` alone, whatever was
    applied before (a test compares it across frame orders)."""
    out: dict = {}
    scene = h.scene
    _rna_values(scene, "scene", out)
    for vl in scene.view_layers:
        _rna_values(vl, f"view_layer[{vl.name}]", out)
    for kind in ("objects", "lights", "cameras", "meshes", "worlds", "materials", "actions"):
        for block in getattr(bpy.data, kind):
            _rna_values(block, f"{kind}[{block.name}]", out)
            if getattr(block, "node_tree", None) is not None:
                _node_tree_values(block.node_tree, f"{kind}[{block.name}].nodes", out)
    return out
