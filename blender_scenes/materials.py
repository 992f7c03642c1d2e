"""Node materials (bpy) and their per-frame parameters.

Cycles' Principled BSDF (multiscatter GGX, energy compensation) costs about 40 % of the render
time in this scene at 1-2 samples; a mix of a Diffuse and a single-scatter GGX Glossy BSDF gives
painted metal for much less, so every material here is built from those two.
"""
from __future__ import annotations

import bpy


def _clear(nt):
    for n in list(nt.nodes):
        if n.type != "OUTPUT_MATERIAL":
            nt.nodes.remove(n)
    return nt.nodes["Material Output"]


def _value(nt, name, v):
    n = nt.nodes.new("ShaderNodeValue")
    n.name = name
    n.outputs[0].default_value = v
    return n


def _math(nt, op, a, b, clamp=False):
    n = nt.nodes.new("ShaderNodeMath")
    n.operation = op
    n.use_clamp = clamp
    for i, src in enumerate((a, b)):
        if isinstance(src, (int, float)):
            n.inputs[i].default_value = float(src)
        else:
            nt.links.new(src, n.inputs[i])
    return n.outputs[0]


def diffuse_material(name, color=(0.5, 0.5, 0.5), gloss=0.0, roughness=0.5):
    """Matte colour with an optional glossy share ``gloss`` (node names: "color", "gloss", "rough")."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    out = _clear(nt)
    rgb = nt.nodes.new("ShaderNodeRGB")
    rgb.name = "color"
    rgb.outputs[0].default_value = (*color, 1.0)
    diffuse = nt.nodes.new("ShaderNodeBsdfDiffuse")
    nt.links.new(rgb.outputs[0], diffuse.inputs["Color"])
    if gloss <= 0:
        nt.links.new(diffuse.outputs[0], out.inputs["Surface"])
        return mat
    glossy = nt.nodes.new("ShaderNodeBsdfGlossy")
    glossy.distribution = "GGX"
    nt.links.new(_value(nt, "rough", roughness).outputs[0], glossy.inputs["Roughness"])
    mix = nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(_value(nt, "gloss", gloss).outputs[0], mix.inputs[0])
    nt.links.new(diffuse.outputs[0], mix.inputs[1])
    nt.links.new(glossy.outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], out.inputs["Surface"])
    return mat


def set_diffuse(mat, color=None, gloss=None, roughness=None):
    nodes = mat.node_tree.nodes
    if color is not None:
        nodes["color"].outputs[0].default_value = (*color, 1.0)
    if gloss is not None:
        nodes["gloss"].outputs[0].default_value = gloss
    if roughness is not None:
        nodes["rough"].outputs[0].default_value = roughness


def _noise_factor(nt):
    """The "Fac" output of a one-octave noise texture on object coordinates (mapping node "mapping")."""
    coords = nt.nodes.new("ShaderNodeTexCoord")
    mapping = nt.nodes.new("ShaderNodeMapping")
    mapping.name = "mapping"
    noise = nt.nodes.new("ShaderNodeTexNoise")
    noise.inputs["Detail"].default_value = 0.0   # one octave: finer octaves cost ~10 % of the render at 1 spp
    nt.links.new(coords.outputs["Object"], mapping.inputs["Vector"])
    nt.links.new(mapping.outputs["Vector"], noise.inputs["Vector"])
    return noise.outputs["Fac"]


def _grimy_colour(nt, paint, grime, fac):
    """Diffuse colour = paint * (1 - grime * noise); returns the colour output."""
    darken = _math(nt, "SUBTRACT", 1.0, _math(nt, "MULTIPLY", grime.outputs[0], fac))
    col = nt.nodes.new("ShaderNodeMix")
    col.data_type = "RGBA"
    col.blend_type = "MULTIPLY"
    col.inputs["Factor"].default_value = 1.0
    nt.links.new(paint.outputs[0], col.inputs[6])
    nt.links.new(darken, col.inputs[7])
    return col.outputs[2]


def _glossy_tint(nt, metal, paint):
    """Glossy tint between white (paint clear coat) and the paint colour (metal); the colour output."""
    tint = nt.nodes.new("ShaderNodeMix")
    tint.data_type = "RGBA"
    tint.inputs[6].default_value = (1.0, 1.0, 1.0, 1.0)
    nt.links.new(metal.outputs[0], tint.inputs["Factor"])
    nt.links.new(paint.outputs[0], tint.inputs[7])
    return tint.outputs[2]


def _diffuse_glossy_mix(nt, out, colour, tint, roughness, metal) -> None:
    """Diffuse + GGX glossy into ``out``; the glossy share grows with metalness and at grazing
    angles (layer weight)."""
    diffuse = nt.nodes.new("ShaderNodeBsdfDiffuse")
    nt.links.new(colour, diffuse.inputs["Color"])
    glossy = nt.nodes.new("ShaderNodeBsdfGlossy")
    glossy.distribution = "GGX"
    nt.links.new(tint, glossy.inputs["Color"])
    nt.links.new(roughness, glossy.inputs["Roughness"])
    layer = nt.nodes.new("ShaderNodeLayerWeight")
    layer.inputs["Blend"].default_value = 0.3
    share = _math(nt, "ADD", _math(nt, "MULTIPLY", metal.outputs[0], 0.6),
                  _math(nt, "MULTIPLY", layer.outputs["Fresnel"], 0.4), clamp=True)
    mix = nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(share, mix.inputs[0])
    nt.links.new(diffuse.outputs[0], mix.inputs[1])
    nt.links.new(glossy.outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], out.inputs["Surface"])


def paint_material(name):
    """Painted industrial metal: a noise texture drives grime (darker paint) and roughness.

    Named nodes set per frame: "paint" (RGB), "metal" (glossy share), "grime", "rough",
    "rough_var" (Value), "mapping" (noise scale and offset).
    """
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    out = _clear(nt)
    fac = _noise_factor(nt)
    paint = nt.nodes.new("ShaderNodeRGB")
    paint.name = "paint"
    grime, rough, rough_var = _value(nt, "grime", 0.1), _value(nt, "rough", 0.4), _value(nt, "rough_var", 0.1)
    metal = _value(nt, "metal", 0.3)
    colour = _grimy_colour(nt, paint, grime, fac)
    # roughness = rough + rough_var * (noise - 0.5)
    roughness = _math(nt, "ADD", rough.outputs[0],
                      _math(nt, "MULTIPLY", _math(nt, "SUBTRACT", fac, 0.5), rough_var.outputs[0]), clamp=True)
    tint = _glossy_tint(nt, metal, paint)
    _diffuse_glossy_mix(nt, out, colour, tint, roughness, metal)
    return mat


def set_paint(mat, color, metallic, roughness, roughness_variation, grime, scale, offset):
    nodes = mat.node_tree.nodes
    nodes["paint"].outputs[0].default_value = (*color, 1.0)
    nodes["metal"].outputs[0].default_value = metallic
    nodes["grime"].outputs[0].default_value = grime
    nodes["rough"].outputs[0].default_value = roughness
    nodes["rough_var"].outputs[0].default_value = roughness_variation
    nodes["mapping"].inputs["Scale"].default_value = (scale, scale, scale)
    nodes["mapping"].inputs["Location"].default_value = offset


def emission_material(name):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    out = _clear(nt)
    em = nt.nodes.new("ShaderNodeEmission")
    em.name = "emission"
    nt.links.new(em.outputs[0], out.inputs["Surface"])
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
