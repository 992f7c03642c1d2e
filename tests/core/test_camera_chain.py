"""The colour camera after the lens (core.camera_chain: colour_sensor, isp, order) and its place in the factory:
colours survive the chain, the photon transfer curve of a flat field through the whole chain
gives back the preset's gain and dark noise (EMVA 1288's own method), fixed patterns belong to a
camera unit, the sensor never moves a label, bad sensor configs are refused in one line."""
from __future__ import annotations

import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from dockfactory.core.camera_chain import ColourChain, develop
from dockfactory.core.camera_chain.cfa import PATTERNS, channel_map
from dockfactory.core.camera_chain.colour_sensor import camera_response, configured_sensor, sense, white_dn
from dockfactory.core.camera_chain.demosaic import DEMOSAICS
from dockfactory.core.camera_chain.emva import photon_transfer
from dockfactory.core.camera_chain.encoding import jpeg_round_trip
from dockfactory.core.camera_chain.isp import colour_correction_matrix, white_balance_gains
from dockfactory.core.config import ConfigError, config_from_dict
from dockfactory.generator.labels import frame_labels
from dockfactory.generator.sampler import frame_plan, sample_frame
from dockfactory.generator.random_draws import static_scene


def srgb(x):
    x = np.asarray(x, dtype=float)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055) * 255


def srgb_inverse(v):
    x = np.asarray(v, dtype=float) / 255.0
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def chain(**kw) -> ColourChain:
    base = dict(cfa="RGGB", sensor=configured_sensor("imx273", (), 12), unit_seed=3, crosstalk=0.03,
                exposure_s=0.01, demosaic="bilinear", wb_error=(0.0, 0.0), colour_correction=True,
                tone="srgb", denoise="off", sharpen_amount=0.0, sharpen_sigma_px=1.0)
    return ColourChain(**{**base, **kw})


PATCHES = np.array([[0.18, 0.18, 0.18], [0.6, 0.05, 0.05], [0.05, 0.1, 0.6], [0.4, 0.4, 0.1], [0.02, 0.02, 0.02]])


def patch_image(size=32) -> np.ndarray:
    return np.concatenate([np.full((size, size, 3), c, np.float32) for c in PATCHES], axis=1)


@pytest.mark.parametrize("cfa", ("none",) + PATTERNS)
@pytest.mark.parametrize("method", DEMOSAICS)
def test_colours_survive_the_chain(cfa, method):
    """A flat colour patch comes out as the sRGB of its linear value: within 1.5 levels on the
    patch mean (the noise averages out; crosstalk, QE and white balance are undone exactly)."""
    if cfa == "none" and method != "bilinear":
        pytest.skip("a three-chip sensor has no demosaic")
    img, raw = develop(patch_image(), chain(cfa=cfa, demosaic=method), np.random.default_rng(5))
    for k, c in enumerate(PATCHES):
        inner = img[8:24, 32 * k + 8:32 * k + 24].reshape(-1, 3).mean(axis=0)
        np.testing.assert_allclose(inner, srgb(c), atol=1.5, err_msg=f"patch {c}")
    assert raw.dtype == np.uint16 and raw.shape == (img.shape[:2] if cfa != "none" else img.shape)


def test_white_balance_error_tints_a_grey():
    """An error of +20 % on the red gain makes a grey 20 % redder in linear light (3 %)."""
    img, _ = develop(np.full((64, 64, 3), 0.18, np.float32), chain(wb_error=(0.2, -0.1)), np.random.default_rng(1))
    m = (srgb_inverse(img[8:-8, 8:-8])).reshape(-1, 3).mean(axis=0)
    assert m[0] / m[1] == pytest.approx(1.2, rel=0.03)
    assert m[2] / m[1] == pytest.approx(0.9, rel=0.03)


def test_colour_correction_inverts_the_white_balanced_response():
    s = configured_sensor("imx174", (), 12)
    r = camera_response(s, 0.05)
    g = white_balance_gains(r)
    np.testing.assert_allclose(colour_correction_matrix(r) @ (g[:, None] * r), np.eye(3), atol=1e-12)
    np.testing.assert_allclose(colour_correction_matrix(r).sum(axis=1), 1.0, atol=1e-12)


