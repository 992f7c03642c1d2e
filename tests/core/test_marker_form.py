"""[markers] form: a raised puck or a flat printed plate (core.layout.base_depth_mm).

The disc is planar in both, so labels are exact for either; the form sets how far the marker's
dark base reaches below the disc (the puck's at least RING_BASE_DEPTH_MM, the plate's its
thickness plus the sagitta of its rim over the cylinder): never floating over the section. The
default is the flat plate (0.1 mm); the configs pinned to the puck render their scenes unchanged.
"""
import json
import math

import numpy as np
import pytest

from dockfactory.core.config import ConfigError, config_from_dict, config_from_identity, load_config
from dockfactory.core.layout import BASE_EMBED_MM, FORM_RAISE_MM, RING_BASE_DEPTH_MM, RING_EXTRA_MM, base_depth_mm
from dockfactory.core.scene import to_dict
from dockfactory.generator.marker_regions import halo_points
from dockfactory.generator.random_draws import static_scene


def _plate_reach(raise_mm, diameter_mm, radius_mm):
    r = diameter_mm / 2 + RING_EXTRA_MM
    return raise_mm + radius_mm - math.sqrt(radius_mm ** 2 - r ** 2) + BASE_EMBED_MM


@pytest.mark.parametrize("raise_mm, diameter_mm, radius_mm", [(0.1, 20.0, 300.0), (0.5, 30.0, 450.0), (0.2, 40, 150)])
def test_a_flat_plate_reaches_the_section_under_its_rim_and_no_further(raise_mm, diameter_mm, radius_mm):
    depth = base_depth_mm("flat", raise_mm, diameter_mm, radius_mm)
    assert depth == pytest.approx(_plate_reach(raise_mm, diameter_mm, radius_mm), abs=1e-12)
    # the plate's lowest rim point (across the cylinder) is BASE_EMBED_MM inside the section
    r = diameter_mm / 2 + RING_EXTRA_MM
    top = radius_mm + raise_mm                          # the disc's top face, radially from the axis
    rim_bottom = math.hypot(top - depth, r)             # distance of the plate's bottom rim from the axis
    assert rim_bottom == pytest.approx(radius_mm - BASE_EMBED_MM, abs=2e-3)


def test_a_puck_keeps_its_depth_unless_it_would_float():
    assert base_depth_mm("puck", 1.0, 20.0, 300.0) == RING_BASE_DEPTH_MM
    tall = base_depth_mm("puck", 3.0, 30.0, 300.0)
    assert tall == pytest.approx(_plate_reach(3.0, 30.0, 300.0)) and tall > RING_BASE_DEPTH_MM
    with pytest.raises(ValueError, match="marker form must be one of"):
        base_depth_mm("cube", 1.0, 20.0, 300.0)


def test_the_shipped_configs_scenes_carry_their_forms_depth(repo_root):
    """The configs pinned to the puck render their scenes as before (the depth not named, so the
    same bytes); every other one renders the default flat plate with its own depth."""
    paths = sorted((repo_root / "configs").glob("*.toml")) + sorted((repo_root / "bench" / "configs").glob("*.toml"))
    datasets = [p for p in paths if "[dataset]" in p.read_text()]        # not the acceptance or training configs
    assert len(datasets) >= 10
    forms = {}
    for path in datasets:
        cfg = load_config(path)
        static = static_scene(cfg)
        forms[path.name] = cfg.markers.form
        if cfg.markers.form == "puck":
            assert static.marker_base_depth_mm == RING_BASE_DEPTH_MM and cfg.markers.raise_mm == 1.0
            assert "marker_base_depth_mm" not in json.dumps(to_dict(static))
        else:
            assert cfg.markers.raise_mm == FORM_RAISE_MM["flat"]
            assert static.marker_base_depth_mm == pytest.approx(
                _plate_reach(0.1, cfg.markers.diameter_mm, cfg.sections.radius_mm))
    pinned = {"paper.toml", "detector.toml", "detector_colour.toml", "centre_scene_b.toml"}
    assert {n for n, f in forms.items() if f == "puck"} == pinned & set(forms)
    assert forms["quick.toml"] == "flat"


def test_a_flat_config_carries_its_depth_and_another_version():
    puck = config_from_dict({"markers": {"form": "puck", "raise_mm": 0.2}})
    flat = config_from_dict({"markers": {"form": "flat", "raise_mm": 0.2}})
    assert flat.canonical_json() != puck.canonical_json()                # another dataset version
    assert config_from_dict({"markers": {"form": "flat", "raise_mm": 0.1}}).canonical_json() == \
        config_from_dict({}).canonical_json()
    depth = static_scene(flat).marker_base_depth_mm
    assert to_dict(static_scene(flat))["marker_base_depth_mm"] == depth == pytest.approx(_plate_reach(0.2, 20, 300))
    assert static_scene(flat).markers == static_scene(puck).markers      # the same discs: the same labels


@pytest.mark.parametrize("markers, form, raise_mm", [
    ({}, "flat", 0.1), ({"form": "flat"}, "flat", 0.1), ({"form": "puck"}, "puck", 1.0),
    ({"form": "puck", "raise_mm": 2.0}, "puck", 2.0), ({"raise_mm": 0.3}, "flat", 0.3)])
def test_an_unset_raise_is_the_forms_own(markers, form, raise_mm):
    m = config_from_dict({"markers": markers}).markers
    assert (m.form, m.raise_mm) == (form, raise_mm)


def test_a_puck_dataset_stored_before_the_flat_default_reads_back_as_a_puck():
    """A stored identity without ``form`` was rendered as a puck (the form before the default
    changed); a puck config written out states its form, so it reads back a puck."""
    puck = config_from_dict({"markers": {"form": "puck"}})
    stored = puck.to_dict()
    assert "form" not in stored["markers"] and stored["markers"]["raise_mm"] == 1.0
    back = config_from_identity(stored)
    assert (back.markers.form, back.markers.raise_mm) == ("puck", 1.0) and back == puck
    assert puck.resolved_dict()["markers"]["form"] == "puck"
    assert config_from_dict(puck.resolved_dict()) == puck
    assert "form" in config_from_dict({}).to_dict()["markers"]         # a flat dataset names its form


def test_the_halo_reaches_the_bottom_of_the_base():
    m = static_scene(config_from_dict({})).markers[0]
    pts = halo_points(m, n=8, base_depth_mm=0.4)
    normal = np.asarray(m.normal)
    heights = (pts - np.asarray(m.center_mm)) @ normal
    assert np.allclose(heights[:8], 0, atol=1e-9) and np.allclose(heights[8:], -0.4, atol=1e-9)


@pytest.mark.parametrize("markers, message", [
    ({"form": "flat", "raise_mm": 1.0}, r"\[markers\] raise_mm: a flat marker is a printed plate at most 0.5 mm thick, got 1 "
                       r"\(set raise_mm, e.g. 0.2\)"),
    ({"form": "disc"}, r"\[markers\] form: 'disc' is not one of puck, flat"),
])
def test_a_bad_form_is_refused_in_one_line(markers, message):
    with pytest.raises(ConfigError, match=message):
        config_from_dict({"markers": markers})
