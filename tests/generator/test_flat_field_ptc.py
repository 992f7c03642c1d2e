"""EMVA 1288's photon transfer method on flat fields rendered by Cycles and sent through the
factory's own sensor stage (``core.camera_chain.expose_frame``: auto exposure, exposure_ev, the
colour camera's crosstalk, QE, Bayer CFA, DSNU / PRNU of the unit, temporal noise, ADC): the raw
frames' green sites give back the preset's system gain K and temporal dark noise within 5 %.

The series varies the exposure (``exposure_ev``) at a fixed irradiance, as the standard allows;
each level is a pair of frames with different noise seeds, the dark pair a black render. 256 x
256 px: 32,768 green sites, a relative standard error of a variance of 0.8 %."""
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dockfactory.core.camera_chain import ColourChain, expose_frame
from dockfactory.core.camera_chain.colour_sensor import configured_sensor
from dockfactory.core.camera_chain.cfa import channel_map
from dockfactory.core.camera_chain.emva import photon_transfer
from dockfactory.core.scene import SensorParams
from dockfactory.generator.exr import read_passes
from dockfactory.core.camera_chain.light import TARGET_GREY

SIZE = 256
SCRIPT = Path(__file__).with_name("flat_field_scene.py")
# well fillings of the green sites, dark excluded: 3 % to 70 % of the full well
FILLS = np.linspace(0.03, 0.7, 9)


@pytest.fixture(scope="module")
def flat_renders(tmp_path_factory):
    """(lit, dark) (SIZE, SIZE, 3) float32 linear renders: a flat grey field and a black one."""
    out = tmp_path_factory.mktemp("flat")
    subprocess.run([sys.executable, str(SCRIPT), str(out), str(SIZE), "0.5", "0.0"], check=True,
                   capture_output=True, timeout=300)
    return read_passes(out / "flat_0.exr").rgb, read_passes(out / "flat_1.exr").rgb


def _params(name: str, ev: float, seed: int) -> SensorParams:
    chain = ColourChain(cfa="GRBG", sensor=configured_sensor(name, (), 12), unit_seed=7, crosstalk=0.02,
                        exposure_s=0.0, demosaic="bilinear", wb_error=(0.0, 0.0), colour_correction=True,
                        tone="srgb", denoise="off", sharpen_amount=0.0, sharpen_sigma_px=1.0)
    return SensorParams(ideal=False, exposure_ev=ev, gain_ev=0.0, full_well_e=0.0, read_noise_e=0.0,
                        adc_bits=12, vignetting=0.0, bloom=0.0, noise_seed=seed, chain=chain)


def _green(raw: np.ndarray) -> np.ndarray:
    """(H, W / 2) the green sites of a GRBG mosaic: (0, 0) and (1, 1) of each 2 x 2 block, stacked."""
    assert (channel_map("GRBG", 2, 2) == [[1, 0], [2, 1]]).all()
    return np.vstack([raw[0::2, 0::2], raw[1::2, 1::2]]).astype(np.float64)


@pytest.mark.render
def test_the_rendered_flat_field_is_flat(flat_renders):
    """The premise of the method: Cycles' flat field is grey and uniform to 0.5 % RMS, and the
    black render is black. (The factory's denoiser at 1 sample leaves isolated pixels a few per
    cent off a flat field; without it the render is exactly flat. Within a pair both frames see
    the same render, so that structure cancels like a fixed pattern.)"""
    lit, dark = flat_renders
    assert lit.shape == (SIZE, SIZE, 3)
    assert float(lit.std() / lit.mean()) < 5e-3
    np.testing.assert_allclose(lit.mean(axis=(0, 1)), lit.mean(), rtol=1e-3)
    assert float(np.abs(dark).max()) == 0.0


@pytest.mark.render
@pytest.mark.parametrize("name", ("imx174", "imx250", "imx273"))
def test_photon_transfer_of_a_rendered_flat_field(flat_renders, name):
    """K and the temporal dark noise from the raw frames within 5 % of the preset's figures."""
    lit, dark = flat_renders
    dark_pair = tuple(_green(expose_frame(dark, _params(name, 0.0, s))[1]) for s in (100, 101))
    pairs = []
    for k, fill in enumerate(FILLS):
        # auto exposure brings the flat to TARGET_GREY; exposure_ev sets the well filling of a green
        # site (linear 1.0 fills it, before crosstalk)
        ev = float(np.log2(fill / TARGET_GREY))
        a, b = (_green(expose_frame(lit, _params(name, ev, 2 * k + j))[1]) for j in (0, 1))
        pairs.append((a, b, *dark_pair))
    sensor = configured_sensor(name, (), 12)
    fit = photon_transfer(pairs)
    assert fit["K"] == pytest.approx(sensor.gain_dn_per_e, rel=0.05)
    assert fit["dark_noise_e"] == pytest.approx(sensor.dark_noise_e, rel=0.05)