@pytest.mark.parametrize("name", ("imx174", "imx250", "imx273"))
def test_photon_transfer_of_a_flat_field_through_the_chain(name):
    """EMVA 1288's method on raw frames of flat fields sent through the whole sensor side of the
    chain (crosstalk, QE, CFA, fixed patterns): the green pixels give back the preset's system gain
    and temporal dark noise within 5 %."""
    c = chain(sensor=configured_sensor(name, (), 12), exposure_s=0.0)
    sat_level = 1.0    # linear 1.0 fills a green pixel's full well
    pairs = []
    for k, level in enumerate([0.0] + list(np.linspace(0.03, 0.7, 9) * sat_level)):
        lin = np.full((256, 256, 3), level, np.float32)
        a, b = (sense(lin, c, np.random.default_rng([k, j]))[0::2, 1::2] for j in (0, 1))   # G sites of RGGB
        if k == 0:
            dark = (a, b)
        pairs.append((a, b, *dark))
    fit = photon_transfer(pairs)
    assert fit["K"] == pytest.approx(c.sensor.gain_dn_per_e, rel=0.05)
    assert fit["dark_noise_e"] == pytest.approx(c.sensor.dark_noise_e, rel=0.05)


def test_fixed_patterns_belong_to_the_unit():
    """Frames of one camera unit share the unit's pattern seed (hence DSNU and PRNU); units
    differ; the frames' own draws (white balance, exposure time) differ frame to frame."""
    cfg = config_from_dict({"dataset": {"frames": 12}, "camera_units": {"count": 2},
                            "sensor": {"presets": ["imx273", "imx174"], "cfa": ["RGGB", "GRBG"],
                                       "wb_error": [-0.1, 0.1], "exposure_time_ms": [5.0, 20.0]}})
    chains = {}
    for spec in frame_plan(cfg)[:12]:
        chains.setdefault(spec.unit, []).append(sample_frame(cfg, spec).sensor.chain)
    for unit, cs in chains.items():
        assert len({c.unit_seed for c in cs}) == 1 and len({c.sensor for c in cs}) == 1
        assert len({c.wb_error for c in cs}) == len(cs) and len({c.exposure_s for c in cs}) == len(cs)
    assert chains[0][0].unit_seed != chains[1][0].unit_seed
    assert (chains[0][0].cfa, chains[1][0].cfa) == ("RGGB", "GRBG")
    dark = np.zeros((64, 64, 3), np.float32)
    mean = [np.mean([sense(dark, replace(chains[u][0], cfa="none"), np.random.default_rng(i))[..., 1]
                     for i in range(40)], axis=0) for u in (0, 0, 1)]
    assert np.corrcoef(mean[0].ravel(), mean[1].ravel())[0, 1] > 0.99   # same unit, same DSNU
    assert abs(np.corrcoef(mean[0].ravel(), mean[2].ravel())[0, 1]) < 0.2


def test_the_sensor_never_moves_a_label():
    """The same config with and without a colour camera: the same geometry, camera and pose for
    every frame, and the same geometric labels."""
    base = {"dataset": {"frames": 6}, "camera_units": {"count": 2, "k1": [-0.1, 0.0]}}
    plain = config_from_dict(base)
    colour = config_from_dict({**base, "sensor": {"presets": ["imx174"], "cfa": "BGGR", "wb_error": [-0.2, 0.2]}})
    for spec in frame_plan(plain):
        a, b = sample_frame(plain, spec), sample_frame(colour, spec)
        assert a.camera == b.camera and a.d_from_b == b.d_from_b and a.props == b.props
        assert replace(a.sensor, chain=None) == replace(b.sensor, chain=None) and b.sensor.chain is not None
        la = frame_labels(a, static_scene(plain), None, 0.5)
        lb = frame_labels(b, static_scene(colour), None, 0.5)
        assert la["markers"] == lb["markers"] and la["camera"] == lb["camera"]


