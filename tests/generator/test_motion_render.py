"""[motion] through Cycles (docs/motion.md): two 320 x 240 frames of B moving at 1.5 m/s for a
10 ms exposure (about 6 px of blur), one with a global shutter, one with a 20 ms rolling shutter.

The blurred markers are measured on the linear render with a neutral stage (grey paint, rings,
floor, walls and world, white lights, no props): there a pixel's blue excess b - (r + g) / 2 is
the blue marker's coverage of it, time-averaged over its exposure and filtered by the
(symmetric) pixel filter, on a background whose faint blue bounce light (the scene's blue
cradles) is removed by a plane fitted to the window's border. Its centroid must be the label's
outline centroid: B at mid-exposure (global shutter) or at each point's row time (rolling
shutter); its second moment along the blur must exceed the still disc's (the label's outline)
by the blur's L^2 / 12, which pins the blur length to the exposure. The index pass, one sample
per pixel at a random instant, must agree more loosely.

Beside them: a frame without motion rendered after moving ones has the bytes it has alone (and
the Blender state a render reads is the frame's alone), and B's keyframes move every object of
section B and nothing of A.
"""
import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest

from dockfactory.core.config import config_from_dict
from dockfactory.core.layout import marker_outline
from dockfactory.core.scene import mat4, to_dict
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.exr import read_compact
from dockfactory.generator.frame_output import frame_paths
from dockfactory.generator.sampler import frame_plan, sample_frame
from render_workers import start_worker as start_render_worker

pytestmark = pytest.mark.render

TIMEOUT_S = 300
ROLLING_MS = 20.0
CONFIG = {
    "dataset": {"name": "motion-check", "seed": 11, "frames": 2},
    "conditions": {"normal": 0, "low_light": 0, "occlusion": 0, "glare": 0, "ideal": 1},
    "image": {"width": 320, "height": 240},
    "camera": {"focal_px": [300, 750], "margin_px": 12},
    "render": {"samples": 32, "denoise": "off", "keep_exr": True, "frame_timeout_s": TIMEOUT_S},
    "sensor": {"exposure_time_ms": [10.0, 10.0]},
    "motion": {"enabled": True, "velocity_mm_s": [1500.0, 1500.0], "velocity_y_mm_s": [300.0, 300.0]},
}
CHROMA_TOL_PX = 0.15     # blue-excess centroid vs the label's outline centroid, every checked marker
INDEX_MEDIAN_TOL_PX = 0.4   # index-pass centroid (one random instant per pixel): median over markers
INDEX_MAX_TOL_PX = 1.0      # ... and worst marker
BLUR_VARIANCE = (0.5, 1.5)  # measured / expected (L^2 / 12) excess variance along the blur: a shutter
                            # of twice or half the exposure gives 4 or 0.25, no blur 0
MIN_MISS_PX = 1.0        # the wrong timing (shutter open or close; a global shutter's labels for the
                         # rolling frame) must miss the measured centroid by more than this


def neutral(frame):
    """The frame on a neutral stage (no colour but the markers'), without props."""
    grey = (0.5, 0.5, 0.5)
    look = dataclasses.replace(frame.appearance, section_color_a=grey, section_color_b=grey, grime=0.0,
                               ring_color=(0.03, 0.03, 0.03), floor_color=(0.25, 0.25, 0.25), wall_color=grey,
                               world_color=(1.0, 1.0, 1.0))
    return dataclasses.replace(frame, appearance=look, props=())


@pytest.fixture(scope="module")
def setup():
    cfg = config_from_dict(CONFIG, "motion-check")
    plan = frame_plan(cfg)
    glob = neutral(sample_frame(cfg, plan[0]))
    rolling = neutral(sample_frame(cfg, plan[1]))
    rolling = dataclasses.replace(rolling, motion=dataclasses.replace(rolling.motion, readout_ms=ROLLING_MS))
    assert glob.motion.readout_ms == 0 and glob.motion.exposure_ms == 10.0
    return cfg, {"global": glob, "rolling": rolling}


