"""Marker coverage for label-aware sampling's control variate (bpy).

Every marker disc and ring writes its class into the shader AOV :data:`COVERAGE_AOV` where a
camera ray hits it (R: disc, G: ring; everything else writes nothing, 0). Cycles accumulates an
AOV with the same samples and pixel filter as the colour, so a region's AOV holds the share of its
samples that landed on each class: the coverage those samples saw. Rendered again with every
shader replaced by :func:`coverage_material` (it shows the class and nothing else: no light, no
bounce, a small part of a full sample's cost) at many samples (adaptively: only the edges need
them), the AOV is the coverage the colour
converges to. ``dockfactory.generator.marker_coverage`` takes the colour's antialiasing noise out
with the difference of the two.
"""
from __future__ import annotations

import bpy

from dockfactory.core.names import MARKER_CLASS_AOV as COVERAGE_AOV

COVERAGE_MATERIAL = "marker_coverage"
DISC_CLASS = (1.0, 0.0, 0.0, 1.0)
RING_CLASS = (0.0, 1.0, 0.0, 1.0)
NO_CLASS = (0.0, 0.0, 0.0, 1.0)


def register_coverage_pass(view_layer) -> None:
    """The colour AOV :data:`COVERAGE_AOV` in ``view_layer``'s passes."""
    aov = view_layer.aovs.add()
    aov.name = COVERAGE_AOV
    aov.type = "COLOR"


def add_class_output(mat, colour) -> None:
    """Write ``colour`` (:data:`DISC_CLASS` or :data:`RING_CLASS`) into the coverage AOV from
    ``mat``'s node tree; its shading is untouched."""
    node = mat.node_tree.nodes.new("ShaderNodeOutputAOV")
    node.aov_name = COVERAGE_AOV
    node.inputs["Color"].default_value = colour


def coverage_material():
    """The override material of the coverage render: the object's colour (its class:
    :func:`set_classes`) as an emitter that is never sampled as a light (opaque, no light is
    sampled, no ray bounces; a material without a surface would let the rays through) and into
    the coverage AOV. The emitted class colour is what Cycles' adaptive sampling judges a pixel's
    convergence by (it reads the colour, not the AOV)."""
    mat = bpy.data.materials.new(COVERAGE_MATERIAL)
    mat.use_nodes = True
    mat.cycles.emission_sampling = "NONE"
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    info = nt.nodes.new("ShaderNodeObjectInfo")
    surface = nt.nodes.new("ShaderNodeEmission")
    nt.links.new(info.outputs["Color"], surface.inputs["Color"])
    nt.links.new(surface.outputs[0], nt.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    out = nt.nodes.new("ShaderNodeOutputAOV")
    out.aov_name = COVERAGE_AOV
    nt.links.new(info.outputs["Color"], out.inputs["Color"])
    return mat


def set_classes(objects, discs, rings) -> None:
    """Every object's colour (read only by :func:`coverage_material`): its class."""
    disc_names, ring_names = {o.name for o in discs}, {o.name for o in rings}
    for o in objects:
        o.color = DISC_CLASS if o.name in disc_names else RING_CLASS if o.name in ring_names else NO_CLASS
