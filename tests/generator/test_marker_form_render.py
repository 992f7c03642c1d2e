"""[markers] form in Blender: each marker's base, built from the static scene, reaches from just
below the disc down into the section under its whole rim, for the puck and the flat plate
(core.layout.base_depth_mm), on a section radius where the plate's sagitta matters."""
import json
import subprocess
import sys

import numpy as np
import pytest

from dockfactory.core.config import config_from_dict
from dockfactory.core.scene import to_dict
from dockfactory.generator.random_draws import static_scene

pytestmark = pytest.mark.render

RING_VERTICES_SCRIPT = """
import json, sys
import bpy
import dockfactory
from dockfactory.core.scene import StaticScene, from_dict
from dockfactory.blender_scenes.render import BlenderRenderer
req = json.loads(sys.stdin.read())
renderer = BlenderRenderer(from_dict(StaticScene, req["static"]), 320, 240, 1, req["exr"])
bpy.context.view_layer.update()   # world matrices of the objects just built
objs = renderer.handles.scene.objects
out = {o.name: [list(o.matrix_world @ v.co) for v in o.data.vertices] for o in objs if o.name.startswith("ring_")}
print("RESULT " + json.dumps(out))
"""


@pytest.mark.parametrize("form, raise_mm", [("puck", 1.0), ("flat", 0.1)])
def test_every_marker_base_reaches_into_the_section_under_its_whole_rim(form, raise_mm, tmp_path):
    cfg = config_from_dict({"sections": {"radius_mm": 150.0}, "markers": {"form": form, "raise_mm": raise_mm,
                                                                          "diameter_mm": 30.0}})
    static = static_scene(cfg)
    req = {"static": to_dict(static), "exr": str(tmp_path / "x.exr")}
    run = subprocess.run([sys.executable, "-c", RING_VERTICES_SCRIPT], input=json.dumps(req), capture_output=True,
                         text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    rings = json.loads(next(line for line in run.stdout.splitlines() if line.startswith("RESULT "))[7:])
    assert len(rings) == len(static.markers)
    for m in static.markers:
        v = np.array(rings[f"ring_{m.id}"]) * 1000.0             # m -> mm, section A's frame (B docked at identity)
        height = (v - np.array(m.center_mm)) @ np.array(m.normal)
        assert height.max() == pytest.approx(-0.05, abs=1e-3) and height.min() == pytest.approx(
            -static.marker_base_depth_mm, abs=1e-3)
        bottom = v[height < -0.06]
        from_axis = np.hypot(bottom[:, 1], bottom[:, 2])        # the sections' axis is X
        assert from_axis.max() < cfg.sections.radius_mm - 0.04, (m.id, from_axis.max())   # in the section
        if form == "flat":                                      # and no deeper than the rim needs
            assert from_axis.max() > cfg.sections.radius_mm - 0.06, (m.id, from_axis.max())
