"""``dockfactory render --reference N``: the converged reference's settings in one flag. The config
it makes is what the sampling bench accepts as a reference (and the default is not), its dataset
version is the one the same keys given by hand make, and a count below the floor or a ``--set`` of
one of its own keys is one line and nothing rendered."""
from __future__ import annotations

import pytest

from bench.render.marker_sampling import reference_problems
from dockfactory.cli import main
from dockfactory.cli_factory import load_checked
from dockfactory.core.errors import DockfactoryError
from dockfactory.generator.reference_render import REFERENCE_SAMPLES, reference_overrides
from dockfactory.generator.version import dataset_version_id

BY_HAND = ["render.marker_coverage_threshold=0", "render.marker_light_smoothing_px=0", "render.marker_denoise=off",
           "render.marker_adaptive_min_samples=0", "render.marker_coverage_source=render",
           "render.marker_adaptive_threshold=0", "render.marker_coverage_samples=0"]


def _version(sets) -> str:
    cfg, _ = load_checked("smoke", sets)
    return dataset_version_id(cfg.canonical_json(), "bpy", "gen")


def test_the_reference_is_what_the_bench_takes_for_one_and_the_default_is_not():
    ref, _ = load_checked("smoke", reference_overrides(REFERENCE_SAMPLES, ["dataset.frames=3"]))
    assert reference_problems(ref.render) == []
    assert ref.render.marker_samples == 1024 and ref.dataset.frames == 3
    default, _ = load_checked("smoke", ["render.marker_samples=40"])
    assert reference_problems(default.render) != []


def test_its_dataset_version_is_that_of_the_same_keys_set_by_hand_in_any_order():
    assert _version(reference_overrides(512, [])) == _version(["render.marker_samples=512", *BY_HAND])
    assert _version(reference_overrides(512, [])) != _version(reference_overrides(1024, []))


@pytest.mark.parametrize("samples, sets, needle", [
    (100, [], "--reference: expected at least 256 samples, got 100"),
    (1024, ["render.marker_denoise=fast"], "--reference sets render.marker_denoise itself: leave it out of --set"),
])
def test_a_bad_reference_is_one_line(samples, sets, needle):
    with pytest.raises(DockfactoryError) as exc:
        reference_overrides(samples, sets)
    assert str(exc.value) == needle


def test_the_cli_refuses_it_before_writing_anything(tmp_path, capsys):
    out = tmp_path / "ref"
    assert main(["render", "smoke", "--out", str(out), "--reference", "--set", "render.marker_samples=8"]) == 2
    assert not out.exists()
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["dockfactory: error: --reference sets render.marker_samples itself: leave it out of --set"]
