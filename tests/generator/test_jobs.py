"""Render jobs at scale: kill and resume, verify, shards, Ray, exports (small frames)."""
import json
import os
import signal
import subprocess
import sys
import time

import cv2
import numpy as np
import pytest

from dockfactory.core.config import load_config
from dockfactory.generator.datasets import tools as dt
from dockfactory.generator.bop_images import label_box
from dockfactory.generator.render_job import JobOptions, run_render

pytestmark = pytest.mark.render

JOB = """
[dataset]
name = "jobs"
seed = 21
frames = 12
train_fraction = 0.5
[conditions]
normal = 1
low_light = 1
occlusion = 1
glare = 1
[repeatability]
poses = 1
captures = 2
[image]
width = 320
height = 240
[camera]
focal_px = [300, 750]
margin_px = 12
[render]
samples = 1
keep_exr = true
frame_timeout_s = 60
marker_samples = 0   # the job mechanics, not label-aware sampling (its own render tests)
[export]
formats = ["coco", "yolo", "bop"]
"""


def content(root):
    return {rel: (root / rel).read_bytes() for rel in dt.content_files(root)}


@pytest.fixture(scope="module")
def job(tmp_path_factory):
    d = tmp_path_factory.mktemp("job")
    path = d / "job.toml"
    path.write_text(JOB)
    cfg = load_config(path)
    summary = run_render(cfg, d / "clean", JOB, JobOptions(progress=False))
    assert summary.ok and summary.complete
    return cfg, path, d / "clean"


def test_clean_run_verifies(job):
    _, _, clean = job
    report = dt.verify(clean)
    assert report.ok, report.text()
    manifest = json.loads((clean / "manifest.json").read_text())
    assert manifest["counts"]["frames"] == 14
    assert {"images/000000.png", "labels/000000.json", "exr/000000.exr", "dataset.json"} <= {f["path"] for f in manifest["files"]}
    assert manifest["conventions"]["pixels"].startswith("OpenCV")


