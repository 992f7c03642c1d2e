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


def test_pooled_renders_keep_every_frame_apart(monkeypatch):
    """``A+B`` measures both renders and keeps each one's frames under its own prefix (two renders of
    other seeds name their frames alike), the version of both, the settings of the first."""
    import bench.render.marker_sampling as bench

    def fake(root, weights):
        n = {"a": 2, "b": 3}[root.name]
        return {"version": root.name * 2, "marker_samples": 40, "timing": {"cycles_s": 1.0},
                "rows": {f"{i:06d}": {"err_x": i} for i in range(n)},
                "centres": {f"{i:06d}": [[0.0, 0.0]] for i in range(n)},
                "true": {f"{i:06d}": root.name for i in range(n)}}
    monkeypatch.setattr(bench, "measure", fake)
    got = bench.measure_pooled("out/a+out/b", None)
    assert got["version"] == "aa+bb" and got["marker_samples"] == 40
    assert sorted(got["rows"]) == ["0/000000", "0/000001", "1/000000", "1/000001", "1/000002"]
    assert got["true"]["0/000001"] == "a" and got["true"]["1/000001"] == "b"
    assert bench.measure_pooled("out/a", None)["rows"] == fake(__import__("pathlib").Path("out/a"), None)["rows"]
