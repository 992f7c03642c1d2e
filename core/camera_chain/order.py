"""The camera chain's order: every image effect applied to a rendered frame, in the order light
travels, each stage a function of its stage module.

lens (``lens``: distortion, pixel aspect, lateral chromatic aberration; the passes resampled with
the image) -> light before the sensor (``light``: auto exposure, exposure offset, vignetting,
veiling glare) -> sensor (``plain_sensor``, or a colour camera's ``colour_sensor``: colour filters,
CFA, EMVA 1288 noise, ADC) -> ISP (``isp``: white balance, demosaic, colour correction, digital
gain, tone, denoise, sharpening) -> encoding (``encoding``: JPEG). Motion blur and the rolling
shutter happen before the lens: the render draws them (``generator.motion`` gives their geometry).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dockfactory.core.camera_chain.colour_sensor import ColourChain, sense
from dockfactory.core.camera_chain.encoding import encode_frame
from dockfactory.core.camera_chain.isp import display_from_dn, process
from dockfactory.core.camera_chain.lens import RenderPasses, resample_passes
from dockfactory.core.camera_chain.light import auto_exposure_scale, light_on_sensor
from dockfactory.core.camera_chain.plain_sensor import ideal_dn, plain_dn
from dockfactory.core.scene import CameraModel, SensorParams


@dataclass(frozen=True)
class Capture:
    """What the camera delivers of one render. ``passes``: the delivered passes (the lens's
    geometry; colour still scene-linear); ``image``: (H, W, 3) uint8 RGB, as encoded and decoded;
    ``raw``: a colour camera's raw frame in DN, uint16 ((H, W) behind a CFA, (H, W, 3) for three
    sensors), else None; ``derived``: the values the chain derived (``auto_exposure_scale``)."""
    passes: RenderPasses
    image: np.ndarray
    raw: np.ndarray | None
    derived: dict


def capture(passes: RenderPasses, cam: CameraModel, sensor: SensorParams, outlines=()) -> Capture:
    """The whole camera chain on a frame's render: lens, light, sensor, ISP, encoding.

    Parameters
    ----------
    passes : RenderPasses
        The render canvas (``cam.canvas()``): colour (H, W, 3) float32 scene-linear radiance, depth
        (mm) and object index.
    cam : CameraModel
        The frame's camera (lens, pixel aspect, JPEG encoding).
    sensor : SensorParams
        The frame's sensor, ISP and noise seed.
    outlines : sequence of (int, (N, 2) float64)
        (index-pass value, convex outline in the camera's pinhole px) of the markers whose edges
        the lens decides exactly (:func:`~dockfactory.core.camera_chain.lens.resample_passes`).

    Returns
    -------
    Capture
        The delivered passes, image, raw frame and derived values.

    Raises
    ------
    ValueError
        A render that is not the camera's canvas or not (H, W, 3), or a colour chain it cannot run.
    RuntimeError
        The JPEG encoder failed.
    """
    delivered = resample_passes(passes, cam, outlines)           # lens
    image, raw, derived = expose_frame(delivered.rgb, sensor)     # light, sensor, ISP
    return Capture(delivered, encode_frame(image, cam), raw, derived)   # encoding


def expose_frame(linear: np.ndarray, p: SensorParams) -> tuple[np.ndarray, np.ndarray | None, dict]:
    """The chain between the lens and the encoding: light before the sensor, sensor, ISP.

    Parameters
    ----------
    linear : (H, W, 3) float32
        Scene-linear radiance of the delivered image (not changed; NaN and inf read as 0).
    p : SensorParams
        The frame's sensor: ideal, plain (no ``chain``) or a colour camera (``chain``).

    Returns
    -------
    image : (H, W, 3) uint8
        Display RGB, before the encoding.
    raw : (H, W) or (H, W, 3) uint16 or None
        A colour camera's raw frame in DN (behind a CFA, or three sensors); None for the plain
        and the ideal sensor.
    derived : dict
        ``auto_exposure_scale``: the auto exposure's scale of the radiance.

    Raises
    ------
    ValueError
        ``linear`` not (H, W, 3), or a colour chain it cannot run (``ColourChain.check``).
    """
    if linear.ndim != 3 or linear.shape[2] != 3:
        raise ValueError(f"linear image must be (H, W, 3), got {linear.shape}")
    img = np.nan_to_num(np.array(linear, dtype=np.float32), copy=False, nan=0.0, posinf=0.0, neginf=0.0)
    scale = auto_exposure_scale(img)
    derived = {"auto_exposure_scale": scale}
    light = light_on_sensor(img, p, scale)
    if p.ideal:   # noise-free whatever the camera
        return display_from_dn(ideal_dn(light, p.adc_bits), p.adc_bits), None, derived
    rng = np.random.default_rng(p.noise_seed)
    if p.chain is not None:
        image, raw = develop(light, p.chain, rng, p.gain_ev)
        return image, raw, derived
    return display_from_dn(plain_dn(light, p, rng), p.adc_bits, p.gain_ev), None, derived


def develop(linear: np.ndarray, chain: ColourChain, rng: np.random.Generator,
            gain_ev: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """A colour camera's sensor and ISP on one exposure: ``sense`` then ``process``.

    Parameters
    ----------
    linear : (H, W, 3) float32
        Exposure-normalised linear light (linear sRGB primaries; 1.0 fills a green pixel's full
        well).
    chain : ColourChain
        The frame's colour camera.
    rng : numpy.random.Generator
        The frame's noise stream.
    gain_ev : float
        Digital gain, stops.

    Returns
    -------
    image : (H, W, 3) uint8
        Display RGB.
    raw : (H, W) or (H, W, 3) uint16
        The raw frame, DN.

    Raises
    ------
    ValueError
        ``linear`` not (H, W, 3), or a chain it cannot run (``ColourChain.check``).
    """
    chain.check()
    if linear.ndim != 3 or linear.shape[2] != 3:
        raise ValueError(f"linear image must be (H, W, 3), got {linear.shape}")
    raw = sense(linear, chain, rng)
    return process(raw, chain, gain_ev), raw
