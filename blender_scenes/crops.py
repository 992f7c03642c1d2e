"""Label-aware sampling in Blender: the marker regions rendered again, cropped (bpy).

Which regions, and how they are blended into the frame, is decided without bpy
(``dockfactory.generator.marker_regions``); this renders them with Cycles' border render.
"""
from __future__ import annotations

import bpy

from dockfactory.blender_scenes.coverage import COVERAGE_MATERIAL
from dockfactory.blender_scenes.frame_update import DENOISE_QUALITY, apply_render_settings

# Blender turns the border (a share of the canvas) into pixels by truncation: a quarter pixel
# past each pixel boundary lands on that boundary whatever the float rounding.
BORDER_NUDGE_PX = 0.25
# The coverage render's adaptive minimum. Cycles' automatic one grows as the threshold falls (most
# of the samples at the thresholds a coverage needs); a pixel whose first samples all land on one
# class is inside it, and an edge pixel's neighbours keep sampling with it (Cycles' convergence
# filter), so the edges still get every sample (bench/results/marker_sampling/README.md).
COVERAGE_MIN_SAMPLES = 16


def crop_path(exr_path: str, i: int, kind: str = "crop") -> str:
    """The scratch EXR of region ``i`` of the frame rendered into ``exr_path`` (``kind`` "crop":
    its colour; "cov": its coverage render)."""
    stem = exr_path[:-4] if exr_path.endswith(".exr") else exr_path
    return f"{stem}_{kind}{i}.exr"


def _set_border(render, region, wc: int, hc: int) -> None:
    """Border of ``region`` (canvas pixels, rows from the top) in Blender's terms (shares of the
    canvas, rows from the bottom)."""
    render.border_min_x = (region.x0 + BORDER_NUDGE_PX) / wc
    render.border_max_x = min(1.0, (region.x1 + BORDER_NUDGE_PX) / wc)
    render.border_min_y = (hc - region.y1 + BORDER_NUDGE_PX) / hc
    render.border_max_y = min(1.0, (hc - region.y0 + BORDER_NUDGE_PX) / hc)


def _render_regions(scene, regions, exr_path: str, kind: str) -> list[str]:
    """Border-render each region into its :func:`crop_path` of ``kind``; the paths."""
    r = scene.render
    wc, hc = r.resolution_x, r.resolution_y
    r.use_border = r.use_crop_to_border = True
    paths = []
    # One frame's regions are one scene: Cycles keeps its copy between them (persistent data)
    # instead of syncing the scene afresh for each, and drops it after the last, so no frame
    # inherits another's (scene_builder: why persistent data is off between frames).
    r.use_persistent_data = True
    try:
        for i, region in enumerate(regions):
            _set_border(r, region, wc, hc)
            r.filepath = crop_path(exr_path, i, kind)
            bpy.ops.render.render(write_still=True)
            paths.append(r.filepath)
    finally:
        r.use_persistent_data = False
    return paths


def render_crops(scene, frame, regions, exr_path: str) -> list[str]:
    """Render each of ``regions`` (generator.marker_regions.Region) of the frame already applied to
    ``scene`` at ``frame.render.marker_samples`` samples (with ``marker_adaptive_threshold`` > 0:
    adaptive sampling up to that many from ``marker_adaptive_min_samples``, 0: Cycles' automatic
    minimum), denoised by ``marker_denoise``
    (off: not at all; on, the file holds the colour before denoising too, "Noisy Image"), with
    Cycles' light tree unless ``light_tree`` is off (it picks the light a sample goes to by its
    contribution there: less noise per sample at the markers), into :func:`crop_path` files
    cropped to the region; returns their paths in region order. The render settings are put back
    as ``apply_frame`` set them (no border, the frame's samples, denoiser and light tree), so what
    a frame leaves behind does not depend on its crops."""
    c, rs = scene.cycles, frame.render
    c.samples = rs.marker_samples
    c.use_adaptive_sampling = rs.marker_adaptive_threshold > 0
    c.adaptive_threshold = rs.marker_adaptive_threshold
    c.adaptive_min_samples = rs.marker_adaptive_min_samples
    c.use_denoising = rs.marker_denoise != "off"
    c.use_light_tree = rs.light_tree != "off"
    if c.use_denoising:
        c.denoising_quality = DENOISE_QUALITY[rs.marker_denoise]
    try:
        return _render_regions(scene, regions, exr_path, "crop")
    finally:
        apply_render_settings(scene, frame)
        scene.render.filepath = exr_path


def render_coverage(scene, frame, regions, exr_path: str) -> list[str]:
    """Each region again at ``frame.render.marker_coverage_samples`` samples with every shader
    replaced by the coverage material (blender_scenes.coverage: the classes' exact coverage in
    its AOV), no bounce, no denoiser, no light tree; with ``marker_coverage_threshold`` > 0
    adaptive sampling up to those samples from :data:`COVERAGE_MIN_SAMPLES`: the material shows each
    class in its colour, so a pixel across an edge keeps sampling and one inside a class stops
    early. The "cov" :func:`crop_path` files in region order. The override and every render
    setting are put back as ``apply_frame`` set them, whatever happens."""
    c, vl, rs = scene.cycles, scene.view_layers[0], frame.render
    c.samples = rs.marker_coverage_samples
    c.use_denoising = c.use_light_tree = False
    c.use_adaptive_sampling = rs.marker_coverage_threshold > 0
    c.adaptive_threshold = rs.marker_coverage_threshold
    c.adaptive_min_samples = min(COVERAGE_MIN_SAMPLES, rs.marker_coverage_samples)
    c.max_bounces = 0
    vl.material_override = bpy.data.materials[COVERAGE_MATERIAL]
    try:
        return _render_regions(scene, regions, exr_path, "cov")
    finally:
        vl.material_override = None
        apply_render_settings(scene, frame)
        scene.render.filepath = exr_path
        vl.update()      # the evaluated scene too: nothing of the override left for the next frame