@pytest.mark.parametrize("sensor, message", [
    ({"presets": ["imx999"]}, "[sensor] presets: unknown sensor preset 'imx999'"),
    ({"presets": ["imx273"], "overrides": {"dark_noise": 2.0}}, "[sensor] overrides: unknown key 'dark_noise'"),
    ({"presets": ["imx273"], "overrides": {"qe_red": 1.5}}, "quantum_efficiency[R] must be <= 1"),
    ({"presets": ["imx273"], "overrides": {"gain_dn_per_e": 5.0}}, "gain_dn_per_e * saturation_e"),
    ({"cfa": "RGGB"}, "[sensor] cfa: a colour filter array needs a sensor preset"),
    ({"presets": ["imx273"], "cfa": ["RGBG"]}, "[sensor] cfa: 'RGBG' is not one of"),
    ({"presets": ["imx273"], "demosaic": ["ahd"]}, "[sensor] demosaic: 'ahd' is not one of"),
    ({"presets": ["imx273"], "tone": "log"}, "[sensor] tone: 'log' is not one of"),
    ({"raw_output": True}, "[sensor] raw_output: needs a sensor preset"),
])
def test_bad_sensor_configs_are_refused(sensor, message):
    with pytest.raises(ConfigError) as exc:
        config_from_dict({"sensor": sensor})
    assert message in str(exc.value) and "\n" not in str(exc.value)


def test_a_bad_preset_is_one_line_and_exit_2(tmp_path):
    cfg = tmp_path / "bad.toml"
    cfg.write_text('[sensor]\npresets = ["imx273"]\n[sensor.overrides]\nprnu_pct = -1.0\n')
    r = subprocess.run([sys.executable, "-m", "dockfactory", "check-config", str(cfg)], capture_output=True, text=True)
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0 and "prnu_pct must be >= 0, got -1.0" in r.stderr


def test_white_level_and_raw_range():
    s = configured_sensor("imx174", (), 12)
    assert white_dn(s) == pytest.approx(s.black_level_dn + s.gain_dn_per_e * s.saturation_e)
    raw = sense(np.full((8, 8, 3), 5.0, np.float32), chain(sensor=s), np.random.default_rng(0))
    assert raw.max() <= 2 ** 12 - 1 and raw.min() > 0.9 * white_dn(s)


@pytest.mark.parametrize("sub", ("420", "444"))
def test_jpeg_subsampling_keeps_or_halves_chroma(sub):
    """A one-pixel-wide red line on grey: 4:4:4 keeps its chroma, 4:2:0 smears it."""
    img = np.full((32, 32, 3), 128, np.uint8)
    img[:, 15] = (255, 0, 0)
    out = jpeg_round_trip(img, 95, sub).astype(int)
    red_minus_green = out[8:24, 15, 0] - out[8:24, 15, 1]
    assert (red_minus_green.mean() > 180) == (sub == "444")


COLOUR_DATASET = """
[dataset]
name = "colour"
seed = 5
frames = 4
train_fraction = 0.5
[conditions]
normal = 1
[repeatability]
poses = 1
captures = 2
[camera_units]
count = 2
jpeg = true
jpeg_quality = [90, 90]
jpeg_subsampling = "444"
[sensor]
presets = ["imx273", "imx174"]
cfa = ["RGGB", "GBRG"]
demosaic = ["mhc", "vng"]
wb_error = [-0.1, 0.1]
raw_output = true
"""


@pytest.fixture(scope="module")
def colour_pair(tmp_path_factory):
    """A painted dataset through Bayer cameras with raw output, and the same config without them."""
    from pipeline_data import painted_from_text
    plain = COLOUR_DATASET.split("[sensor]")[0]
    return painted_from_text(tmp_path_factory, "colour", COLOUR_DATASET), painted_from_text(tmp_path_factory, "plain", plain)


GEOMETRY = ("marker_id", "center_px", "outline_centroid_px", "bbox_px", "visibility", "pixels_visible", "pixels_all")


@pytest.mark.slow   # a painted 1280 x 960 dataset through the colour chain
def test_a_colour_dataset_keeps_its_labels_and_raw_frames(colour_pair):
    """Bayer frames, JPEG and raw output: the dataset verifies; every marker's geometric label is
    that of the three-chip dataset of the same config; each raw frame is a one-channel 16-bit PNG
    whose class-colour sites are the bright ones inside a marker of that colour."""
    import cv2

    from dockfactory.generator.datasets.reader import Dataset
    colour, plain = colour_pair
    ds, ref = Dataset.open(colour), Dataset.open(plain)
    assert any(r["path"].startswith("raw/") for r in ds.manifest["files"])
    for fid in ds.frames():
        lab, other = ds.labels[fid], ref.labels[fid]
        assert [{k: m.get(k) for k in GEOMETRY} for m in lab["markers"]] == \
               [{k: m.get(k) for k in GEOMETRY} for m in other["markers"]]
        chain = lab["sampled"]["sensor"]["chain"]
        assert lab["camera"]["jpeg_subsampling"] == "444"
        raw = cv2.imread(str(ds.root / "raw" / f"{fid}.png"), cv2.IMREAD_UNCHANGED)
        assert raw.dtype == np.uint16 and raw.shape == (lab["image"]["height"], lab["image"]["width"])
        cmap = channel_map(chain["cfa"], *raw.shape)
        for m in lab["markers"]:
            if m["visibility"] != 2 or m["class_id"] != 0:
                continue
            x, y = np.rint(m["center_px"]).astype(int)
            patch, sites = raw[y - 2:y + 3, x - 2:x + 3].astype(float), cmap[y - 2:y + 3, x - 2:x + 3]
            assert patch[sites == 0].mean() > 2 * patch[sites == 2].mean(), (fid, m["marker_id"])


