"""Frozen, bpy-free description of one frame; ``blender_scenes`` turns it into Blender objects.

Lengths in mm, angles in degrees, colours linear RGB in [0, 1]. Transforms are 4x4 nested
tuples named ``<to>_from_<from>``; ``.matrix()`` style helpers return numpy arrays.
"""
from __future__ import annotations

import copy
import dataclasses
import types
import typing
from dataclasses import dataclass

import numpy as np

from dockfactory.core.camera_chain.colour_sensor import ColourChain
from dockfactory.core.distortion import N_COEFFS
from dockfactory.core.geometry import intrinsics, render_canvas
from dockfactory.core.layout import RING_BASE_DEPTH_MM, Marker

Mat4 = tuple[tuple[float, ...], ...]
OMIT_IF_NONE = "omit_if_none"   # field metadata: to_dict leaves the field out while it is None
OMIT_IF_DEFAULT = "omit_if_default"   # field metadata: to_dict leaves the field out while it has its default
Vec3 = tuple[float, float, float]


def mat4(array) -> Mat4:
    """Freeze a (4, 4) array as nested tuples of Python floats."""
    a = np.asarray(array, dtype=np.float64)
    if a.shape != (4, 4):
        raise ValueError(f"expected a (4, 4) transform, got {a.shape}")
    return tuple(tuple(float(v) for v in row) for row in a)


def vec(values) -> tuple[float, ...]:
    return tuple(float(v) for v in np.asarray(values, dtype=np.float64).ravel())


@dataclass(frozen=True)
class FrameSpec:
    """Where a frame sits in the dataset plan."""
    frame_id: str
    index: int        # main frames: 0..frames-1; repeatability frames continue after them
    kind: str         # "main" | "repeat"
    split: str        # "train" | "val" | "test" | "repeat"
    condition: str    # one of generator.config.CONDITIONS
    pose_index: int   # repeatability: static pose number (main frames: -1)
    capture: int      # repeatability: capture number (main frames: -1)
    unit: int = 0     # the camera unit that takes the frame
    run: int = -1     # docking run of the frame ([runs]; -1: not in a run)
    run_frame: int = -1  # its place in the run (0 = the start, B farthest from A)


NO_DISTORTION = (0.0,) * N_COEFFS


@dataclass(frozen=True)
class CameraModel:
    """A frame's camera: K and pose, plus its unit's lens (defaults: an ideal camera).

    K (:meth:`k`) has fx = ``focal_px`` and fy = ``pixel_aspect`` fx. The render is the pinhole
    image with square pixels at ``focal_px`` (:meth:`pinhole_k`); delivered pixel p (OpenCV
    pixels) shows it at the undistorted position of p (``core.distortion``, OpenCV's Brown-Conrady
    model, coefficients in OpenCV's order, the aspect taken out); channel c of it at
    ``pp + (that - pp) / channel_scales()[c]`` (lateral chromatic aberration: the red and blue
    images are magnified about the principal point against the green one).
    """
    width: int
    height: int
    focal_px: float
    principal_point: tuple[float, float]
    cam_from_d: Mat4
    look_at_mm: Vec3       # the point on the seam the camera was aimed at (D)
    distance_mm: float     # camera centre to look_at_mm
    unit: int = 0                                    # camera unit id
    distortion: tuple[float, ...] = NO_DISTORTION    # k1, k2, p1, p2, k3 (OpenCV order)
    aberration_px: tuple[float, float] = (0.0, 0.0)  # red, blue: radial shift vs green at the farthest corner
    f_number: float = 0.0                            # 0: no depth of field (a pinhole aperture)
    focus_distance_mm: float = 0.0                   # along the optical axis
    sensor_width_mm: float = 36.0                    # physical sensor: focal mm = focal_px * this / width
    jpeg_quality: int = 0                            # 0: delivered without JPEG encoding
    jpeg_subsampling: str = "420"                    # chroma: 420 | 444
    # fy / fx of the delivered image's pixels (1: square); left out of to_dict while 1
    pixel_aspect: float = dataclasses.field(default=1.0, metadata={OMIT_IF_DEFAULT: True})

    def k(self) -> np.ndarray:
        """The delivered image's K (3, 3): fx = focal_px, fy = pixel_aspect fx, the principal point."""
        return intrinsics(self.focal_px, self.principal_point, self.pixel_aspect)

    def pinhole_k(self) -> np.ndarray:
        """The render's K (3, 3): square pixels at focal_px, the principal point (pinhole pixels,
        before the canvas offset); :meth:`k` itself for square pixels."""
        return intrinsics(self.focal_px, self.principal_point)

    def corner_radius_px(self) -> float:
        """Distance from the principal point to the farthest image corner (pixel-corner frame)."""
        cx, cy = self.principal_point
        return float(max(np.hypot(x - cx, y - cy) for x in (-0.5, self.width - 0.5)
                         for y in (-0.5, self.height - 0.5)))

    def channel_scales(self) -> tuple[float, float, float]:
        """Magnification of the red, green and blue images about the principal point (green = 1)."""
        r = self.corner_radius_px()
        return (1.0 + self.aberration_px[0] / r, 1.0, 1.0 + self.aberration_px[1] / r)

    def is_pinhole(self) -> bool:
        """No distortion, no aberration and square pixels: the render is the delivered image (no
        resampling)."""
        return not any(self.distortion) and not any(self.aberration_px) and self.pixel_aspect == 1.0

    def canvas(self) -> tuple[int, int, int, int]:
        """(offset_x, offset_y, width, height) of the pinhole render that covers every delivered
        pixel: render pixel (i, j) is pinhole pixel (i + offset_x, j + offset_y) of this camera
        (``core.geometry.render_canvas``); (0, 0, width, height) for a pinhole camera."""
        if self.is_pinhole():
            return 0, 0, self.width, self.height
        return render_canvas(self.width, self.height, self.focal_px, self.principal_point,
                             self.distortion, self.channel_scales(), self.pixel_aspect)

    def focal_mm(self) -> float:
        return self.focal_px * self.sensor_width_mm / self.width

    def cam_from_d_array(self) -> np.ndarray:
        return np.array(self.cam_from_d)


