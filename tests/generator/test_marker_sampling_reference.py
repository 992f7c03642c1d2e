"""The label-aware sampling bench compares against a converged reference only: a dataset rendered
with the adaptive default, a denoiser or the coverage correction at the markers is refused as one."""
from __future__ import annotations

from dataclasses import replace

import pytest

from bench.render.marker_sampling import reference_problems
from dockfactory.core.config import load_config
from dockfactory.core.resources import shipped_config


@pytest.fixture(scope="module")
def render():
    return load_config(shipped_config("quick")).render


def test_the_documented_reference_is_converged(render):
    ref = replace(render, marker_samples=256, marker_adaptive_threshold=0.0, marker_denoise="off",
                  marker_coverage_samples=0)
    assert reference_problems(ref) == []


@pytest.mark.parametrize("change, needle", [
    ({"marker_adaptive_threshold": 0.02}, "marker_adaptive_threshold = 0.02"),
    ({"marker_samples": 32}, "marker_samples = 32"),
    ({"marker_denoise": "fast"}, "marker_denoise = 'fast'"),
    ({"marker_coverage_samples": 128}, "marker_coverage_samples = 128"),
])
def test_each_unconverged_setting_is_named(render, change, needle):
    ref = replace(render, **{"marker_samples": 256, "marker_adaptive_threshold": 0.0, "marker_denoise": "off",
                             "marker_coverage_samples": 0, **change})
    problems = reference_problems(ref)
    assert len(problems) == 1 and problems[0].startswith(needle)
