"""End-to-end renders through Cycles (small frames; a few seconds each)."""
import json
import subprocess
import sys

import numpy as np
import pytest

from dockfactory.core.config import load_config
from dockfactory.generator.datasets.folder import DatasetError
from dockfactory.generator.exr import read_compact
from dockfactory.generator.render_job import JobOptions, run_render

pytestmark = pytest.mark.render

LABEL_CHECK = """
[dataset]
name = "label-check"
seed = 5
frames = 3
[conditions]
normal = 1
low_light = 0
occlusion = 0
glare = 0
[render]
samples = 1
keep_exr = true
"""


@pytest.fixture(scope="module")
def label_dataset(tmp_path_factory):
    d = tmp_path_factory.mktemp("labels")
    cfg_path = d / "cfg.toml"
    cfg_path.write_text(LABEL_CHECK)
    cfg = load_config(cfg_path)
    summary = run_render(cfg, d / "ds", LABEL_CHECK, JobOptions(progress=False))
    assert summary.ok and summary.complete, summary.text()
    return cfg, d / "ds", cfg_path


def test_labels_agree_with_the_index_pass(label_dataset):
    """Pins the half-pixel convention and the K-to-Blender conversion.

    1. Every fully visible marker's pixels in the index pass are exactly the pixel centres that
       fall inside the label's projected outline (up to 2 % of them on the boundary).
    2. The centroid of those pixels is within 0.25 px of the label's projected centre for every
       marker of at least 150 px (smaller, thin ellipses carry more pixel quantisation).
    """
    from matplotlib.path import Path as PolyPath

    from dockfactory.core.geometry import project_points
    from dockfactory.core.layout import marker_outline
    from dockfactory.generator.random_draws import static_scene
    cfg, root, _ = label_dataset
    layout = {m.id: m for m in static_scene(cfg).markers}
    errors, mismatch = [], []
    for label_path in sorted((root / "labels").glob("*.json")):
        label = json.loads(label_path.read_text())
        passes = read_compact(root / "exr" / f"{label['frame_id']}.exr")
        assert passes.index.shape == (960, 1280)
        k = np.array(label["camera"]["K"])
        cam_from_d = np.array(label["camera"]["cam_from_d"])
        d_from_b = np.array(label["d_from_b"])
        for m in label["markers"]:
            if not m["in_frame"] or m["visible_fraction"] < 0.999:
                continue
            cam_from_s = cam_from_d @ (d_from_b if m["section"] == "B" else np.eye(4))
            outline, _ = project_points(k, cam_from_s, marker_outline(layout[m["id"]], 720))
            x0, y0 = np.floor(outline.min(0)).astype(int) - 2
            x1, y1 = np.ceil(outline.max(0)).astype(int) + 3
            ys, xs = np.mgrid[y0:y1, x0:x1]
            inside = PolyPath(outline).contains_points(np.stack([xs.ravel(), ys.ravel()], 1)).reshape(xs.shape)
            in_index = passes.index[y0:y1, x0:x1] == m["pass_index"]
            assert in_index.sum() == m["visible_pixels"]
            mismatch.append((inside != in_index).sum() / max(1, inside.sum()))
            ys_i, xs_i = np.nonzero(passes.index == m["pass_index"])
            if len(xs_i) >= 150:
                centroid = np.array([xs_i.mean(), ys_i.mean()])
                errors.append(np.linalg.norm(centroid - np.array(m["center_px"])))
            bx0, by0, bx1, by1 = m["bbox_px"]
            # every marker pixel's square touches the label's box
            assert np.all(xs_i + 0.5 >= bx0) and np.all(xs_i - 0.5 <= bx1), m["id"]
            assert np.all(ys_i + 0.5 >= by0) and np.all(ys_i - 0.5 <= by1), m["id"]
            # the depth pass agrees with the label's depth at the centre (mm)
            u, v = np.rint(m["center_px"]).astype(int)
            assert passes.depth_mm[v, u] == pytest.approx(m["depth_mm"], abs=2.0)
    errors, mismatch = np.array(errors), np.array(mismatch)
    assert len(mismatch) >= 20 and len(errors) >= 10
    assert np.all(np.isfinite(errors))
    assert mismatch.max() <= 0.02, f"pixel sets differ by up to {mismatch.max():.3f}"
    assert errors.max() < 0.25, f"median {np.median(errors):.3f} max {errors.max():.3f} px"


@pytest.fixture(scope="module")
def lens_dataset(tmp_path_factory):
    from pipeline_data import LENS_CHECK
    d = tmp_path_factory.mktemp("lens")
    (d / "cfg.toml").write_text(LENS_CHECK)
    cfg = load_config(d / "cfg.toml")
    summary = run_render(cfg, d / "ds", LENS_CHECK, JobOptions(progress=False))
    assert summary.ok and summary.complete, summary.text()
    return cfg, d / "ds"