@dataclass(frozen=True)
class Light:
    name: str            # "key" | "fill" | "glare"
    kind: str            # Blender light type: "AREA" | "POINT" | "SPOT"
    d_from_light: Mat4   # light looks down its local -Z (Blender convention), origin = position
    power_w: float       # 0 = off
    size_mm: float
    color: Vec3


@dataclass(frozen=True)
class Prop:
    """An object placed per frame: occluder, clutter or glare lamp. Local X is its long axis."""
    kind: str            # "cable" | "bar" | "tool" | "blob" | "box" | "drum" | "lamp"
    slot: int            # which pooled object of that kind
    d_from_prop: Mat4
    size_mm: Vec3        # extent along local X, Y, Z
    color: Vec3
    emission: float = 0.0  # emission strength (lamps)
    target_marker: str = ""  # occluders: the marker it was aimed at


@dataclass(frozen=True)
class Appearance:
    section_color_a: Vec3
    section_color_b: Vec3
    metallic: float
    roughness: float
    roughness_variation: float
    grime: float
    texture_scale: float        # noise texture scale (per metre)
    texture_offset: Vec3        # shifts the noise so every frame's paint differs
    marker_red: Vec3
    marker_blue: Vec3
    ring_color: Vec3
    floor_color: Vec3
    wall_color: Vec3
    world_color: Vec3
    world_strength: float


@dataclass(frozen=True)
class SensorParams:
    """Inputs of the camera chain's light, sensor and ISP stages (core.camera_chain.expose_frame);
    ``chain``: a colour camera (core.camera_chain.colour_sensor) in place of the plain sensor
    (full_well_e, read_noise_e)."""
    ideal: bool
    exposure_ev: float
    gain_ev: float
    full_well_e: float
    read_noise_e: float
    adc_bits: int
    vignetting: float
    bloom: float
    noise_seed: int
    chain: ColourChain | None = None


