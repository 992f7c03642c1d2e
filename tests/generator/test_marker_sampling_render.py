"""Label-aware sampling through Cycles (small frames): the crops land on the right pixels, the
labels and the rest of the frame do not change, the worker's state does not remember the crops,
and a re-render is the same bytes; with the coverage correction too (its effect on the noise:
test_marker_coverage_render.py)."""
import dataclasses
import json

import numpy as np
import pytest

from dockfactory.core.config import config_from_dict
from dockfactory.core.scene import to_dict
from dockfactory.generator.exr import read_compact
from dockfactory.generator.frame_output import frame_paths
from dockfactory.generator.marker_regions import halo_weights, marker_halos, marker_regions
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.sampler import frame_plan, sample_frame
from render_workers import start_worker

pytestmark = pytest.mark.render

TIMEOUT_S = 300
SAMPLES = 8
COVERAGE_SAMPLES = 64
CONFIG = {
    "dataset": {"name": "marker-sampling-check", "seed": 31, "frames": 2},
    "conditions": {"normal": 1, "low_light": 0, "occlusion": 0, "glare": 0},
    "image": {"width": 320, "height": 240},
    "camera": {"focal_px": [200.0, 280.0]},
    "render": {"marker_samples": SAMPLES, "marker_denoise": "off", "marker_coverage_samples": 0, "keep_exr": True,
               "marker_adaptive_threshold": 0.0,
               "frame_timeout_s": TIMEOUT_S},
}


def _variant(frame, frame_id, **render):
    return dataclasses.replace(frame, render=dataclasses.replace(frame.render, **render),
                               spec=dataclasses.replace(frame.spec, frame_id=frame_id))


@pytest.fixture(scope="module")
def setup():
    cfg = config_from_dict(CONFIG, "marker-sampling-check")
    frame = sample_frame(cfg, frame_plan(cfg)[0])
    return cfg, {"crops": _variant(frame, "crops"),
                 "plain": _variant(frame, "plain", marker_samples=0),
                 "uniform": _variant(frame, "uniform", marker_samples=0, samples=SAMPLES, denoise="off",
                                             light_tree="on"),
                 "adaptive": _variant(frame, "adaptive", marker_samples=4 * SAMPLES, marker_adaptive_threshold=0.1),
                 "coverage": _variant(frame, "coverage", marker_coverage_samples=COVERAGE_SAMPLES,
                                      marker_coverage_threshold=0.005),
                 # a threshold every pixel meets at once: the crops' samples are their minimum
                 "early": _variant(frame, "early", marker_samples=4 * SAMPLES, marker_adaptive_threshold=0.5,
                                   marker_adaptive_min_samples=1),
                 "kept": _variant(frame, "kept", marker_samples=4 * SAMPLES, marker_adaptive_threshold=0.5,
                                  marker_adaptive_min_samples=4 * SAMPLES),
                 "converged": _variant(frame, "converged", marker_samples=32 * SAMPLES),
}


def _worker(cfg, root):
    return start_worker(cfg, root, TIMEOUT_S)


@pytest.fixture(scope="module")
def rendered(setup, tmp_path_factory):
    """One worker renders the frame without crops, with them, and uniformly at the crops' samples;
    the state digests of the plain frame after the plain render and after the crops (a render
    evaluates the scene, so both follow one)."""
    cfg, frames = setup
    root = tmp_path_factory.mktemp("ls") / "ds"
    proc = _worker(cfg, root)
    try:
        digests = []
        for name in ("plain", "crops", "uniform", "adaptive", "coverage", "early", "kept", "converged"):
            reply = proc.request({"op": "render", "frame": to_dict(frames[name])}, TIMEOUT_S)
            assert reply.get("ok"), reply
            if name in ("plain", "crops", "coverage"):
                digests.append(proc.request({"op": "state", "frame": to_dict(frames["plain"])}, TIMEOUT_S)["digest"])
    finally:
        proc.close()
    return root, digests


def _exr(root, name):
    return read_compact(frame_paths(root, name)["exr"])