@pytest.mark.slow   # a painted 1280 x 960 dataset through the colour chain
def test_the_report_names_the_simulated_cameras(colour_pair):
    from dockfactory.eval.simulated_cameras import html_simulated_cameras, simulated_cameras_block
    from dockfactory.generator.datasets.reader import Dataset
    ds = Dataset.open(colour_pair[0])
    rows = [{"frame_id": f, "ok": True, "err_x": 0.1, "err_y": -0.2, "err_alpha": 0.01} for f in ds.frames("test")]
    block = simulated_cameras_block(ds, rows)
    assert [u["sensor"]["preset"] for u in block["units"]] == ["imx273", "imx174"]
    assert sum(u["test"]["solved"] for u in block["units"]) == len(rows)
    text = " ".join(html_simulated_cameras(block))
    for words in ("What was simulated", "rendered, not measured", "EMVA 1288 preset imx273", "RGGB (mhc demosaic)",
                  "GBRG (vng demosaic)", "JPEG q90 444"):
        assert words in text, words


@pytest.mark.slow   # a painted 1280 x 960 dataset through the colour chain
def test_the_detector_is_told_each_frames_camera(colour_pair):
    """detect / run tell the centre refinement each frame's Bayer pattern and JPEG encoding (the
    camera's maker knows both); a three-chip PNG camera tells nothing."""
    from dockfactory.eval.simulated_cameras import dataset_camera
    from dockfactory.generator.datasets.reader import Dataset
    ds, plain = Dataset.open(colour_pair[0]), Dataset.open(colour_pair[1])
    told, plain_told = dataset_camera(ds), dataset_camera(plain)
    for fid in ds.frames():
        assert told(fid) == (ds.labels[fid]["sampled"]["sensor"]["chain"]["cfa"], True)
        assert plain_told(fid) == (None, True)


@pytest.mark.slow   # a painted 1280 x 960 dataset through the colour chain
def test_colour_frames_do_not_depend_on_the_order_they_are_made_in(colour_pair, tmp_path):
    """The sensor stage's caches (fixed patterns, responses, maps) hold no state a frame can leak:
    the frames made again in reverse order, in the same process, equal the dataset's byte for byte
    (image, raw frame, label)."""
    import tempfile
    from pathlib import Path

    from pipeline_data import painted_passes

    from dockfactory.core.config import load_config
    from dockfactory.generator.exr import write_compact
    from dockfactory.generator.frame_output import finish_frame
    colour = colour_pair[0]
    cfg = load_config(colour.parent / "c.toml")
    static = static_scene(cfg)
    with tempfile.TemporaryDirectory() as scratch:
        for spec in reversed(frame_plan(cfg)):
            frame = sample_frame(cfg, spec)
            exr = Path(scratch) / f"{spec.frame_id}.exr"
            write_compact(exr, painted_passes(frame, static))
            finish_frame(frame, static, exr, tmp_path, False, cfg.labels.visible_threshold,
                         min_chroma=cfg.labels.min_chroma, keep_raw=True)
    for spec in frame_plan(cfg):
        for kind in ("images", "raw"):
            assert (tmp_path / kind / f"{spec.frame_id}.png").read_bytes() == \
                   (colour / kind / f"{spec.frame_id}.png").read_bytes(), (kind, spec.frame_id)
        assert (tmp_path / "labels" / f"{spec.frame_id}.json").read_bytes() == \
               (colour / "labels" / f"{spec.frame_id}.json").read_bytes()