@dataclass(frozen=True)
class RenderSettings:
    """Cycles settings of a frame (see [render] in the config)."""
    samples: int
    denoise: str                 # off | fast | balanced | high
    max_bounces: int
    adaptive_threshold: float    # 0 = adaptive sampling off
    adaptive_min_samples: int
    filter_width_px: float       # Blackman-Harris pixel filter width
    denoise_prefilter: str       # none | fast | accurate
    sampling_pattern: str = "tabulated_sobol"  # tabulated_sobol | blue_noise
    post_filter: str = "off"     # off | median3 | median5 (generator.frame_output)
    # label-aware sampling (generator.marker_regions): the marker regions again at this many
    # samples (0 = off), denoised by marker_denoise (off | fast | balanced | high), with adaptive
    # sampling up to marker_samples when marker_adaptive_threshold > 0
    marker_samples: int = dataclasses.field(default=0, metadata={OMIT_IF_DEFAULT: True})
    marker_denoise: str = dataclasses.field(default="fast", metadata={OMIT_IF_DEFAULT: True})
    marker_adaptive_threshold: float = dataclasses.field(default=0.0, metadata={OMIT_IF_DEFAULT: True})
    # with it, every pixel at least this many samples (0: Cycles' automatic minimum)
    marker_adaptive_min_samples: int = dataclasses.field(default=0, metadata={OMIT_IF_DEFAULT: True})
    # Cycles' light tree: off | markers (in the marker regions' renders only) | on (every render)
    light_tree: str = dataclasses.field(default="off", metadata={OMIT_IF_DEFAULT: True})
    # > 0: the regions' antialiasing noise taken out by their coverage rendered at this many
    # samples (generator.marker_coverage)
    marker_coverage_samples: int = dataclasses.field(default=0, metadata={OMIT_IF_DEFAULT: True})
    # > 0: that coverage render with adaptive sampling up to marker_coverage_samples at this threshold
    marker_coverage_threshold: float = dataclasses.field(default=0.0, metadata={OMIT_IF_DEFAULT: True})
    # > 0: the light noise the coverage correction leaves on the marker smoothed over a Gaussian of
    # this sigma in px (generator.marker_coverage)
    marker_light_smoothing_px: float = dataclasses.field(default=0.0, metadata={OMIT_IF_DEFAULT: True})
    # geometry: that coverage computed from the markers' geometry where it applies and the region's
    # own samples agree, rendered elsewhere (generator.coverage_geometry) | render: always rendered
    marker_coverage_source: str = dataclasses.field(default="render", metadata={OMIT_IF_DEFAULT: True})


@dataclass(frozen=True)
class MotionParams:
    """Section B's motion during a frame's exposure ([motion]; docs/motion.md, generator/motion.py).

    Time t (s) runs from the middle of the exposure (t = 0: the frame's ``d_from_b``). B moves at
    the constant ``velocity_mm_s`` (a vector in D) and does not turn: B at t is ``d_from_b`` with
    ``velocity_mm_s * t`` added to its translation. Every image row is exposed for
    ``exposure_ms``; with a rolling shutter (``readout_ms`` > 0) row v of the render canvas
    (OpenCV rows, top = 0, of a canvas H rows high) is exposed centred at
    t(v) = readout * ((v + 1) / H - 1/2), as Cycles' rolling shutter exposes it (top row first).
    """
    velocity_mm_s: Vec3
    exposure_ms: float
    readout_ms: float = 0.0

    def shutter_ms(self) -> float:
        """Shutter open to close: the first row's exposure start to the last row's end."""
        return self.exposure_ms + self.readout_ms

    def moves(self) -> bool:
        """B moves while the shutter is open (the render needs motion blur)."""
        return self.shutter_ms() > 0 and any(v != 0 for v in self.velocity_mm_s)

    def d_from_b_at(self, d_from_b, t_s: float) -> np.ndarray:
        """B at ``t_s`` seconds from mid-exposure: ``d_from_b`` (4, 4), B at mid-exposure, with
        ``velocity_mm_s * t_s`` added to its translation; (4, 4)."""
        out = np.array(d_from_b, dtype=np.float64)
        if out.shape != (4, 4):
            raise ValueError(f"expected a (4, 4) transform, got {out.shape}")
        out[:3, 3] += np.asarray(self.velocity_mm_s, dtype=np.float64) * float(t_s)
        return out


@dataclass(frozen=True)
class PartMesh:
    """A section's part from a mesh file (core.config_parts): vertices (mm, the section's frame)
    and triangles (vertex indices); with ``[sections] materials = "file"`` its materials (rows of
    ``mesh_base.MATERIAL_KEYS``) and each triangle's (empty: the factory's paint)."""
    vertices: tuple[tuple[float, float, float], ...]
    triangles: tuple[tuple[int, int, int], ...]
    materials: tuple[tuple[float, ...], ...] = dataclasses.field(default=(), metadata={OMIT_IF_DEFAULT: True})
    triangle_materials: tuple[int, ...] = dataclasses.field(default=(), metadata={OMIT_IF_DEFAULT: True})

    def corners(self) -> np.ndarray:
        """(M, 3, 3) mm: each triangle's three vertices."""
        return np.asarray(self.vertices, dtype=np.float64)[np.asarray(self.triangles, dtype=np.int64)]