def start_worker(cfg, root):
    return start_render_worker(cfg, root, TIMEOUT_S)


def still_frame(frame):
    """``frame`` without motion, under its own id."""
    return dataclasses.replace(frame, motion=None, spec=dataclasses.replace(frame.spec, frame_id="still"))


@pytest.fixture(scope="module")
def rendered(setup, tmp_path_factory):
    """The dataset folder holding both moving frames, and the still version of the first one
    rendered after them by the same worker."""
    cfg, frames = setup
    root = tmp_path_factory.mktemp("motion") / "ds"
    proc = start_worker(cfg, root)
    try:
        for frame in (*frames.values(), still_frame(frames["global"])):
            reply = proc.request({"op": "render", "frame": to_dict(frame)}, TIMEOUT_S)
            assert reply.get("ok"), reply
    finally:
        proc.close()
    return root


def blue_excess_moments(rgb: np.ndarray, box, margin: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """(centroid (2,), covariance (2, 2)) px of b - (r + g) / 2 over the pixels of ``box`` (OpenCV
    px) widened by ``margin``, less the plane fitted to the window's two-pixel border."""
    x0, y0 = int(np.floor(box[0] + 0.5)) - margin, int(np.floor(box[1] + 0.5)) - margin
    x1, y1 = int(np.ceil(box[2] - 0.5)) + margin, int(np.ceil(box[3] - 0.5)) + margin
    sub = rgb[y0:y1 + 1, x0:x1 + 1].astype(np.float64)
    w = sub[..., 2] - (sub[..., 0] + sub[..., 1]) / 2
    ys, xs = np.mgrid[y0:y1 + 1, x0:x1 + 1]
    border = np.ones(w.shape, bool)
    border[2:-2, 2:-2] = False
    design = np.stack([np.ones(border.sum()), xs[border], ys[border]], 1)
    a, bx, by = np.linalg.lstsq(design, w[border], rcond=None)[0]
    w = w - (a + bx * xs + by * ys)
    c = np.array([(w * xs).sum(), (w * ys).sum()]) / w.sum()
    d = np.stack([xs - c[0], ys - c[1]], -1)
    return c, np.einsum("abi,abj,ab->ij", d, d, w) / w.sum()


def polygon_covariance(poly: np.ndarray) -> np.ndarray:
    """Area covariance (2, 2) px^2 of the simple polygon ``poly`` (N, 2) (Green's theorem)."""
    x, y = poly[:, 0], poly[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cr = x * yn - xn * y
    a = cr.sum() / 2
    cx, cy = ((x + xn) * cr).sum() / (6 * a), ((y + yn) * cr).sum() / (6 * a)
    ixx = ((x * x + x * xn + xn * xn) * cr).sum() / (12 * a) - cx * cx
    iyy = ((y * y + y * yn + yn * yn) * cr).sum() / (12 * a) - cy * cy
    ixy = ((x * yn + 2 * x * y + 2 * xn * yn + xn * y) * cr).sum() / (24 * a) - cx * cy
    return np.array([[ixx, ixy], [ixy, iyy]])


def blur_variance_ratio(cov: np.ndarray, still: np.ndarray, blur_px) -> float:
    """(measured - still) variance along the blur, less the same across it (which cancels the
    pixel filter), over the blur's L^2 / 12."""
    blur = np.asarray(blur_px, dtype=np.float64)
    u = blur / np.hypot(*blur)
    v = np.array([-u[1], u[0]])
    excess = (u @ cov @ u - v @ cov @ v) - (u @ still @ u - v @ still @ v)
    return float(excess / (blur @ blur / 12))


def isolated_b_markers(label: dict, margin: float = 4.0) -> list[dict]:
    """B markers of 20 px^2 or more whose swept box, widened by ``margin``, touches no other marker's."""
    boxes = {m["id"]: m.get("bbox_swept_px") or m["bbox_px"] for m in label["markers"]}
    out = []
    for m in label["markers"]:
        b = boxes[m["id"]]
        if m["section"] != "B" or m["area_px"] < 20 or not m["in_frame"]:
            continue
        g = (b[0] - margin, b[1] - margin, b[2] + margin, b[3] + margin)
        if all(o[2] < g[0] or o[0] > g[2] or o[3] < g[1] or o[1] > g[3] for k, o in boxes.items() if k != m["id"]):
            out.append(m)
    return out


def centroid_at(frame, static, marker_id: str, t_s: float) -> np.ndarray:
    """The marker's outline centroid with all of B at time ``t_s`` (a wrong timing to rule out)."""
    from dockfactory.generator.labels import frame_labels
    moved = dataclasses.replace(frame, motion=None, d_from_b=mat4(frame.motion.d_from_b_at(frame.d_from_b, t_s)))
    rec = next(m for m in frame_labels(moved, static, None, 0.5)["markers"] if m["id"] == marker_id)
    return np.array(rec["outline_centroid_px"])


@pytest.mark.parametrize("kind", ["global", "rolling"])
def test_blurred_markers_centre_on_their_labels(setup, rendered, kind):
    """Per isolated marker of B: the blue excess centroid within CHROMA_TOL_PX of the label, its
    variance along the blur the label's blur length (BLUR_VARIANCE); B at shutter open or close
    (and, for the rolling frame, B at mid-exposure for every row) misses the centroid by more than
    MIN_MISS_PX; the index pass's centroid within the looser index tolerances."""
    from dockfactory.generator.motion import moving_b
    cfg, frames = setup
    frame, static = frames[kind], static_scene(cfg)
    label = json.loads(frame_paths(rendered, frame.spec.frame_id)["label"].read_text())
    passes = read_compact(frame_paths(rendered, frame.spec.frame_id)["exr"])
    half_s, mb = frame.motion.shutter_ms() / 2000.0, moving_b(frame)
    by_id = {m.id: m for m in static.markers}
    rows, index_err = [], []
    for m in isolated_b_markers(label):
        want = np.array(m["outline_centroid_px"])
        got, cov = blue_excess_moments(passes.rgb, m["bbox_swept_px"])
        ys, xs = np.nonzero(passes.index == m["pass_index"])
        index_err.append(float(np.hypot(*(np.array([xs.mean(), ys.mean()]) - want))))
        miss = [float(np.hypot(*(got - centroid_at(frame, static, m["id"], t)))) for t in (-half_s, 0.0, half_s)]
        still = polygon_covariance(mb.project(marker_outline(by_id[m["id"]]))[0])
        rows.append({"id": m["id"], "err": float(np.hypot(*(got - want))), "open": miss[0], "mid": miss[1],
                     "close": miss[2], "blur_ratio": blur_variance_ratio(cov, still, m["blur_px"]),
                     "blur_px": float(np.hypot(*m["blur_px"])), "time_ms": m["time_ms"]})
    print(kind, rows, "index-pass errors px:", index_err)
    assert len(rows) >= 3, rows
    assert all(BLUR_VARIANCE[0] <= r["blur_ratio"] <= BLUR_VARIANCE[1] for r in rows), rows
    assert all(r["err"] <= CHROMA_TOL_PX for r in rows), rows
    assert all(min(r["open"], r["close"]) > MIN_MISS_PX for r in rows), rows
    if kind == "rolling":
        assert max(r["mid"] for r in rows) > MIN_MISS_PX, rows
    assert np.median(index_err) <= INDEX_MEDIAN_TOL_PX and max(index_err) <= INDEX_MAX_TOL_PX, index_err


def test_a_static_frame_after_moving_ones_has_its_own_blender_state(setup, tmp_path):
    """Through the worker's state request (apply a frame, no render): the Blender state a render
    reads after a moving frame is the one of the frame alone, with and without motion."""
    cfg, frames = setup
    still = dataclasses.replace(frames["global"], motion=None)
    proc = start_worker(cfg, tmp_path)
    try:
        def digest(frame):
            return proc.request({"op": "state", "frame": to_dict(frame)}, TIMEOUT_S)["digest"]
        seq = [still, frames["global"], still, frames["rolling"], still, frames["global"], frames["rolling"],
               frames["global"]]
        got = [digest(f) for f in seq]
    finally:
        proc.close()
    assert got[0] == got[2] == got[4]                  # the still frame, after nothing or a moving frame
    assert got[1] == got[5] == got[7] and got[3] == got[6]
    assert len({got[0], got[1], got[3]}) == 3


def test_a_still_frame_after_moving_ones_renders_the_bytes_it_renders_alone(setup, rendered, tmp_path):
    cfg, frames = setup
    still = still_frame(frames["global"])
    proc = start_worker(cfg, tmp_path / "ds")
    try:
        reply = proc.request({"op": "render", "frame": to_dict(still)}, TIMEOUT_S)
        assert reply.get("ok"), reply
    finally:
        proc.close()
    for kind in ("image", "exr", "label"):
        alone, after = frame_paths(tmp_path / "ds", "still")[kind], frame_paths(rendered, "still")[kind]
        assert alone.read_bytes() == after.read_bytes(), kind


B_OBJECTS_SCRIPT = """
import json, sys
import dockfactory
from dockfactory.core.scene import FrameScene, StaticScene, from_dict
from dockfactory.blender_scenes.render import BlenderRenderer
req = json.loads(sys.stdin.read())
renderer = BlenderRenderer(from_dict(StaticScene, req["static"]), 320, 240, 1, req["exr"])
renderer.state(from_dict(FrameScene, req["frame"]))
scene, b_root = renderer.handles.scene, renderer.handles.b_root
out = {"b": sorted(o.name for o in b_root.children_recursive), "at": {}}
for frame_no, sub in ((0, 0.5), (1, 0.0), (1, 0.5)):
    scene.frame_set(frame_no, subframe=sub)
    out["at"][str(frame_no + sub)] = {o.name: list(o.matrix_world.translation)
                                      for o in scene.objects if o.type == "MESH"}
print("RESULT " + json.dumps(out))
"""


def test_b_keyframes_move_every_object_of_b_and_nothing_of_a(setup, tmp_path):
    cfg, frames = setup
    frame = frames["global"]
    req = {"static": to_dict(static_scene(cfg)), "frame": to_dict(frame), "exr": str(tmp_path / "x.exr")}
    run = subprocess.run([sys.executable, "-c", B_OBJECTS_SCRIPT], input=json.dumps(req), capture_output=True,
                         text=True, timeout=TIMEOUT_S)
    assert run.returncode == 0, run.stderr[-2000:]
    out = json.loads(next(line for line in run.stdout.splitlines() if line.startswith("RESULT "))[7:])
    b = set(out["b"])
    assert {f"marker_{m.id}" for m in static_scene(cfg).markers if m.section == "B"} <= b
    assert {f"ring_{m.id}" for m in static_scene(cfg).markers if m.section == "B"} <= b
    assert {"section_B", "flange_B", "band_B"} <= b
    shutter_s = frame.motion.shutter_ms() / 1000.0
    step_m = np.array(frame.motion.velocity_mm_s) * shutter_s / 1000.0
    opened, mid, closed = (out["at"][k] for k in ("0.5", "1.0", "1.5"))
    for name in mid:
        travel = np.array(closed[name]) - np.array(opened[name])
        halves = np.array(mid[name]) - np.array(opened[name])
        if name in b:
            np.testing.assert_allclose(travel, step_m, atol=1e-6, err_msg=name)
            np.testing.assert_allclose(halves, step_m / 2, atol=1e-6, err_msg=name)
        else:
            assert not travel.any(), name
