"""The sensor bench's raw camera (bench.sensor.sensor_effects, ``bayer-raw``): the frame a camera's
raw mosaic becomes in ``measure`` (developed without the camera's ISP), the same exposure and
noise as the camera's own ISP image."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from bench.sensor import sensor_effects as se
from dockfactory.core.camera_chain import expose_frame
from dockfactory.core.camera_chain.colour_sensor import white_dn
from dockfactory.core.camera_chain.isp import develop_raw
from dockfactory.core.scene import SensorParams, from_dict

LABEL = {"spec": {"index": 3}, "sampled": {"sensor": {
    "ideal": False, "exposure_ev": 0.25, "gain_ev": 0.0, "full_well_e": 9290.0, "read_noise_e": 5.07,
    "adc_bits": 12, "vignetting": 0.2, "bloom": 0.0, "noise_seed": 1600955440100208732}}}


def _scene() -> np.ndarray:
    """Linear (64, 96, 3): grey paint with a red and a blue disc."""
    ys, xs = np.mgrid[0:64, 0:96]
    img = np.full((64, 96, 3), 0.2, np.float32)
    img[np.hypot(xs - 30, ys - 32) < 10] = (0.6, 0.03, 0.03)
    img[np.hypot(xs - 66, ys - 32) < 10] = (0.03, 0.06, 0.6)
    return img


def test_the_raw_camera_is_its_mosaic_developed_as_measure_develops_it():
    """Equal to ``develop_raw`` of the raw frame ``expose_frame`` returns through the same camera
    (black and white level the sensor's, VNG), and not the camera's own ISP image."""
    rgb = _scene()
    got = se.delivered(rgb, LABEL, "bayer-raw")
    params = from_dict(SensorParams, {k: v for k, v in LABEL["sampled"]["sensor"].items() if k != "chain"})
    chain = se.EFFECTS["bayer-raw"][0](3)
    isp, raw, _ = expose_frame(rgb, replace(params, chain=chain))
    want = develop_raw(raw, "RGGB", chain.sensor.black_level_dn, white_dn(chain.sensor), "vng")
    assert got.shape == (64, 96, 3) and got.dtype == np.uint8
    assert np.array_equal(got, want)
    assert not np.array_equal(got, isp)