@dataclass(frozen=True)
class StaticScene:
    """What stays the same for a whole dataset (built once per render worker); ``part_a``,
    ``part_b``: a section's part mesh in place of the parametric cylinder and flange."""
    radius_mm: float
    length_mm: float
    flange_width_mm: float
    flange_height_mm: float
    markers: tuple[Marker, ...]
    max_occluders: int
    clutter_slots: int
    # how far each marker's base reaches below its disc's top face (core.layout.base_depth_mm)
    marker_base_depth_mm: float = dataclasses.field(default=RING_BASE_DEPTH_MM, metadata={OMIT_IF_DEFAULT: True})
    part_a: PartMesh | None = dataclasses.field(default=None, metadata={OMIT_IF_NONE: True})
    part_b: PartMesh | None = dataclasses.field(default=None, metadata={OMIT_IF_NONE: True})

    def part(self, section: str) -> PartMesh | None:
        return self.part_a if section == "A" else self.part_b


@dataclass(frozen=True)
class FrameScene:
    spec: FrameSpec
    d_from_b: Mat4
    camera: CameraModel
    lights: tuple[Light, ...]
    props: tuple[Prop, ...]          # occluders, clutter, glare lamp (absent slots are hidden)
    appearance: Appearance
    sensor: SensorParams
    glare_kind: str                  # "none" | "lamp_in_view" | "specular"
    render_seed: int
    render: RenderSettings
    # B's motion during the exposure; None: B stands still (and to_dict leaves the key out)
    motion: MotionParams | None = dataclasses.field(default=None, metadata={OMIT_IF_NONE: True})

    def d_from_b_array(self) -> np.ndarray:
        return np.array(self.d_from_b)

    @property
    def occluders(self) -> tuple[Prop, ...]:
        return tuple(p for p in self.props if p.kind in OCCLUDER_KINDS)


OCCLUDER_KINDS = ("cable", "bar", "tool", "blob")
CLUTTER_KINDS = ("box", "drum")
CLUTTER_SLOTS = 8
FLOOR_GAP_MM = 350.0  # floor sits this far below the sections' underside


def floor_y_mm(radius_mm: float) -> float:
    """Height of the floor plane (mm) below sections of this radius."""
    return -(radius_mm + FLOOR_GAP_MM)


def to_dict(obj) -> dict:
    """JSON-able dict of a scene dataclass, nested ones included (as ``dataclasses.asdict``); its
    fields marked OMIT_IF_NONE are left out while they are None, those marked OMIT_IF_DEFAULT while
    they have their default, at every level (:func:`from_dict` restores their default), so frames
    and labels written before a field existed stay byte for byte what they were."""
    out = {}
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if (f.metadata.get(OMIT_IF_NONE) and value is None) or \
                (f.metadata.get(OMIT_IF_DEFAULT) and value == f.default):
            continue
        out[f.name] = _plain(value)
    return out


def _plain(value):
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return to_dict(value)
    if isinstance(value, (list, tuple)):
        return type(value)(_plain(v) for v in value)
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return copy.deepcopy(value)


def from_dict(cls, data):
    """Rebuild a scene dataclass from :func:`to_dict` output (nested tuples restored)."""
    hints = typing.get_type_hints(cls)
    kwargs = {}
    for f in dataclasses.fields(cls):
        if f.name in data:
            kwargs[f.name] = _restore(hints[f.name], data[f.name])
    return cls(**kwargs)


def _restore(hint, value):
    if isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union:   # X | None
        if value is None:
            return None
        hint = next(a for a in typing.get_args(hint) if a is not type(None))
    if dataclasses.is_dataclass(hint):
        return from_dict(hint, value)
    if typing.get_origin(hint) is tuple:
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_restore(args[0], v) for v in value)
        return tuple(_restore(a, v) for a, v in zip(args, value))
    if hint is float:
        return float(value)
    return value
