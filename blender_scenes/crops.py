"""Label-aware sampling in Blender: the marker regions rendered again, cropped (bpy).

Which regions, and how they are blended into the frame, is decided without bpy
(``dockfactory.generator.marker_regions``); this renders them with Cycles' border render.
"""
from __future__ import annotations

import bpy

from dockfactory.blender_scenes.frame_update import DENOISE_QUALITY, apply_render_settings

# Blender turns the border (a share of the canvas) into pixels by truncation: a quarter pixel
# past each pixel boundary lands on that boundary whatever the float rounding.
BORDER_NUDGE_PX = 0.25


def crop_path(exr_path: str, i: int) -> str:
    """The scratch EXR of region ``i`` of the frame rendered into ``exr_path``."""
    stem = exr_path[:-4] if exr_path.endswith(".exr") else exr_path
    return f"{stem}_crop{i}.exr"


def _set_border(render, region, wc: int, hc: int) -> None:
    """Border of ``region`` (canvas pixels, rows from the top) in Blender's terms (shares of the
    canvas, rows from the bottom)."""
    render.border_min_x = (region.x0 + BORDER_NUDGE_PX) / wc
    render.border_max_x = min(1.0, (region.x1 + BORDER_NUDGE_PX) / wc)
    render.border_min_y = (hc - region.y1 + BORDER_NUDGE_PX) / hc
    render.border_max_y = min(1.0, (hc - region.y0 + BORDER_NUDGE_PX) / hc)


def render_crops(scene, frame, regions, exr_path: str) -> list[str]:
    """Render each of ``regions`` (generator.marker_regions.Region) of the frame already applied to
    ``scene`` at ``frame.render.marker_samples`` samples (with ``marker_adaptive_threshold`` > 0:
    adaptive sampling up to that many, Cycles' automatic minimum), denoised by ``marker_denoise``
    (off: not at all), with Cycles' light tree unless ``light_tree`` is off (it picks the light a
    sample goes to by its contribution there: less noise per sample at the markers), into :func:`crop_path` files cropped to the region; returns their paths. The render
    settings are put back as ``apply_frame`` set them (no border, the frame's samples,
    denoiser and light tree), so what a frame leaves behind does not depend on its crops."""
    r, c, rs = scene.render, scene.cycles, frame.render
    wc, hc = r.resolution_x, r.resolution_y
    paths = []
    c.samples = rs.marker_samples
    c.use_adaptive_sampling = rs.marker_adaptive_threshold > 0
    c.adaptive_threshold = rs.marker_adaptive_threshold
    c.adaptive_min_samples = 0
    c.use_denoising = rs.marker_denoise != "off"
    c.use_light_tree = rs.light_tree != "off"
    if c.use_denoising:
        c.denoising_quality = DENOISE_QUALITY[rs.marker_denoise]
    r.use_border = r.use_crop_to_border = True
    try:
        for i, region in enumerate(regions):
            _set_border(r, region, wc, hc)
            r.filepath = crop_path(exr_path, i)
            bpy.ops.render.render(write_still=True)
            paths.append(r.filepath)
    finally:
        apply_render_settings(scene, frame)
        r.filepath = exr_path
    return paths
