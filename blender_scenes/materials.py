"""Node materials (bpy) and their per-frame parameters."""
from __future__ import annotations

import bpy


def _principled(mat):
    return next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")


def simple_material(name, color=(0.5, 0.5, 0.5), roughness=0.5, metallic=0.0):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    bsdf = _principled(mat)
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Metallic"].default_value = metallic
    return mat


def set_simple(mat, color=None, roughness=None, metallic=None):
    bsdf = _principled(mat)
    if color is not None:
        bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    if roughness is not None:
        bsdf.inputs["Roughness"].default_value = roughness
    if metallic is not None:
        bsdf.inputs["Metallic"].default_value = metallic


def paint_material(name):
    """Painted industrial metal: colour with grime and roughness varying by a noise texture.

    Frame parameters live on named nodes: "paint" (RGB), "grime" / "rough" / "rough_var"
    (Value), "mapping" (scale and location of the noise).
    """
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    bsdf = _principled(mat)
    coords = nt.nodes.new("ShaderNodeTexCoord")
    mapping = nt.nodes.new("ShaderNodeMapping")
    mapping.name = "mapping"
    noise = nt.nodes.new("ShaderNodeTexNoise")
    noise.inputs["Detail"].default_value = 6.0
    nt.links.new(coords.outputs["Object"], mapping.inputs["Vector"])
    nt.links.new(mapping.outputs["Vector"], noise.inputs["Vector"])

    def value(node_name, v):
        n = nt.nodes.new("ShaderNodeValue")
        n.name = node_name
        n.outputs[0].default_value = v
        return n

    paint = nt.nodes.new("ShaderNodeRGB")
    paint.name = "paint"
    grime, rough, rough_var = value("grime", 0.1), value("rough", 0.4), value("rough_var", 0.1)
    # colour = paint * (1 - grime * noise)
    g = nt.nodes.new("ShaderNodeMath")
    g.operation = "MULTIPLY"
    nt.links.new(grime.outputs[0], g.inputs[0])
    nt.links.new(noise.outputs["Fac"], g.inputs[1])
    inv = nt.nodes.new("ShaderNodeMath")
    inv.operation = "SUBTRACT"
    inv.inputs[0].default_value = 1.0
    nt.links.new(g.outputs[0], inv.inputs[1])
    col = nt.nodes.new("ShaderNodeMix")
    col.data_type = "RGBA"
    col.blend_type = "MULTIPLY"
    col.inputs["Factor"].default_value = 1.0
    nt.links.new(paint.outputs[0], col.inputs[6])
    nt.links.new(inv.outputs[0], col.inputs[7])
    nt.links.new(col.outputs[2], bsdf.inputs["Base Color"])
    # roughness = rough + rough_var * (noise - 0.5)
    centred = nt.nodes.new("ShaderNodeMath")
    centred.operation = "SUBTRACT"
    nt.links.new(noise.outputs["Fac"], centred.inputs[0])
    centred.inputs[1].default_value = 0.5
    scaled = nt.nodes.new("ShaderNodeMath")
    scaled.operation = "MULTIPLY"
    nt.links.new(centred.outputs[0], scaled.inputs[0])
    nt.links.new(rough_var.outputs[0], scaled.inputs[1])
    total = nt.nodes.new("ShaderNodeMath")
    total.operation = "ADD"
    total.use_clamp = True
    nt.links.new(rough.outputs[0], total.inputs[0])
    nt.links.new(scaled.outputs[0], total.inputs[1])
    nt.links.new(total.outputs[0], bsdf.inputs["Roughness"])
    return mat


def set_paint(mat, color, metallic, roughness, roughness_variation, grime, scale, offset):
    nt = mat.node_tree
    nt.nodes["paint"].outputs[0].default_value = (*color, 1.0)
    nt.nodes["grime"].outputs[0].default_value = grime
    nt.nodes["rough"].outputs[0].default_value = roughness
    nt.nodes["rough_var"].outputs[0].default_value = roughness_variation
    mapping = nt.nodes["mapping"]
    mapping.inputs["Scale"].default_value = (scale, scale, scale)
    mapping.inputs["Location"].default_value = offset
    _principled(mat).inputs["Metallic"].default_value = metallic


def emission_material(name):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        if n.type != "OUTPUT_MATERIAL":
            nt.nodes.remove(n)
    em = nt.nodes.new("ShaderNodeEmission")
    em.name = "emission"
    nt.links.new(em.outputs[0], nt.nodes["Material Output"].inputs["Surface"])
    return mat


def set_emission(mat, color, strength):
    em = mat.node_tree.nodes["emission"]
    em.inputs["Color"].default_value = (*color, 1.0)
    em.inputs["Strength"].default_value = strength


def world(scene):
    w = bpy.data.worlds.new("world")
    scene.world = w
    w.use_nodes = True
    return w


def set_world(w, color, strength):
    bg = w.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (*color, 1.0)
    bg.inputs["Strength"].default_value = strength