def test_distorted_labels_agree_with_the_index_pass(lens_dataset):
    """The label-vs-pixels check on distorted frames (tests/pipeline_data.py LENS_CHECK: two units
    with barrel distortion k1 -0.15 .. -0.1, the principal point up to 12 px off centre,
    tangential distortion, chromatic aberration, JPEG; 320 x 240, rendered through an overscan
    canvas and resampled). Pins the canvas, the Blender shift of an off-centre principal point
    and the distortion maps:

    1. every fully visible marker's pixels in the delivered index pass are the exact
       rasterisation of its distorted outline (measured: 0 of ~7,500 pixels differ; at most
       0.5 % may, the boundary pixels of the render);
    2. the centroid of those pixels is within 0.25 px of the label's centre for every marker of
       150 px or more (measured: max 0.19 px, median 0.08, over 32 markers).
    """
    from pipeline_data import label_vs_index
    cfg, root = lens_dataset
    got = label_vs_index(root, cfg)
    assert got["markers"] >= 40 and len(got["centre_err"]) >= 20
    assert got["mismatch"] <= 0.005 * got["pixels"], f"{got['mismatch']} of {got['pixels']} marker pixels differ"
    assert got["centre_err"].max() < 0.25, f"median {np.median(got['centre_err']):.3f} max {got['centre_err'].max():.3f} px"
    assert got["centroid_err"].max() < 0.25
    labels = [json.loads(p.read_text()) for p in (root / "labels").glob("*.json")]
    assert {lab["camera"]["unit"] for lab in labels} == {0, 1}
    assert all(lab["camera"]["jpeg_quality"] and any(lab["camera"]["distortion"]) for lab in labels)


def test_frame_alone_equals_frame_in_a_run(label_dataset, tmp_path):
    cfg, root, _ = label_dataset
    alone = tmp_path / "alone"
    summary = run_render(cfg, alone, LABEL_CHECK, JobOptions(progress=False, frame_ids=("000001",)))
    assert summary.rendered == 1 and not summary.complete
    for sub in ("labels", "images"):
        a = (root / sub / f"000001.{'json' if sub == 'labels' else 'png'}").read_bytes()
        b = (alone / sub / f"000001.{'json' if sub == 'labels' else 'png'}").read_bytes()
        assert a == b, sub


def test_rerun_renders_nothing_and_changes_nothing(label_dataset):
    cfg, root, _ = label_dataset
    before = {p: p.stat().st_mtime_ns for p in root.rglob("*") if p.is_file() and "logs" not in p.parts}
    summary = run_render(cfg, root, LABEL_CHECK, JobOptions(progress=False))
    assert summary.rendered == 0 and summary.skipped == 3 and summary.complete
    after = {p: p.stat().st_mtime_ns for p in root.rglob("*") if p.is_file() and "logs" not in p.parts}
    assert before == after


def test_other_config_is_refused_and_nothing_changes(label_dataset, tmp_path):
    _, root, _ = label_dataset
    other_text = LABEL_CHECK.replace("seed = 5", "seed = 6")
    other_path = tmp_path / "other.toml"
    other_path.write_text(other_text)
    before = {p: p.read_bytes() for p in root.rglob("*") if p.is_file() and "logs" not in p.parts}
    with pytest.raises(DatasetError, match="dataset.seed: 5 -> 6"):
        run_render(load_config(other_path), root, other_text, JobOptions(progress=False))
    after = {p: p.read_bytes() for p in root.rglob("*") if p.is_file() and "logs" not in p.parts}
    assert before == after


def test_crashed_worker_is_restarted_and_frame_retried(tmp_path):
    import os
    text = LABEL_CHECK.replace("frames = 3", "frames = 2") + \
        "[image]\nwidth = 320\nheight = 240\n[camera]\nfocal_px = [300, 750]\nmargin_px = 12\n"
    cfg_path = tmp_path / "c.toml"
    cfg_path.write_text(text)
    env = dict(os.environ, DOCKFACTORY_FAULT="crash:000001", DOCKFACTORY_FAULT_DIR=str(tmp_path))
    summary = run_render(load_config(cfg_path), tmp_path / "ds", text, JobOptions(progress=False, env=env))
    assert summary.ok and summary.complete
    assert summary.retried >= 1 and summary.rendered + summary.recovered == 2
    assert (tmp_path / "fault-crash-000001").exists()


def test_smoke_config_through_the_cli(repo_root, tmp_path):
    out = tmp_path / "smoke"
    proc = subprocess.run([sys.executable, "-m", "dockfactory", "render", str(repo_root / "configs/smoke.toml"),
                           "--out", str(out)], capture_output=True, text=True, cwd=repo_root, timeout=600)
    assert proc.returncode == 0, proc.stderr
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["counts"]["frames"] == 10
    assert set(manifest["counts"]["by_condition"]) == {"normal", "low_light", "occlusion", "glare"}
    assert "render [" in proc.stderr and "dataset complete" in proc.stderr
    occluded = 0
    for p in (out / "labels").glob("*.json"):
        lab = json.loads(p.read_text())
        if lab["spec"]["condition"] == "occlusion":
            occluded += sum(m["visibility"] == 1 or m["visible_fraction"] < 0.99 for m in lab["markers"])
        assert lab["image"]["width"] == 320
    assert occluded >= 1  # occluders hide markers, and the labels say so
    overlay = tmp_path / "ov.png"
    proc = subprocess.run([sys.executable, "-m", "dockfactory", "show", str(out), "000000", "--out", str(overlay)],
                          capture_output=True, text=True, cwd=repo_root)
    assert proc.returncode == 0 and overlay.stat().st_size > 1000