def test_kill_process_group_then_resume(job, tmp_path, repo_root):
    cfg, path, clean = job
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "dockfactory", "render", str(path), "--out", str(out), "--quiet"]
    proc = subprocess.Popen(cmd, cwd=repo_root, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        done = list((out / "labels").glob("*.json")) if (out / "labels").exists() else []
        if len(done) >= 4:
            break
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    done_before = {p.stem for p in (out / "labels").glob("*.json")}
    assert 4 <= len(done_before) < 14
    assert not (out / "manifest.json").exists()
    assert not dt.verify(out).ok
    timings_before = (out / "logs" / "timings.jsonl").read_text().splitlines() if (out / "logs" / "timings.jsonl").exists() else []
    summary = run_render(cfg, out, JOB, JobOptions(progress=False))
    assert summary.ok and summary.complete
    # no finished frame rendered twice: the second run rendered exactly the missing ones
    lines = (out / "logs" / "timings.jsonl").read_text().splitlines()[len(timings_before):]
    second = {json.loads(l)["frame_id"] for l in lines}
    assert second.isdisjoint(done_before)
    assert len(second) == 14 - len(done_before) == summary.rendered
    report = dt.verify(out)
    assert report.ok, report.text()
    a, b = content(clean), content(out)
    assert a.keys() == b.keys()
    for rel in a:
        if rel.startswith("labels/") or rel.startswith("images/"):
            assert a[rel] == b[rel], rel


def test_flipped_byte_is_named(job, tmp_path):
    import shutil
    _, _, clean = job
    copy = tmp_path / "copy"
    shutil.copytree(clean, copy)
    victim = copy / "images" / "000003.png"
    data = bytearray(victim.read_bytes())
    data[len(data) // 2] ^= 0x01
    victim.write_bytes(bytes(data))
    (copy / "images" / "stray.png").write_bytes(b"x")
    (copy / "labels" / "000005.json").unlink()
    report = dt.verify(copy)
    assert not report.ok
    assert [p for p, _ in report.corrupt] == ["images/000003.png"]
    assert report.missing == ["labels/000005.json"]
    assert report.unexpected == ["images/stray.png"]
    text = report.text()
    assert "images/000003.png" in text and "sha256" in text
    proc = subprocess.run([sys.executable, "-m", "dockfactory", "dataset", "verify", str(copy)],
                          capture_output=True, text=True)
    assert proc.returncode == 1 and "images/000003.png" in proc.stdout


def test_shards_together_equal_a_single_run(job, tmp_path):
    cfg, _, clean = job
    out = tmp_path / "sharded"
    s1 = run_render(cfg, out, JOB, JobOptions(progress=False, shard=(1, 2)))
    assert s1.rendered == 7 and not s1.complete
    s2 = run_render(cfg, out, JOB, JobOptions(progress=False, shard=(2, 2)))
    assert s2.rendered == 7 and s2.complete
    assert content(out) == content(clean)
    assert dt.diff(out, clean)["different"] == []


def test_ray_executor_matches_local(job, tmp_path):
    pytest.importorskip("ray")
    cfg, _, clean = job
    out = tmp_path / "ray"
    ids = ("000000", "000002", "000007")
    summary = run_render(cfg, out, JOB, JobOptions(progress=False, executor="ray", frame_ids=ids))
    assert summary.ok and summary.rendered == 3
    for fid in ids:
        for rel in (f"labels/{fid}.json", f"images/{fid}.png", f"exr/{fid}.exr"):
            assert (out / rel).read_bytes() == (clean / rel).read_bytes(), rel


def test_hung_worker_is_killed_and_frame_retried(tmp_path):
    text = JOB.replace("frames = 12", "frames = 2").replace("frame_timeout_s = 60", "frame_timeout_s = 8") \
        .replace('formats = ["coco", "yolo", "bop"]', "formats = []")
    path = tmp_path / "h.toml"
    path.write_text(text)
    env = dict(os.environ, DOCKFACTORY_FAULT="hang:000000", DOCKFACTORY_FAULT_DIR=str(tmp_path))
    summary = run_render(load_config(path), tmp_path / "ds", text, JobOptions(progress=False, env=env))
    assert summary.ok and summary.complete and summary.retried >= 1  # the hung frame (and any in flight with it)
    assert summary.rendered + summary.recovered == 4


def test_frame_that_keeps_failing_is_reported(tmp_path):
    text = JOB.replace("frames = 12", "frames = 2").replace('formats = ["coco", "yolo", "bop"]', "formats = []")
    path = tmp_path / "f.toml"
    path.write_text(text)
    env = dict(os.environ, DOCKFACTORY_FAULT="crash-always:000001")
    summary = run_render(load_config(path), tmp_path / "ds", text, JobOptions(progress=False, env=env, retries=1))
    assert not summary.ok and list(summary.failed) == ["000001"] and not summary.complete
    assert summary.retried >= 1 and summary.rendered + summary.recovered == 3  # the other three frames
    assert "FAILED 000001: worker crashed or hung" in summary.text()
    assert not (tmp_path / "ds" / "labels" / "000001.json").exists()


def test_yolo_round_trip(job):
    from dockfactory.generator.exports.yolo import parse_yolo_line
    _, _, clean = job
    yolo = clean / "exports" / "yolo"
    text = (yolo / "data.yaml").read_text()
    assert "names:\n  0: RedA\n  1: BlueB" in text and "path:" not in text
    n = 0
    for lab_path in (clean / "labels").glob("*.json"):
        lab = json.loads(lab_path.read_text())
        split = lab["spec"]["split"]
        lines = (yolo / "labels" / split / f"{lab['frame_id']}.txt").read_text().splitlines()
        expected = [m for m in lab["markers"] if m["bbox_px"] and m["visible_fraction"] >= 0.5 and m["legible"]]
        assert len(lines) == len(expected)
        for line, m in zip(lines, expected):
            c, box = parse_yolo_line(line, 320, 240)
            assert c == m["class_id"]
            assert np.allclose(box, m["bbox_px"], atol=1e-5)
            n += 1
        assert (yolo / "images" / split / f"{lab['frame_id']}.png").read_bytes() == (clean / "images" / f"{lab['frame_id']}.png").read_bytes()
    assert n > 50


def test_coco_round_trip(job):
    from pycocotools.coco import COCO
    _, _, clean = job
    coco = COCO(str(clean / "exports" / "coco" / "annotations" / "person_keypoints_test.json"))
    assert [c["name"] for c in coco.loadCats(coco.getCatIds())] == ["RedA", "BlueB"]
    for img in coco.loadImgs(coco.getImgIds()):
        lab = json.loads((clean / "labels" / f"{img['frame_id']}.json").read_text())
        by_id = {m["id"]: m for m in lab["markers"]}
        anns = coco.loadAnns(coco.getAnnIds(imgIds=img["id"]))
        assert len(anns) == sum(1 for m in lab["markers"] if m.get("visible_pixels"))
        for a in anns:
            m = by_id[a["marker_id"]]
            x, y, w, h = a["bbox"]
            assert np.allclose([x - 0.5, y - 0.5, x + w - 0.5, y + h - 0.5], m["bbox_px"], atol=1e-9)
            # keypoints are pixel indices (the label's OpenCV centre), boxes continuous (+0.5)
            assert a["keypoints"][:2] == (m["center_px"] if m["in_frame"] else [0, 0])
            assert (img["file_name"], img["frame_id"]) == (f"{lab['frame_id']}.png", lab["frame_id"])
            assert a["segmentation"] and len(a["segmentation"][0]) >= 6
            assert a["category_id"] == m["class_id"] + 1 and a["area"] > 0
            assert a["iscrowd"] == (0 if m["visible_fraction"] >= 0.5 and m["legible"] else 1)


def test_bop_round_trip(job):
    from dockfactory.generator.bop_models import read_ply
    _, _, clean = job
    bop = clean / "exports" / "bop"
    verts = read_ply(bop / "models" / "obj_000001.ply")["pts"]
    r = np.hypot(verts[:, 1], verts[:, 2])
    assert r.max() == pytest.approx(308.0, abs=1e-3) and verts[:, 0].min() == pytest.approx(-1200.0)
    info = json.loads((bop / "models" / "models_info.json").read_text())
    assert set(info) == {"1", "2"} and info["1"]["size_x"] == pytest.approx(1200.0)
    scene = bop / "test" / "000000"
    cams = json.loads((scene / "scene_camera.json").read_text())
    gts = json.loads((scene / "scene_gt.json").read_text())
    infos = json.loads((scene / "scene_gt_info.json").read_text())
    ids = json.loads((scene / "frame_ids.json").read_text())
    for im, fid in ids.items():
        lab = json.loads((clean / "labels" / f"{fid}.json").read_text())
        cam_from_d = np.eye(4)
        cam_from_d[:3, :3] = np.array(cams[im]["cam_R_w2c"]).reshape(3, 3)
        cam_from_d[:3, 3] = cams[im]["cam_t_w2c"]
        assert np.allclose(cam_from_d, lab["camera"]["cam_from_d"], atol=1e-9)
        k = np.array(cams[im]["cam_K"]).reshape(3, 3)
        assert np.allclose(k - np.array([[0, 0, .5], [0, 0, .5], [0, 0, 0]]), lab["camera"]["K"])
        gb = next(g for g in gts[im] if g["obj_id"] == 2)
        m2c = np.eye(4)
        m2c[:3, :3] = np.array(gb["cam_R_m2c"]).reshape(3, 3)
        m2c[:3, 3] = gb["cam_t_m2c"]
        assert np.allclose(np.linalg.inv(cam_from_d) @ m2c, lab["d_from_b"], atol=1e-9)
        depth = cv2.imread(str(scene / "depth" / f"{int(im):06d}.png"), cv2.IMREAD_UNCHANGED)
        assert depth.dtype == np.uint16 and cams[im]["depth_scale"] in (0.1, 1.0, 10.0) and depth.any()
        for gt, (srec, inf) in enumerate(zip(lab["sections"], infos[im])):
            # the BOP masks: pixel centres inside the flange or the body (the label's silhouette) and
            # the index pass's pixels within them
            mask = cv2.imread(str(scene / "mask" / f"{int(im):06d}_{gt:06d}.png"), cv2.IMREAD_UNCHANGED) > 0
            visib = cv2.imread(str(scene / "mask_visib" / f"{int(im):06d}_{gt:06d}.png"), cv2.IMREAD_UNCHANGED) > 0
            assert inf["px_count_all"] == mask.sum() == srec["pixels_all"]
            assert inf["bbox_obj"] == label_box(srec["bbox_obj_px"])
            assert inf["px_count_visib"] == visib.sum() <= srec["pixels_visible"] and not (visib & ~mask).any()
            assert inf["px_count_visib"] >= 0.9 * srec["pixels_visible"] > 0
            assert 0 < inf["visib_fract"] <= 1


def test_dataset_info_and_diff_cli(job, tmp_path):
    _, _, clean = job
    proc = subprocess.run([sys.executable, "-m", "dockfactory", "dataset", "info", str(clean)],
                          capture_output=True, text=True)
    assert proc.returncode == 0 and "14 of 14 done; complete" in proc.stdout
    d = dt.diff(clean, clean)
    assert d["config"] == [] and d["different"] == [] and d["same"] > 40
