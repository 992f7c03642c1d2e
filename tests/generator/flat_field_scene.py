"""Run as a script (bpy, in its own process): render flat fields with the factory's Cycles settings.

    python flat_field_scene.py OUT_DIR SIZE STRENGTH [STRENGTH ...]

An emissive square fills an orthographic camera's view (world black, no other object), rendered
with ``blender_scenes.scene_builder.configure_render`` (the factory's render settings and
multilayer EXR passes) at 1 sample with the factory's fast denoise, one EXR per strength:
``OUT_DIR/flat_<k>.exr``. Used by test_flat_field_ptc.py.
"""
import sys
from pathlib import Path

import bpy

from dockfactory.blender_scenes.scene_builder import configure_render


def emissive_square(strength: float):
    mesh = bpy.data.meshes.new("flat")
    mesh.from_pydata([(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], [], [(0, 1, 2, 3)])
    obj = bpy.data.objects.new("flat", mesh)
    mat = bpy.data.materials.new("emit")
    mat.use_nodes = True
    nodes = mat.node_tree.nodes
    nodes.clear()
    emit = nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = strength
    emit.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    out = nodes.new("ShaderNodeOutputMaterial")
    mat.node_tree.links.new(emit.outputs["Emission"], out.inputs["Surface"])
    obj.data.materials.append(mat)
    return obj


def main(out_dir: str, size: int, strengths: list[float]) -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    world = bpy.data.worlds.new("black")
    world.color = (0.0, 0.0, 0.0)
    scene.world = world
    cam_data = bpy.data.cameras.new("cam")
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = 1.0
    cam = bpy.data.objects.new("cam", cam_data)
    cam.location = (0.0, 0.0, 1.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    for k, strength in enumerate(strengths):
        obj = emissive_square(strength)
        scene.collection.objects.link(obj)
        configure_render(scene, size, size, 1, str(Path(out_dir) / f"flat_{k}.exr"))
        scene.cycles.samples = 1
        scene.cycles.use_denoising = True
        bpy.ops.render.render(write_still=True)
        bpy.data.objects.remove(obj)


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), [float(s) for s in sys.argv[3:]])