def test_region_interiors_are_the_uniform_render_and_the_rest_is_the_plain_one(setup, rendered):
    """Pixel for pixel (the kept EXR, half floats): where the blend is 1 the crops equal a whole
    frame rendered at the crops' samples without the denoiser and with the light tree (so the
    border lands on the right pixels, and the crops were rendered with the tree); across the
    feather, out to the rectangle's own edge pixels, the blend of those two frames (to half-float
    rounding: a border render's edge pixels are the whole frame's, so the rectangle needs no margin
    beyond the feather); and wherever the blend is 0 the frame is the one rendered without crops."""
    cfg, frames = setup
    root, _ = rendered
    crops, plain, uniform = (_exr(root, n).rgb for n in ("crops", "plain", "uniform"))
    regions = marker_regions(frames["crops"], static_scene(cfg))
    halos = marker_halos(frames["crops"], static_scene(cfg))
    assert len(regions) >= 1
    covered = np.zeros(crops.shape[:2], bool)
    for r in regions:
        w = halo_weights(halos, r)
        inner = w == 1.0
        assert inner.sum() > 100
        assert np.array_equal(crops[r.y0:r.y1, r.x0:r.x1][inner], uniform[r.y0:r.y1, r.x0:r.x1][inner])
        assert not np.array_equal(crops[r.y0:r.y1, r.x0:r.x1][inner], plain[r.y0:r.y1, r.x0:r.x1][inner])
        feather = (w > 0) & (w < 1)
        ys, xs = np.nonzero(feather)   # the feather reaches within a pixel of the rectangle's edge
        assert min(ys.min(), xs.min(), w.shape[0] - 1 - ys.max(), w.shape[1] - 1 - xs.max()) <= 1
        p, u = plain[r.y0:r.y1, r.x0:r.x1][feather], uniform[r.y0:r.y1, r.x0:r.x1][feather]
        want = p + w[feather][:, None] * (u - p)
        np.testing.assert_allclose(crops[r.y0:r.y1, r.x0:r.x1][feather], want, rtol=3e-3, atol=1e-4)
        covered[r.y0:r.y1, r.x0:r.x1] = w > 0
    assert np.array_equal(crops[~covered], plain[~covered])


# what a label measures on the delivered image rather than the geometry: the disc's colour (and
# whether it is legible) and the auto exposure, read off the (now cleaner) pixels
IMAGE_FIELDS = ("chroma", "legible")


@pytest.mark.parametrize("name", ["crops", "adaptive", "coverage"])
def test_labels_and_geometry_passes_are_those_of_the_plain_render(rendered, name):
    """Every geometric label field is the plain render's; the image-measured ones may differ (and
    the cleaner markers do show more colour); with uniform and with adaptive sampling."""
    root, _ = rendered
    a = json.loads(frame_paths(root, name)["label"].read_text())
    b = json.loads(frame_paths(root, "plain")["label"].read_text())
    assert a["sampled"]["render"]["marker_samples"] > 0 and "marker_samples" not in b["sampled"]["render"]
    assert a["derived"]["auto_exposure_scale"] == pytest.approx(b["derived"]["auto_exposure_scale"], rel=0.01)
    chroma = [(ma["chroma"], mb["chroma"]) for ma, mb in zip(a["markers"], b["markers"]) if ma["chroma"] is not None]
    assert np.mean([c[0] for c in chroma]) > np.mean([c[1] for c in chroma])
    for lab in (a, b):
        for key in ("marker_samples", "marker_denoise", "marker_adaptive_threshold", "marker_adaptive_min_samples",
                    "marker_coverage_samples", "marker_coverage_threshold", "marker_light_smoothing_px"):
            lab["sampled"]["render"].pop(key, None)
        lab.pop("frame_id")
        lab["spec"].pop("frame_id")
        lab["derived"].pop("auto_exposure_scale")
        for m in lab["markers"]:
            for k in IMAGE_FIELDS:
                m.pop(k, None)
    assert a == b
    pa, pb = _exr(root, name), _exr(root, "plain")
    assert np.array_equal(pa.index, pb.index) and np.array_equal(pa.depth_mm, pb.depth_mm)


def test_the_adaptive_minimum_is_the_samples_a_pixel_keeps(setup, rendered):
    """At a threshold every pixel meets at once, the crops stop at their minimum: with a minimum
    of all 32 samples the marker pixels' squared error against a 256-sample render is under 0.6x
    the error with a minimum of 1 (about 0.35x measured: Cycles' first check comes after a few
    samples, and the 256-sample render's own noise is in both)."""
    cfg, frames = setup
    root, _ = rendered
    early, kept, ref = (_exr(root, n).rgb.astype(np.float64) for n in ("early", "kept", "converged"))
    halos = marker_halos(frames["early"], static_scene(cfg))
    ratios = []
    for r in marker_regions(frames["early"], static_scene(cfg)):
        inner = halo_weights(halos, r) == 1.0
        crop = (slice(r.y0, r.y1), slice(r.x0, r.x1))
        err = [np.mean((img[crop][inner] - ref[crop][inner]) ** 2) for img in (kept, early)]
        ratios.append(err[0] / err[1])
    assert ratios and max(ratios) < 0.6, ratios


def test_the_crops_leave_no_trace_in_the_scene(rendered):
    """Neither the crops nor the coverage render (its material override, no bounces) stay behind."""
    _, digests = rendered
    assert digests[0] == digests[1] == digests[2]


def test_a_second_worker_renders_the_same_bytes(setup, rendered, tmp_path):
    """With the crops, and with their coverage correction (its coverage render in the same order
    after a different history: the first worker rendered other frames between)."""
    cfg, frames = setup
    root, _ = rendered
    proc = _worker(cfg, tmp_path / "again")
    try:
        for name in ("coverage", "crops"):
            reply = proc.request({"op": "render", "frame": to_dict(frames[name])}, TIMEOUT_S)
            assert reply.get("ok"), reply
    finally:
        proc.close()
    for name in ("crops", "coverage"):
        for kind in ("image", "exr", "label"):
            assert frame_paths(root, name)[kind].read_bytes() == frame_paths(tmp_path / "again", name)[kind].read_bytes()
