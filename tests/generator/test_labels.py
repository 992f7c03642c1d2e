import numpy as np
import pytest

from dockfactory.core.config import config_from_dict
from dockfactory.core.geometry import polygon_area_centroid
from dockfactory.core.layout import marker_outline
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.labels import clip_polygon, frame_labels
from dockfactory.generator.sampler import frame_plan, sample_frame


def test_polygon_area_and_centroid():
    square = np.array([[0, 0], [4, 0], [4, 2], [0, 2]], float)
    area, c = polygon_area_centroid(square)
    assert area == pytest.approx(8.0) and np.allclose(c, [2, 1])
    area_rev, _ = polygon_area_centroid(square[::-1])
    assert area_rev == pytest.approx(8.0)


def test_clip_polygon_to_image():
    square = np.array([[-2, -2], [2, -2], [2, 2], [-2, 2]], float)
    clipped = clip_polygon(square, -0.5, -0.5, 10, 10)
    area, c = polygon_area_centroid(clipped)
    assert area == pytest.approx(2.5 * 2.5) and np.allclose(c, [0.75, 0.75])
    assert len(clip_polygon(square, 5, 5, 10, 10)) == 0


def test_outline_is_a_circle_of_the_marker_diameter():
    cfg = config_from_dict({})
    m = static_scene(cfg).markers[3]
    pts = marker_outline(m)
    d = np.linalg.norm(pts - np.array(m.center_mm), axis=1)
    assert np.allclose(d, m.diameter_mm / 2)
    assert np.allclose((pts - np.array(m.center_mm)) @ np.array(m.normal), 0, atol=1e-12)




def test_visibility_from_index_pass():
    cfg = config_from_dict({"dataset": {"frames": 4}})
    spec = frame_plan(cfg)[0]
    frame = sample_frame(cfg, spec)
    static = static_scene(cfg)
    w, h = frame.camera.width, frame.camera.height
    base = frame_labels(frame, static, None, 0.5)
    import cv2
    index = np.zeros((h, w), np.int32)
    from dockfactory.core.geometry import project_points, transform_points
    for m, rec in zip(static.markers, base["markers"]):
        d_from_s = frame.d_from_b_array() if m.section == "B" else np.eye(4)
        uv, _ = project_points(frame.camera.k(), frame.camera.cam_from_d_array(),
                               transform_points(d_from_s, marker_outline(m)))
        cv2.fillPoly(index, [np.round(uv * 16).astype(np.int32)], int(m.pass_index), cv2.LINE_8, 4)
    # hide the left half of the first marker
    first = base["markers"][0]
    u0 = first["center_px"][0]
    ys, xs = np.nonzero(index == first["pass_index"])
    index[ys[xs < u0], xs[xs < u0]] = 0
    labels = frame_labels(frame, static, index, 0.5, {"auto_exposure_scale": 1.0})
    for rec in labels["markers"][1:]:
        assert rec["visible_fraction"] == pytest.approx(1.0, abs=0.06)
        assert rec["visibility"] == 2
        assert rec["bbox_visible_px"] is not None
    remaining = int((index == first["pass_index"]).sum())
    rec0 = labels["markers"][0]
    assert rec0["visible_pixels"] == remaining
    assert rec0["visible_fraction"] == pytest.approx(remaining / first["area_in_frame_px"])
    assert 0.35 < rec0["visible_fraction"] < 0.65
    # legibility from the final image: marker 1 washed out to white, the others in their colour
    image = np.zeros((h, w, 3), np.uint8)
    for m in static.markers:
        image[index == m.pass_index] = (200, 20, 30) if m.section == "A" else (20, 30, 200)
    image[index == base["markers"][1]["pass_index"]] = (250, 250, 250)
    lab2 = frame_labels(frame, static, index, 0.5, None, image, min_chroma=0.03)
    assert lab2["markers"][1]["legible"] is False and lab2["markers"][1]["chroma"] == pytest.approx(0.0)
    assert all(r["legible"] for i, r in enumerate(lab2["markers"]) if i != 1)
    assert lab2["markers"][2]["chroma"] == pytest.approx(170 / 255, abs=1e-6)
    # raise the threshold: the half-hidden marker becomes "occluded"
    strict = frame_labels(frame, static, index, 0.7)
    assert strict["markers"][0]["visibility"] == 1
    with pytest.raises(ValueError, match="index pass"):
        frame_labels(frame, static, index[:-1], 0.5)


def test_label_record_contents():
    cfg = config_from_dict({"dataset": {"frames": 4}})
    frame = sample_frame(cfg, frame_plan(cfg)[1])
    lab = frame_labels(frame, static_scene(cfg), None, 0.5)
    assert lab["image"]["width"] == 1280
    k = np.array(lab["camera"]["K"])
    assert k[0, 2] == 639.5 and k[1, 2] == 479.5
    assert set(lab["pose_b_in_d"]) == {"x_mm", "y_mm", "z_mm", "alpha_deg", "beta_deg", "gamma_deg"}
    for m in lab["markers"]:
        x0, y0, x1, y1 = m["bbox_px"]
        u, v = m["center_px"]
        assert x0 < u < x1 and y0 < v < y1
        assert m["in_frame"]
    assert lab["sampled"]["sensor"]["noise_seed"] == frame.sensor.noise_seed
