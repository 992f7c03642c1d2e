"""Apply one frozen FrameScene to the built Blender scene (bpy): transforms, lights, materials."""
from __future__ import annotations

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


def _blender_matrix(d_from_x, scale_xyz_mm=None) -> Matrix:
    m = np.array(d_from_x, dtype=float)
    m[:3, 3] *= MM
    if scale_xyz_mm is not None:
        m[:3, :3] = m[:3, :3] @ np.diag(np.asarray(scale_xyz_mm) * MM)
    return Matrix(m.tolist())


def _apply_render_settings(scene, frame: FrameScene) -> None:
    """Cycles samples, seed, bounces, adaptive sampling, filter and denoising of the frame."""
    c = scene.cycles
    rs = frame.render
    c.samples = rs.samples
    c.seed = frame.render_seed
    c.max_bounces = rs.max_bounces
    c.use_adaptive_sampling = rs.adaptive_threshold > 0
    if rs.adaptive_threshold > 0:
        c.adaptive_threshold = rs.adaptive_threshold
        c.adaptive_min_samples = rs.adaptive_min_samples
    c.filter_width = rs.filter_width_px
    c.use_denoising = rs.denoise != "off"
    if rs.denoise != "off":
        c.denoising_quality = DENOISE_QUALITY[rs.denoise]
        c.denoising_prefilter = rs.denoise_prefilter.upper()


def _apply_camera(h: SceneHandles, cam) -> None:
    h.camera.matrix_world = Matrix(blender_world_from_camera(cam.cam_from_d_array(), MM).tolist())
    intr = blender_camera_intrinsics(cam.focal_px, cam.principal_point, cam.width, cam.height)
    h.camera.data.lens = intr["lens_mm"]
    h.camera.data.sensor_width = intr["sensor_width_mm"]
    h.camera.data.shift_x = intr["shift_x"]
    h.camera.data.shift_y = intr["shift_y"]


def _apply_lights(h: SceneHandles, frame: FrameScene) -> None:
    """Place and switch on the frame's lights; the others are hidden."""
    lights = {light.name: light for light in frame.lights}
    for name, obj in h.lights.items():
        light = lights.get(name)
        on = light is not None and light.power_w > 0
        obj.hide_render = not on
        if on:
            obj.matrix_world = _blender_matrix(light.d_from_light)
            obj.data.energy = light.power_w
            obj.data.size = light.size_mm * MM
            obj.data.color = light.color


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
    """Show the frame's props from the pooled objects; hide every pooled object it does not use."""
    used = set()
    for p in frame.props:
        key = (p.kind, p.slot)
        if key not in h.props:
            raise ValueError(f"frame {frame.spec.frame_id}: no pooled object for {p.kind} slot {p.slot}")
        used.add(key)
        obj = h.props[key]
        obj.matrix_world = _blender_matrix(p.d_from_prop, p.size_mm)
        obj.hide_render = False
        if p.kind == "lamp":
            mats.set_emission(h.prop_materials[key], p.color, p.emission)
        else:
            mats.set_diffuse(h.prop_materials[key], color=p.color)
    for key, obj in h.props.items():
        if key not in used:
            obj.hide_render = True


def apply_frame(h: SceneHandles, frame: FrameScene) -> None:
    _apply_render_settings(h.scene, frame)
    h.b_root.matrix_world = _blender_matrix(frame.d_from_b)
    _apply_camera(h, frame.camera)
    _apply_lights(h, frame)
    _apply_appearance(h, frame.appearance)
    _apply_props(h, frame)
