"""Dataset configuration: frozen dataclasses loaded from TOML (data, never executed).

Every key has a default, so an empty file is a valid config; unknown keys, wrong types and
impossible values raise :class:`ConfigError` naming the file, the table and the key.
Ranges are written ``[min, max]``. NaN and inf never pass (one check over every float), and counts
have the named upper bounds below (MAX_FRAMES, MAX_REPEAT_POSES, ...).
"""
from __future__ import annotations

import dataclasses
import json
import math
import re
import tomllib
import typing
from dataclasses import dataclass, field
from pathlib import Path

from dockfactory.core import layout as layout_mod
from dockfactory.core.camera_chain.colour_sensor import CFA_CHOICES, configured_sensor
from dockfactory.core.config_files import resolve_config_files
from dockfactory.core.mesh_base import MAX_TRIANGLES, MeshError, checked_materials
from dockfactory.core.mesh_files import UNITS_MM
from dockfactory.core.mesh_markers import layout_on_parts
from dockfactory.core.camera_chain.demosaic import DEMOSAICS
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.geometry import MAX_PIXEL_ASPECT_DIFF
from dockfactory.core.camera_chain.encoding import JPEG_SUBSAMPLING
from dockfactory.core.camera_chain.isp import DENOISERS, TONE_CURVES
from dockfactory.core.sensor_presets import PRESETS
from dockfactory.core.names import MIN_CHROMA

Range = tuple[float, float]
Overrides = tuple[tuple[str, float], ...]   # a TOML table of name = number, sorted by name

# Upper bounds of the counts and sizes a config may ask for; beyond them a config used to end in a
# MemoryError traceback (frames = 1e12) or a hang (100 M repeat poses) after it passed validation.
# MAX_FRAMES bounds the whole dataset (main + repeatability frames): `render` samples every frame's
# scene before it writes anything (measured ~16 KB and ~13 ms per frame: 1.6 GB and ~20 min at the
# bound) and `check-config` samples every frame's geometry (~0.4 ms per frame). The largest shipped
# config (paper) has 3 200 frames.
MAX_FRAMES = 100_000
MAX_REPEAT_POSES = 1_000        # repeatability ids are repPPP_CC: three digits of pose ...
MAX_REPEAT_CAPTURES = 100       # ... and two of capture
MIN_IMAGE_PX, MAX_IMAGE_PX = 16, 16384  # per side; at 16384 one float32 RGB pass is 3.2 GB
MAX_SAMPLES = 1 << 24           # Cycles' hard limit on samples per pixel
MAX_LIGHT_SMOOTHING_PX = 4.0   # [render] marker_light_smoothing_px: beyond it the smoothing reaches across a small marker
MAX_BOUNCES = 1024              # Blender's limit on light path bounces
# Every float (mm, deg, s, electrons, weights) is finite and at most this in size: 1e9 mm is
# 1000 km, far beyond any docking scene, and sums, spans and products of config values stay finite
# (a [-1e308, 1e308] range passed and then overflowed numpy's uniform sampler).
MAX_MAGNITUDE = 1e9
# Camera units: a dataset holds at most this many physical cameras; lens values beyond
# these bounds are not camera lenses (and the distortion model folds over inside the image).
MAX_CAMERA_UNITS = 100
MAX_PRINCIPAL_OFFSET = 0.25     # |principal point offset| <= this share of the image side
MAX_RADIAL = 1.0                # |k1|, |k2|, |k3|
MAX_TANGENTIAL = 0.05           # |p1|, |p2|
MAX_ABERRATION_PX = 5.0         # |lateral chromatic aberration| at the image corner
F_NUMBER_LIMITS = (0.5, 64.0)
SENSOR_WIDTH_LIMITS_MM = (1.0, 100.0)
# [motion]: B's speed (10 m/s: far beyond any docking approach) and a frame's readout time
MAX_SPEED_MM_S = 10_000.0
MAX_READOUT_MS = 1_000.0

# a licence id as the Hugging Face hub spells them (cc-by-4.0, cc0-1.0, mit, other): the shape only,
# the hub's list changes
LICENSE_ID = re.compile(r"[a-z0-9][a-z0-9.+-]{0,63}")

CONDITIONS = ("normal", "low_light", "occlusion", "glare", "ideal")
CHALLENGING = ("low_light", "occlusion", "glare")


class ConfigError(DockfactoryError):
    """A config that cannot be used; the message names file, table and key."""


@dataclass(frozen=True)
class DatasetConfig:
    name: str = "dockfactory"    # a label for people; not part of any draw
    seed: int = 0                # every random draw of the dataset derives from it
    frames: int = 50             # main frames (train + val + test); the repeatability subset is extra
    train_fraction: float = 0.8  # share of each condition's frames outside the test split
    val_fraction: float = 0.1    # share of each condition's train frames held out as the val split
    license: str = "cc-by-4.0"   # the data's licence in the dataset card (a Hugging Face licence id, or "other")


@dataclass(frozen=True)
class ConditionsConfig:
    """Relative weights of the frame conditions; counts are exact (largest remainder)."""
    normal: float = 2.0          # ordinary workshop light
    low_light: float = 1.0 / 3.0  # several stops under exposed, with digital gain ([sensor] low_light_ev)
    occlusion: float = 1.0 / 3.0  # cables, bars, tools or blobs in front of markers ([occlusion])
    glare: float = 1.0 / 3.0      # a lamp in view or specular highlights ([glare])
    ideal: float = 0.0            # no noise, blur or clutter: the solver's own precision


@dataclass(frozen=True)
class RepeatabilityConfig:
    """Static poses captured several times with new lighting and noise (estimation precision)."""
    poses: int = 0               # static poses (0: no repeatability subset)
    captures: int = 10           # captures of each pose
    condition: str = "normal"    # the condition every capture is taken under


@dataclass(frozen=True)
class ImageConfig:
    width: int = 1280            # pixels
    height: int = 960            # pixels


@dataclass(frozen=True)
class CameraConfig:
    distance_mm: Range = (1000.0, 1800.0)  # camera centre to the look-at point on the seam
    tilt_deg: float = 4.0                 # max |tilt| of the viewing direction about X and Y
    roll_deg: float = 2.0                 # max |roll| about the optical axis
    lateral_jitter_mm: float = 30.0       # max |offset| of the look-at point in X and Y
    focal_px: Range = (1200.0, 3000.0)    # zoom range; capped per frame so markers fit
    margin_px: float = 48.0               # markers keep this far from the image border


@dataclass(frozen=True)
class CameraUnitsConfig:
    """Physical cameras. Each unit draws its lens once from these ranges with the dataset seed
    (README, "Camera units"); the defaults are one ideal pinhole unit."""
    count: int = 1                                   # frames are assigned to units from the seed
    principal_offset_x_px: Range = (0.0, 0.0)        # principal point - image centre
    principal_offset_y_px: Range = (0.0, 0.0)        # (rows; the x one in columns)
    k1: Range = (0.0, 0.0)                           # Brown-Conrady radial (OpenCV's k1, k2, k3)
    k2: Range = (0.0, 0.0)                           # radial, 4th order
    k3: Range = (0.0, 0.0)                           # radial, 6th order
    p1: Range = (0.0, 0.0)                           # tangential (OpenCV's p1, p2)
    p2: Range = (0.0, 0.0)                           # tangential, second coefficient
    pixel_aspect: Range = (1.0, 1.0)                 # fy / fx of a unit's pixels (1: square; a calibration file's fy / fx)
    aberration_red_px: Range = (0.0, 0.0)            # red vs green, radial shift at the image corner
    aberration_blue_px: Range = (0.0, 0.0)           # blue vs green
    sensor_width_mm: float = 36.0                    # sets the aperture (focal mm / f-number)
    depth_of_field: bool = False                     # Cycles depth of field
    f_number: Range = (2.8, 8.0)                     # aperture with depth_of_field
    focus_error_mm: Range = (0.0, 0.0)               # focus distance = aimed distance + error
    jpeg: bool = False                               # JPEG-encode the delivered image
    jpeg_quality: tuple[int, int] = (85, 95)         # [min, max] JPEG quality per frame, 1-100
    jpeg_subsampling: str = "420"                    # 420 (libjpeg's and most cameras' default) | 444
    calibration: str = ""                            # a calibration file (OpenCV, ROS, COLMAP): every unit is that camera


@dataclass(frozen=True)
class RunsConfig:
    """Docking runs: per camera unit the camera's pose and zoom are fixed and B approaches A."""
    frames_per_run: int = 0          # 0: no runs (every frame has its own camera and pose)
    x_end_mm: Range = (1.0, 5.0)     # where a run ends; it starts at the top of [pose] x_mm


@dataclass(frozen=True)
class PoseConfig:
    """Pose of B relative to A (``d_from_b``)."""
    x_mm: Range = (5.0, 150.0)       # axial gap (D's +X: from A toward B)
    y_mm: Range = (-15.0, 15.0)      # vertical offset (+Y up)
    z_mm: Range = (-15.0, 15.0)      # offset toward the camera side (+Z)
    alpha_deg: Range = (-1.5, 1.5)   # rotation about Z: the misalignment the camera sees
    beta_deg: Range = (-1.5, 1.5)    # rotation about Y
    gamma_deg: Range = (-5.0, 5.0)   # roll about the docking axis


@dataclass(frozen=True)
class SectionsConfig:
    radius_mm: float = 300.0        # outer radius of both cylinders
    length_mm: float = 1200.0       # length of each section
    flange_width_mm: float = 20.0   # flange at each docking face: axial width
    flange_height_mm: float = 8.0   # and radial height
    mesh_a: str = ""                # A's part from a mesh file (glTF, OBJ, STL, PLY; its frame is A's, docs/configuration.md): read at load
    mesh_b: str = ""                # B's part the same way (in B's frame); empty: the parametric cylinder
    mesh_units: str = "mm"          # unit of OBJ, STL and PLY coordinates: mm | cm | m | in (glTF is in metres)
    mesh_a_vertices: tuple[tuple[float, float, float], ...] = ()  # A's part as loaded (mm; written by the load of mesh_a)
    mesh_a_triangles: tuple[tuple[int, int, int], ...] = ()       # its triangles (vertex indices)
    mesh_b_vertices: tuple[tuple[float, float, float], ...] = ()  # B's part as loaded (mm, B's frame)
    mesh_b_triangles: tuple[tuple[int, int, int], ...] = ()       # its triangles
    materials: str = "paint"        # paint (the factory's randomised paint on every part) | file (each part's glTF materials: base colour, metallic, roughness)
    mesh_a_materials: tuple[tuple[float, float, float, float, float], ...] = ()  # A's materials as loaded (red, green, blue linear, metallic, roughness; materials = "file")
    mesh_a_triangle_materials: tuple[int, ...] = ()              # each of A's triangles' material
    mesh_b_materials: tuple[tuple[float, float, float, float, float], ...] = ()  # B's materials as loaded
    mesh_b_triangle_materials: tuple[int, ...] = ()              # each of B's triangles' material


@dataclass(frozen=True)
class MarkersConfig:
    diameter_mm: float = 20.0       # of each coloured disc
    raise_mm: float | None = None   # height of the disc's top face above the surface; unset: the form's (layout.FORM_RAISE_MM: puck 1 mm, flat 0.1 mm)
    form: str = "flat"              # flat (printed on a dark plate raise_mm thick, at most 0.5 mm) | puck (the disc on a raised dark cylinder, its side showing at a slant); docs/rendering.md
    ring: str = "dark"              # the ring around each disc: dark (reflectance 0.01-0.05) | white (0.70-0.85) | mixed (each frame one of the two)
    layout_a: tuple[tuple[float, float], ...] = layout_mod.DEFAULT_LAYOUT_A  # A's markers: (s_mm from the docking face, phi_deg about the axis, 0 = toward +Z)
    layout_b: tuple[tuple[float, float], ...] = layout_mod.DEFAULT_LAYOUT_B  # B's, the same way

    def __post_init__(self):
        """An unset ``raise_mm`` becomes the form's (an unknown form keeps the puck's: validation
        names the form), so every reader sees a number."""
        if self.raise_mm is None:
            object.__setattr__(self, "raise_mm", layout_mod.FORM_RAISE_MM.get(self.form, layout_mod.FORM_RAISE_MM["puck"]))


@dataclass(frozen=True)
class RenderConfig:
    samples: int = 1                # per pixel outside the marker regions (marker_samples converges those); 1: about 5 s a frame at 1280x960 on 2 cores (bench/results/speeds)
    denoise: str = "fast"           # off | fast | balanced | high (OpenImageDenoise quality)
    max_bounces: int = 2            # light path bounces of Cycles
    adaptive_threshold: float = 0.0  # > 0: adaptive sampling up to `samples` (noise threshold)
    adaptive_min_samples: int = 0    # with adaptive sampling; 0 = Cycles' automatic choice
    filter_width_px: float = 1.5     # Blackman-Harris pixel filter width
    denoise_prefilter: str = "none"  # none | fast | accurate: OIDN prefiltering of albedo/normal
    sampling_pattern: str = "tabulated_sobol"  # tabulated_sobol | blue_noise (Cycles' pixel sample pattern)
    post_filter: str = "off"         # off | median3 | median5: median of the linear render, before the lens
    marker_samples: int = 40         # > 0: label-aware sampling, the marker regions rendered again at this many samples (docs/rendering.md); 0 = off
    marker_denoise: str = "fast"     # off | fast | balanced | high: the denoiser of those marker regions (docs/rendering.md)
    marker_adaptive_threshold: float = 0.02  # > 0: those regions with adaptive sampling up to marker_samples (noise threshold: the markers' edges get them all, flat paint stops early; docs/rendering.md); 0 = every pixel marker_samples
    marker_adaptive_min_samples: int = 4  # with that adaptive sampling, every pixel at least this many samples; 0 = Cycles' automatic minimum (most of marker_samples at small thresholds)
    marker_coverage_samples: int = 128  # > 0: those regions' antialiasing noise taken out by their exact coverage, rendered at this many samples (docs/rendering.md); 0 = off
    marker_coverage_threshold: float = 0.005  # > 0: that coverage render with adaptive sampling up to marker_coverage_samples (the markers' edges get them, their insides stop early); 0 = every pixel all of them
    marker_coverage_source: str = "geometry"  # geometry: that coverage computed from the markers' geometry where it applies and the regions' own samples agree, rendered elsewhere | render: always rendered (docs/rendering.md)
    marker_light_smoothing_px: float = 1.0  # > 0: with the coverage correction, the light noise its samples leave on the marker smoothed over a Gaussian of this sigma (px), its exact-coverage edges kept (docs/rendering.md); 0 = off
    light_tree: str = "markers"      # off | markers | on: Cycles' light tree in the marker regions only, or everywhere (docs/rendering.md)
    keep_exr: bool = False          # keep a compressed EXR (linear RGB, depth, index) per frame
    frame_timeout_s: float = 300.0  # a frame over this is a hung worker
    device: str = "cpu"             # cpu | gpu (Cycles on CUDA, OptiX or HIP; its frames differ from the CPU's)

    def rendered_light_tree(self) -> str:
        """The light tree the frames are rendered with: ``markers`` without label-aware sampling
        renders as ``off`` (no marker regions to use it in)."""
        return "off" if self.light_tree == "markers" and self.marker_samples == 0 else self.light_tree

    def rendered_coverage_samples(self) -> int:
        """The coverage correction's samples the frames are rendered with: 0 without label-aware
        sampling (no marker regions to correct)."""
        return self.marker_coverage_samples if self.marker_samples else 0

    def rendered_coverage_threshold(self) -> float:
        """The coverage render's adaptive threshold the frames are rendered with: 0 without a
        coverage render."""
        return self.marker_coverage_threshold if self.rendered_coverage_samples() else 0.0

    def rendered_coverage_source(self) -> str:
        """Where the coverage correction's coverage comes from in the frames rendered: ``render``
        without a coverage correction (nothing to compute)."""
        return self.marker_coverage_source if self.rendered_coverage_samples() else "render"

    def rendered_light_smoothing(self) -> float:
        """The marker's light smoothing the frames are rendered with: 0 without the coverage
        correction (it smooths what that correction leaves)."""
        return self.marker_light_smoothing_px if self.rendered_coverage_samples() else 0.0

    def rendered_adaptive_threshold(self) -> float:
        """The marker regions' adaptive threshold the frames are rendered with: 0 without
        label-aware sampling (no marker regions to sample)."""
        return self.marker_adaptive_threshold if self.marker_samples else 0.0

    def rendered_adaptive_min_samples(self) -> int:
        """The marker regions' adaptive minimum the frames are rendered with: 0 without adaptive
        sampling there (no minimum to keep), at most ``marker_samples``."""
        return min(self.marker_adaptive_min_samples, self.marker_samples) if self.rendered_adaptive_threshold() else 0


@dataclass(frozen=True)
class SensorConfig:
    """The camera after the lens: exposure, sensor, ISP (the camera chain, core/camera_chain/)."""
    full_well_e: Range = (8000.0, 20000.0)  # electrons at linear 1.0 after auto exposure
    read_noise_e: Range = (2.0, 6.0)         # electrons, per frame
    adc_bits: int = 12                       # 8-16: the raw frame's depth
    exposure_ev: Range = (-0.4, 0.3)         # normal frames, around auto exposure
    low_light_ev: Range = (-5.0, -3.0)       # several stops down
    low_light_gain_ev: Range = (0.5, 2.0)    # digital gain that partly makes up for it (net 1-4.5 EV darker)
    vignetting: Range = (0.0, 0.25)          # relative fall-off at the image corners
    # A colour camera (camera_chain.colour_sensor): with presets, EMVA 1288 sensors replace the model above
    # (full_well_e, read_noise_e); each per-unit list gives unit u its item u % len(list).
    presets: tuple[str, ...] = ()            # core.sensor_presets names; () keeps the model above
    overrides: Overrides = ()                # [sensor.overrides]: preset figures replaced, key by key
    cfa: tuple[str, ...] = ("none",)         # per unit: RGGB | BGGR | GRBG | GBRG | none (three-chip)
    demosaic: tuple[str, ...] = ("bilinear",)  # per unit: bilinear | edge_aware | vng | mhc
    crosstalk: Range = (0.0, 0.0)            # per unit: share of each channel's light in each other one
    exposure_time_ms: Range = (10.0, 10.0)   # per frame (dark current; with [motion], the blur's exposure)
    wb_error: Range = (0.0, 0.0)             # per frame: relative error of the red and blue gains
    colour_correction: bool = True           # the ISP's colour-correction matrix
    tone: str = "srgb"                       # srgb | gamma22
    denoise: str = "off"                     # off | bilateral (the ISP's, on the 8-bit image)
    sharpen: Range = (0.0, 0.0)              # per unit: unsharp-mask amount
    sharpen_sigma_px: float = 1.0            # the unsharp mask's Gaussian
    raw_output: bool = False                 # also write raw/<id>.png: the raw frame in DN, 16 bit


@dataclass(frozen=True)
class MotionConfig:
    """Section B moving during the exposure: motion blur and a rolling shutter (docs/motion.md).
    Off by default: without it a config samples, labels and renders what it did before. The
    exposure is the frame's [sensor] exposure_time_ms draw."""
    enabled: bool = False                  # true: B moves during the exposure
    velocity_mm_s: Range = (0.0, 0.0)      # per frame: closing speed toward A (B's velocity along -X of D)
    velocity_y_mm_s: Range = (0.0, 0.0)    # per frame: B's vertical velocity (+Y of D)
    velocity_z_mm_s: Range = (0.0, 0.0)    # per frame: B's velocity toward the camera side (+Z of D)
    rolling_shutter_ms: float = 0.0        # readout of a whole frame, top row first; 0 = global shutter


@dataclass(frozen=True)
class OcclusionConfig:
    occluders: tuple[int, int] = (1, 3)   # [min, max] occluders in an occlusion frame
    kinds: tuple[str, ...] = ("cable", "bar", "tool", "blob")  # the shapes drawn from
    gap_mm: Range = (60.0, 400.0)   # distance of the occluder in front of the marker it covers


@dataclass(frozen=True)
class GlareConfig:
    kinds: tuple[str, ...] = ("lamp_in_view", "specular")  # the glare sources drawn from
    bloom: Range = (0.02, 0.08)     # veiling glare: share of the light the lens scatters into a wide halo


@dataclass(frozen=True)
class LabelsConfig:
    visible_threshold: float = 0.5  # visible fraction at or above which COCO visibility is 2
    min_chroma: float = MIN_CHROMA  # a marker whose colour is washed out below this is not legible


@dataclass(frozen=True)
class ExportConfig:
    """Exports written when the dataset completes. A name is a format of the export registry
    (``dockfactory dataset export --help`` lists them) not written on demand only; check-config,
    render and run refuse any other in one line naming the file, table and key."""
    formats: tuple[str, ...] = ("coco", "yolo")  # the formats written when the dataset completes




# keys added after datasets were published, at the value that renders what those datasets hold
# (or, for the licence, at the default those datasets are published under): left out of the
# identity's config at that value (Config.to_dict), so their version ids stay
IDENTITY_NEUTRAL = {("render", "device"): "cpu", ("render", "marker_samples"): 0, ("render", "marker_denoise"): "fast",
                    ("render", "marker_adaptive_threshold"): 0.0, ("render", "marker_adaptive_min_samples"): 0,
                    ("render", "light_tree"): "off",
                    ("render", "marker_coverage_samples"): 0, ("render", "marker_coverage_threshold"): 0.0,
                    ("render", "marker_light_smoothing_px"): 0.0, ("render", "marker_coverage_source"): "render",
                    ("dataset", "license"): "cc-by-4.0", ("markers", "ring"): "dark",
                    ("markers", "form"): "puck", ("camera_units", "calibration"): "",
                    ("camera_units", "pixel_aspect"): [1.0, 1.0],
                    ("sections", "mesh_a"): "", ("sections", "mesh_b"): "", ("sections", "mesh_units"): "mm",
                    ("sections", "mesh_a_vertices"): [], ("sections", "mesh_a_triangles"): [],
                    ("sections", "mesh_b_vertices"): [], ("sections", "mesh_b_triangles"): [],
                    ("sections", "materials"): "paint",
                    ("sections", "mesh_a_materials"): [], ("sections", "mesh_a_triangle_materials"): [],
                    ("sections", "mesh_b_materials"): [], ("sections", "mesh_b_triangle_materials"): []}
RENDER_DEVICES = ("cpu", "gpu")
PART_MATERIALS = ("paint", "file")
LIGHT_TREE_CHOICES = ("off", "markers", "on")
COVERAGE_SOURCES = ("geometry", "render")


@dataclass(frozen=True)
class Config:
    dataset: DatasetConfig = field(default_factory=DatasetConfig)
    conditions: ConditionsConfig = field(default_factory=ConditionsConfig)
    repeatability: RepeatabilityConfig = field(default_factory=RepeatabilityConfig)
    image: ImageConfig = field(default_factory=ImageConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    camera_units: CameraUnitsConfig = field(default_factory=CameraUnitsConfig)
    runs: RunsConfig = field(default_factory=RunsConfig)
    pose: PoseConfig = field(default_factory=PoseConfig)
    sections: SectionsConfig = field(default_factory=SectionsConfig)
    markers: MarkersConfig = field(default_factory=MarkersConfig)
    render: RenderConfig = field(default_factory=RenderConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    motion: MotionConfig = field(default_factory=MotionConfig)
    occlusion: OcclusionConfig = field(default_factory=OcclusionConfig)
    glare: GlareConfig = field(default_factory=GlareConfig)
    labels: LabelsConfig = field(default_factory=LabelsConfig)
    export: ExportConfig = field(default_factory=ExportConfig)

    def to_dict(self, full: bool = False) -> dict:
        """Plain JSON-able dict (tuples become lists): the dataset identity's config (its version id
        is a hash of it), where a key added later at a value that leaves the output unchanged
        (:data:`IDENTITY_NEUTRAL`) is left out, so the datasets made before it keep their version
        ids; ``full``: every key."""
        d = json.loads(json.dumps(dataclasses.asdict(self)))
        if not full:
            d["render"]["light_tree"] = self.render.rendered_light_tree()
            d["render"]["marker_coverage_samples"] = self.render.rendered_coverage_samples()
            d["render"]["marker_coverage_threshold"] = self.render.rendered_coverage_threshold()
            d["render"]["marker_light_smoothing_px"] = self.render.rendered_light_smoothing()
            d["render"]["marker_coverage_source"] = self.render.rendered_coverage_source()
            d["render"]["marker_adaptive_threshold"] = self.render.rendered_adaptive_threshold()
            d["render"]["marker_adaptive_min_samples"] = self.render.rendered_adaptive_min_samples()
        for (table, key), neutral in ([] if full else IDENTITY_NEUTRAL.items()):
            if d[table][key] == neutral:
                del d[table][key]
        return d

    def resolved_dict(self) -> dict:
        """:meth:`to_dict` plus every identity-neutral key at its neutral value where that is not
        today's default: what a written config must state so that reading it back gives this
        config (a key left out reads as today's default)."""
        d, full = self.to_dict(), self.to_dict(full=True)
        for (table, key), neutral in IDENTITY_NEUTRAL.items():
            if full[table][key] == neutral != _default_of(table, key):
                d[table][key] = neutral
        return d

    def canonical_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))

    def markers_layout(self):
        """Every marker, A's then B's: on the cylinder, or cast onto a section's part mesh."""
        return layout_on_parts(self.sections, self.markers)[0]


# ----------------------------------------------------------------------------- loading

def _convert(value, hint, where: str):
    """Check ``value`` against the type ``hint`` and convert lists to tuples."""
    origin = typing.get_origin(hint)
    if hint is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        return value
    if hint is float or hint == (float | None):   # TOML has no null: an optional number given is a number
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if hint == Overrides:   # a TOML table, or the [[name, number], ...] pairs a stored config holds
        if isinstance(value, list) and all(isinstance(v, list) and len(v) == 2 for v in value):
            value = dict(value)
        if not isinstance(value, dict) or not all(isinstance(k, str) for k in value):
            raise ConfigError(f"{where}: expected a table of name = number, got {value!r}")
        return tuple(sorted((k, _convert(v, float, f"{where}.{k}")) for k, v in value.items()))
    if hint is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    if origin is tuple:
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            if isinstance(value, str) and args[0] is str:   # one name for a list of names
                value = [value]
            if not isinstance(value, (list, tuple)):
                raise ConfigError(f"{where}: expected a list, got {value!r}")
            return tuple(_convert(v, args[0], f"{where}[{i}]") for i, v in enumerate(value))
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where}: expected a list, got {value!r}")
        if len(value) != len(args):
            raise ConfigError(f"{where}: expected {len(args)} values, got {len(value)}")
        return tuple(_convert(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
    raise TypeError(f"unsupported config type {hint!r} at {where}")  # programming error


def build_dataclass(cls, data, source: str, table: str | None = None):
    """Build the frozen dataclass ``cls`` from TOML data, rejecting unknown keys and wrong types."""
    where = f"{source}: [{table}]" if table else f"{source}:"
    if not isinstance(data, dict):
        raise ConfigError(f"{where} expected a table, got {data!r}")
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(data) - set(names))
    if unknown:
        what = "key" if table else "table"
        raise ConfigError(f"{where} unknown {what} {unknown[0]!r} (known: {', '.join(names)})")
    kwargs = {}
    for name in names:
        if name not in data:
            continue
        hint = hints[name]
        if dataclasses.is_dataclass(hint):
            kwargs[name] = build_dataclass(hint, data[name], source, name)
        else:
            kwargs[name] = _convert(data[name], hint, f"{where} {name}")
    return cls(**kwargs)


def config_from_dict(data: dict, source: str = "<config>") -> Config:
    """Build and validate a :class:`Config`; errors name ``source``. ``[render] light_tree`` and
    ``marker_coverage_samples`` / ``marker_coverage_threshold`` / ``marker_light_smoothing_px`` /
    ``marker_coverage_source`` (``render`` without a coverage correction) /
    ``marker_adaptive_threshold`` / ``marker_adaptive_min_samples`` are the ones the frames render
    with (without label-aware sampling ``markers`` is ``off``, the coverage samples and the
    adaptive threshold 0, without those samples the coverage threshold and the smoothing 0, without an adaptive threshold its minimum 0, and the
    minimum at most ``marker_samples``), so a config and its stored identity read back equal."""
    cfg = build_dataclass(Config, data, source)
    validate(cfg, source)
    render = dataclasses.replace(cfg.render, light_tree=cfg.render.rendered_light_tree(),
                                 marker_coverage_samples=cfg.render.rendered_coverage_samples(),
                                 marker_coverage_threshold=cfg.render.rendered_coverage_threshold(),
                                 marker_light_smoothing_px=cfg.render.rendered_light_smoothing(),
                                 marker_coverage_source=cfg.render.rendered_coverage_source(),
                                 marker_adaptive_threshold=cfg.render.rendered_adaptive_threshold(),
                                 marker_adaptive_min_samples=cfg.render.rendered_adaptive_min_samples())
    return dataclasses.replace(cfg, render=render)


def _default_of(table: str, key: str):
    """Today's default of ``[table] key``."""
    return json.loads(json.dumps(dataclasses.asdict(getattr(Config(), table))))[key]


def config_from_identity(data: dict, source: str = "<config>") -> Config:
    """Build a :class:`Config` from a stored identity dict (:meth:`Config.to_dict`: a dataset's
    ``dataset.json``, a manifest): an identity-neutral key it leaves out held its neutral value,
    whatever today's default (a stored dataset reads back as it was rendered)."""
    if not isinstance(data, dict):
        return config_from_dict(data, source)
    filled = {t: (dict(v) if isinstance(v, dict) else v) for t, v in data.items()}
    for (table, key), neutral in IDENTITY_NEUTRAL.items():
        if isinstance(filled.get(table, {}), dict):
            filled.setdefault(table, {}).setdefault(key, neutral)
    return config_from_dict(filled, source)


def load_config(path) -> Config:
    """Read a TOML config file; raises ConfigError (file, key, value) on any problem."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config: {exc.strerror}") from exc
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from exc
    except RecursionError:
        raise ConfigError(f"{path}: not valid TOML: its arrays or tables nest too deeply") from None
    data, _ = resolve_config_files(data, path)
    return config_from_dict(data, str(path))


# ----------------------------------------------------------------------------- validation

def _err(source, table, key, msg):
    return ConfigError(f"{source}: [{table}] {key}: {msg}")


def _check_range(source, table, key, rng, lo=None, hi=None):
    a, b = rng
    if a > b:
        raise _err(source, table, key, f"min {a} > max {b}")
    if lo is not None and a < lo:
        raise _err(source, table, key, f"{a} is below the smallest allowed value {lo}")
    if hi is not None and b > hi:
        raise _err(source, table, key, f"{b} is above the largest allowed value {hi}")


def _check_positive(source, table, key, value, allow_zero=False):
    if value < 0 or (value == 0 and not allow_zero):
        raise _err(source, table, key, f"must be {'>= 0' if allow_zero else '> 0'}, got {value}")


def _check_finite(source, table, key, value) -> None:
    """Every float (also inside ranges and layouts) finite and at most MAX_MAGNITUDE in size."""
    if isinstance(value, tuple):
        for i, v in enumerate(value):
            _check_finite(source, table, f"{key}[{i}]", v)
    elif isinstance(value, float):
        if not math.isfinite(value):
            raise _err(source, table, key, f"must be a finite number, got {value}")
        if abs(value) > MAX_MAGNITUDE:
            raise _err(source, table, key, f"{value:g} is out of range (|value| <= {MAX_MAGNITUDE:g})")


def _validate_numbers(cfg: Config, source: str) -> None:
    """One generic pass over every field: NaN and inf pass every ``<`` test, so reject them first."""
    for table in dataclasses.fields(cfg):
        section = getattr(cfg, table.name)
        for f in dataclasses.fields(section):
            _check_finite(source, table.name, f.name, getattr(section, f.name))


def _check_at_most(source, table, key, value, limit, why: str) -> None:
    if value > limit:
        raise _err(source, table, key, f"{value} is above the limit {limit} ({why})")


def _check_marker_coverage(source, rc: "RenderConfig") -> None:
    """[render] marker_coverage_samples: 0 or a sample count (inert without label-aware sampling);
    marker_coverage_threshold: 0 or an adaptive threshold below 1; marker_coverage_source: one of
    :data:`COVERAGE_SOURCES`; marker_light_smoothing_px: 0 or
    a sigma up to :data:`MAX_LIGHT_SMOOTHING_PX`."""
    _check_positive(source, "render", "marker_coverage_samples", rc.marker_coverage_samples, allow_zero=True)
    _check_at_most(source, "render", "marker_coverage_samples", rc.marker_coverage_samples, MAX_SAMPLES,
                   "Cycles' limit")
    _check_positive(source, "render", "marker_coverage_threshold", rc.marker_coverage_threshold, allow_zero=True)
    if rc.marker_coverage_threshold >= 1.0:
        raise _err(source, "render", "marker_coverage_threshold",
                   f"{rc.marker_coverage_threshold} is not below 1 (a noise threshold: 0.005 is the default, 0 = off)")
    if rc.marker_coverage_source not in COVERAGE_SOURCES:
        raise _err(source, "render", "marker_coverage_source",
                   f"{rc.marker_coverage_source!r} is not one of {', '.join(COVERAGE_SOURCES)}")
    _check_positive(source, "render", "marker_light_smoothing_px", rc.marker_light_smoothing_px, allow_zero=True)
    _check_at_most(source, "render", "marker_light_smoothing_px", rc.marker_light_smoothing_px, MAX_LIGHT_SMOOTHING_PX,
                   "it would reach across a small marker")


def validate(cfg: Config, source: str = "<config>") -> None:
    """Reject impossible configs before anything is rendered or written (no frame is sampled)."""
    for check in (_validate_numbers, _validate_dataset, _validate_image_camera, _validate_camera_units,
                  _validate_lens_extras, _validate_runs, _validate_pose_sections, _validate_markers,
                  _validate_render, _validate_sensor, _validate_motion, _validate_occlusion_glare,
                  _validate_labels):
        check(cfg, source)


def _validate_dataset(cfg: Config, source: str) -> None:
    """[dataset], [conditions] and [repeatability]."""
    d = cfg.dataset
    _check_positive(source, "dataset", "frames", d.frames, allow_zero=True)
    _check_at_most(source, "dataset", "frames", d.frames, MAX_FRAMES, "frames of one dataset")
    if not 0.0 <= d.train_fraction <= 1.0:
        raise _err(source, "dataset", "train_fraction", f"must be in [0, 1], got {d.train_fraction}")
    if not 0.0 <= d.val_fraction < 1.0:
        raise _err(source, "dataset", "val_fraction", f"must be in [0, 1), got {d.val_fraction}")
    if not 0 <= d.seed < 2**63:
        raise _err(source, "dataset", "seed", f"must be in [0, 2^63), got {d.seed}")
    if not LICENSE_ID.fullmatch(d.license):
        raise _err(source, "dataset", "license", f"{d.license!r} is not a licence id (lower-case letters, digits, "
                                                  f"'.', '-', '+'; e.g. cc-by-4.0, cc0-1.0, mit, other)")
    weights = dataclasses.asdict(cfg.conditions)
    for k, w in weights.items():
        _check_positive(source, "conditions", k, w, allow_zero=True)
    if d.frames > 0 and sum(weights.values()) <= 0:
        raise _err(source, "conditions", "*", "all weights are zero")
    r = cfg.repeatability
    _check_positive(source, "repeatability", "poses", r.poses, allow_zero=True)
    _check_positive(source, "repeatability", "captures", r.captures)
    _check_at_most(source, "repeatability", "poses", r.poses, MAX_REPEAT_POSES,
                   "repeatability ids have three digits of pose")
    _check_at_most(source, "repeatability", "captures", r.captures, MAX_REPEAT_CAPTURES,
                   "repeatability ids have two digits of capture")
    if r.condition not in CONDITIONS:
        raise _err(source, "repeatability", "condition", f"{r.condition!r} is not one of {CONDITIONS}")
    if d.frames + r.poses * r.captures > MAX_FRAMES:
        raise _err(source, "repeatability", "poses", f"{r.poses} poses x {r.captures} captures + {d.frames} "
                   f"main frames is above the limit of {MAX_FRAMES} frames of one dataset")
    if d.frames + r.poses * r.captures == 0:
        raise _err(source, "dataset", "frames", "the dataset would have no frames")


def _validate_image_camera(cfg: Config, source: str) -> None:
    im, c = cfg.image, cfg.camera
    for k in ("width", "height"):
        v = getattr(im, k)
        if not MIN_IMAGE_PX <= v <= MAX_IMAGE_PX:
            raise _err(source, "image", k, f"must be in [{MIN_IMAGE_PX}, {MAX_IMAGE_PX}], got {v}")
    _check_range(source, "camera", "distance_mm", c.distance_mm, lo=1e-3)
    _check_range(source, "camera", "focal_px", c.focal_px, lo=1e-3)
    for k in ("tilt_deg", "roll_deg"):
        if not 0 <= getattr(c, k) < 45:
            raise _err(source, "camera", k, f"must be in [0, 45), got {getattr(c, k)}")
    _check_positive(source, "camera", "lateral_jitter_mm", c.lateral_jitter_mm, allow_zero=True)
    _check_positive(source, "camera", "margin_px", c.margin_px, allow_zero=True)
    if 2 * c.margin_px >= min(im.width, im.height):
        raise _err(source, "camera", "margin_px", f"{c.margin_px} leaves no room in a "
                   f"{im.width}x{im.height} image")


def _check_symmetric(source, table, key, rng, limit, name: str) -> None:
    """A range inside [-limit, limit] (``name`` is the named bound)."""
    _check_range(source, table, key, rng)
    if max(abs(rng[0]), abs(rng[1])) > limit:
        raise _err(source, table, key, f"{list(rng)} is outside [-{limit:g}, {limit:g}] ({name})")


def _validate_camera_units(cfg: Config, source: str) -> None:
    """[camera_units]: count, principal point, distortion, pixel aspect and aberration ranges."""
    u, t = cfg.camera_units, "camera_units"
    if u.calibration:
        raise _err(source, t, "calibration", f"{u.calibration!r} is read when a config file is loaded (load_config), "
                   "relative to its folder: a config built from data has none")
    if not 1 <= u.count <= MAX_CAMERA_UNITS:
        raise _err(source, t, "count", f"must be in [1, {MAX_CAMERA_UNITS}] (MAX_CAMERA_UNITS), got {u.count}")
    for key, side in (("principal_offset_x_px", cfg.image.width), ("principal_offset_y_px", cfg.image.height)):
        _check_symmetric(source, t, key, getattr(u, key), MAX_PRINCIPAL_OFFSET * side,
                         f"MAX_PRINCIPAL_OFFSET: {MAX_PRINCIPAL_OFFSET:g} of the image side")
    for key in ("k1", "k2", "k3"):
        _check_symmetric(source, t, key, getattr(u, key), MAX_RADIAL, "MAX_RADIAL")
    for key in ("p1", "p2"):
        _check_symmetric(source, t, key, getattr(u, key), MAX_TANGENTIAL, "MAX_TANGENTIAL")
    for key in ("aberration_red_px", "aberration_blue_px"):
        _check_symmetric(source, t, key, getattr(u, key), MAX_ABERRATION_PX, "MAX_ABERRATION_PX")
    _check_range(source, t, "pixel_aspect", u.pixel_aspect, 1.0 - MAX_PIXEL_ASPECT_DIFF, 1.0 + MAX_PIXEL_ASPECT_DIFF)


def _validate_lens_extras(cfg: Config, source: str) -> None:
    """[camera_units]: sensor, depth of field and JPEG."""
    u, t = cfg.camera_units, "camera_units"
    lo, hi = SENSOR_WIDTH_LIMITS_MM
    if not lo <= u.sensor_width_mm <= hi:
        raise _err(source, t, "sensor_width_mm", f"must be in [{lo:g}, {hi:g}], got {u.sensor_width_mm}")
    lens_mm = cfg.camera.focal_px[0] * u.sensor_width_mm / cfg.image.width
    if lens_mm < 1.0:
        raise _err(source, t, "sensor_width_mm", f"{u.sensor_width_mm:g} mm makes the smallest focal ({cfg.camera.focal_px[0]:g} "
                   f"px) a {lens_mm:.2f} mm lens, below Blender's 1 mm")
    _check_range(source, t, "f_number", u.f_number, *F_NUMBER_LIMITS)
    _check_range(source, t, "focus_error_mm", u.focus_error_mm)
    nearest = cfg.camera.distance_mm[0]
    if u.focus_error_mm[0] <= -0.5 * nearest:
        raise _err(source, t, "focus_error_mm", f"{u.focus_error_mm[0]} would focus at or nearer than half of "
                   f"the nearest camera distance ({nearest:g} mm)")
    _check_range(source, t, "jpeg_quality", u.jpeg_quality, 1, 100)
    if u.jpeg_subsampling not in JPEG_SUBSAMPLING:
        raise _err(source, t, "jpeg_subsampling", f"{u.jpeg_subsampling!r} is not one of {', '.join(JPEG_SUBSAMPLING)}")


def _validate_runs(cfg: Config, source: str) -> None:
    r = cfg.runs
    if r.frames_per_run == 1 or not 0 <= r.frames_per_run <= MAX_FRAMES:
        raise _err(source, "runs", "frames_per_run", f"must be 0 (no runs) or in [2, {MAX_FRAMES}], "
                   f"got {r.frames_per_run}")
    _check_range(source, "runs", "x_end_mm", r.x_end_mm, lo=0.0)
    if r.x_end_mm[1] >= cfg.pose.x_mm[1]:
        raise _err(source, "runs", "x_end_mm", f"{r.x_end_mm[1]} must be below the top of [pose] x_mm "
                   f"({cfg.pose.x_mm[1]}), where a run starts")


def _validate_pose_sections(cfg: Config, source: str) -> None:
    for k in ("x_mm", "y_mm", "z_mm"):
        _check_range(source, "pose", k, getattr(cfg.pose, k))
    for k in ("alpha_deg", "beta_deg", "gamma_deg"):
        _check_range(source, "pose", k, getattr(cfg.pose, k), lo=-30, hi=30)
    s = cfg.sections
    _check_positive(source, "sections", "radius_mm", s.radius_mm)
    _check_positive(source, "sections", "length_mm", s.length_mm)
    _check_positive(source, "sections", "flange_width_mm", s.flange_width_mm, allow_zero=True)
    _check_positive(source, "sections", "flange_height_mm", s.flange_height_mm, allow_zero=True)
    _validate_parts(s, source)


def _validate_parts(s: SectionsConfig, source: str) -> None:
    """[sections] part meshes: a file name is read at load (never left in a built config); the
    loaded triangles index their vertices."""
    if s.mesh_units not in UNITS_MM:
        raise _err(source, "sections", "mesh_units", f"{s.mesh_units!r} is not one of {', '.join(UNITS_MM)}")
    for sec in ("a", "b"):
        name, verts, tris = (getattr(s, f"mesh_{sec}{k}") for k in ("", "_vertices", "_triangles"))
        if name:
            raise _err(source, "sections", f"mesh_{sec}", f"{name!r} is read when a config file is loaded "
                       "(load_config), relative to its folder: a config built from data has none")
        if len(tris) > MAX_TRIANGLES:
            raise _err(source, "sections", f"mesh_{sec}_triangles", f"{len(tris)} triangles, more than {MAX_TRIANGLES}")
        if tris and not (0 <= min(map(min, tris)) and max(map(max, tris)) < len(verts)):
            raise _err(source, "sections", f"mesh_{sec}_triangles", f"a triangle names a vertex beyond the "
                       f"{len(verts)} of mesh_{sec}_vertices")
        if bool(verts) != bool(tris):
            raise _err(source, "sections", f"mesh_{sec}_vertices", "vertices and triangles come together")
        _validate_part_materials(s, sec, source)


def _validate_part_materials(s: SectionsConfig, sec: str, source: str) -> None:
    """[sections] materials: "file" needs every part's materials (read at load), "paint" none; the
    loaded materials are rows of five numbers in [0, 1], one material index per triangle."""
    if s.materials not in PART_MATERIALS:
        raise _err(source, "sections", "materials", f"{s.materials!r} is not one of {', '.join(PART_MATERIALS)}")
    tris, mats, idx = (getattr(s, f"mesh_{sec}{k}") for k in ("_triangles", "_materials", "_triangle_materials"))
    if s.materials == "paint" and (mats or idx):
        raise _err(source, "sections", f"mesh_{sec}_materials", 'stated with materials = "paint"; give one')
    if s.materials == "file" and tris and not mats:
        raise _err(source, "sections", "materials", f'"file", but part {sec.upper()} has no materials '
                   "(only glTF files carry them): use \"paint\"")
    if mats:
        try:
            if not tris:
                raise MeshError("materials without a part")
            checked_materials(mats, idx, len(tris), f"mesh_{sec}_materials")
        except (MeshError, ValueError) as e:
            raise _err(source, "sections", f"mesh_{sec}_materials", "each material is five numbers in [0, 1] "
                       "and each triangle of the part names one of them") from e


def _validate_markers(cfg: Config, source: str) -> None:
    m, s = cfg.markers, cfg.sections
    _check_positive(source, "markers", "diameter_mm", m.diameter_mm)
    _check_positive(source, "markers", "raise_mm", m.raise_mm)
    if m.form not in layout_mod.MARKER_FORMS:
        raise _err(source, "markers", "form", f"{m.form!r} is not one of {', '.join(layout_mod.MARKER_FORMS)}")
    if m.form == "flat" and m.raise_mm > layout_mod.FLAT_MAX_RAISE_MM:
        raise _err(source, "markers", "raise_mm", f"a flat marker is a printed plate at most "
                   f"{layout_mod.FLAT_MAX_RAISE_MM:g} mm thick, got {m.raise_mm:g} (set raise_mm, e.g. 0.2)")
    if m.ring not in layout_mod.RING_DESIGNS:
        raise _err(source, "markers", "ring", f"{m.ring!r} is not one of {', '.join(layout_mod.RING_DESIGNS)}")
    reach = m.diameter_mm / 2 + layout_mod.RING_EXTRA_MM
    lo, hi = s.flange_width_mm + reach + 2.0, s.length_mm - reach
    for key, pattern in (("layout_a", m.layout_a), ("layout_b", m.layout_b)):
        on_part = bool(getattr(s, f"mesh_{key[-1]}_triangles"))   # a part: its surface decides (placement)
        for i, (s_mm, phi) in enumerate(pattern):
            if not on_part and not lo <= s_mm <= hi:
                raise _err(source, "markers", f"{key}[{i}]",
                           f"axial offset {s_mm} mm puts the marker on the flange or off the section "
                           f"(allowed: {lo:g} to {hi:g} mm)")
            if not -80 <= phi <= 80:
                raise _err(source, "markers", f"{key}[{i}]", f"angle {phi} deg is not on the camera side")
    try:
        problems = layout_mod.layout_problems(cfg.markers_layout())
    except MeshError as exc:
        raise ConfigError(f"{source}: {exc}") from None
    if problems:
        raise _err(source, "markers", "layout_a/layout_b", "; ".join(problems))


SAMPLING_PATTERNS = ("tabulated_sobol", "blue_noise")
POST_FILTERS = ("off", "median3", "median5", "gauss05", "gauss07", "gauss10")


def _validate_render(cfg: Config, source: str) -> None:
    rc = cfg.render
    _check_positive(source, "render", "samples", rc.samples)
    _check_at_most(source, "render", "samples", rc.samples, MAX_SAMPLES, "Cycles' limit")
    if rc.denoise not in ("off", "fast", "balanced", "high"):
        raise _err(source, "render", "denoise", f"{rc.denoise!r} is not one of off, fast, balanced, high")
    _check_positive(source, "render", "max_bounces", rc.max_bounces, allow_zero=True)
    _check_at_most(source, "render", "max_bounces", rc.max_bounces, MAX_BOUNCES, "Blender's limit")
    _check_positive(source, "render", "adaptive_threshold", rc.adaptive_threshold, allow_zero=True)
    _check_positive(source, "render", "adaptive_min_samples", rc.adaptive_min_samples, allow_zero=True)
    _check_at_most(source, "render", "adaptive_min_samples", rc.adaptive_min_samples, MAX_SAMPLES,
                   "Cycles' limit")
    if rc.denoise_prefilter not in ("none", "fast", "accurate"):
        raise _err(source, "render", "denoise_prefilter", f"{rc.denoise_prefilter!r} is not one of none, fast, accurate")
    if rc.sampling_pattern not in SAMPLING_PATTERNS:
        raise _err(source, "render", "sampling_pattern",
                   f"{rc.sampling_pattern!r} is not one of {', '.join(SAMPLING_PATTERNS)}")
    if rc.post_filter not in POST_FILTERS:
        raise _err(source, "render", "post_filter", f"{rc.post_filter!r} is not one of {', '.join(POST_FILTERS)}")
    _check_positive(source, "render", "marker_samples", rc.marker_samples, allow_zero=True)
    _check_at_most(source, "render", "marker_samples", rc.marker_samples, MAX_SAMPLES, "Cycles' limit")
    _check_positive(source, "render", "marker_adaptive_threshold", rc.marker_adaptive_threshold, allow_zero=True)
    _check_positive(source, "render", "marker_adaptive_min_samples", rc.marker_adaptive_min_samples, allow_zero=True)
    _check_at_most(source, "render", "marker_adaptive_min_samples", rc.marker_adaptive_min_samples, MAX_SAMPLES,
                   "Cycles' limit")
    _check_marker_coverage(source, rc)
    if rc.light_tree not in LIGHT_TREE_CHOICES:
        raise _err(source, "render", "light_tree", f"{rc.light_tree!r} is not one of {', '.join(LIGHT_TREE_CHOICES)}")
    if rc.marker_denoise not in ("off", "fast", "balanced", "high"):
        raise _err(source, "render", "marker_denoise", f"{rc.marker_denoise!r} is not one of off, fast, balanced, high")
    if not 0.01 <= rc.filter_width_px <= 10:
        raise _err(source, "render", "filter_width_px", f"must be in [0.01, 10], got {rc.filter_width_px}")
    _check_positive(source, "render", "frame_timeout_s", rc.frame_timeout_s)
    if rc.device not in RENDER_DEVICES:
        raise _err(source, "render", "device", f"{rc.device!r} is not one of {', '.join(RENDER_DEVICES)}")


def _validate_sensor(cfg: Config, source: str) -> None:
    se = cfg.sensor
    _check_range(source, "sensor", "full_well_e", se.full_well_e, lo=1.0)
    _check_range(source, "sensor", "read_noise_e", se.read_noise_e, lo=0.0)
    if not 8 <= se.adc_bits <= 16:
        raise _err(source, "sensor", "adc_bits", f"must be in [8, 16], got {se.adc_bits}")
    _check_range(source, "sensor", "exposure_ev", se.exposure_ev, lo=-10, hi=10)
    _check_range(source, "sensor", "low_light_ev", se.low_light_ev, lo=-12, hi=0)
    _check_range(source, "sensor", "low_light_gain_ev", se.low_light_gain_ev, lo=0, hi=12)
    _check_range(source, "sensor", "vignetting", se.vignetting, lo=0, hi=0.9)
    _validate_colour_sensor(cfg, source)


def _check_choices(source, table: str, key: str, values: tuple[str, ...], known: tuple[str, ...]) -> None:
    if not values:
        raise _err(source, table, key, "is empty")
    for v in values:
        if v not in known:
            raise _err(source, table, key, f"{v!r} is not one of {', '.join(known)}")


def _validate_colour_sensor(cfg: Config, source: str) -> None:
    """[sensor]: presets, overrides and the ISP of a colour camera (core.camera_chain)."""
    se, t = cfg.sensor, "sensor"
    _check_choices(source, t, "cfa", se.cfa, CFA_CHOICES)
    _check_choices(source, t, "demosaic", se.demosaic, DEMOSAICS)
    _check_range(source, t, "crosstalk", se.crosstalk, lo=0.0, hi=0.3)
    _check_range(source, t, "exposure_time_ms", se.exposure_time_ms, lo=0.0, hi=1e5)
    _check_range(source, t, "wb_error", se.wb_error, lo=-0.5, hi=0.5)
    _check_range(source, t, "sharpen", se.sharpen, lo=0.0, hi=5.0)
    if not 0.1 <= se.sharpen_sigma_px <= 10:
        raise _err(source, t, "sharpen_sigma_px", f"must be in [0.1, 10], got {se.sharpen_sigma_px}")
    if se.tone not in TONE_CURVES:
        raise _err(source, t, "tone", f"{se.tone!r} is not one of {', '.join(TONE_CURVES)}")
    if se.denoise not in DENOISERS:
        raise _err(source, t, "denoise", f"{se.denoise!r} is not one of {', '.join(DENOISERS)}")
    if not se.presets:
        for key in ("overrides", "raw_output"):
            if getattr(se, key):
                raise _err(source, t, key, "needs a sensor preset (presets = [...])")
        if any(c != "none" for c in se.cfa):
            raise _err(source, t, "cfa", "a colour filter array needs a sensor preset (presets = [...])")
    for name in se.presets:
        try:
            configured_sensor(name, se.overrides, se.adc_bits)
        except ValueError as exc:
            raise _err(source, t, "presets" if name not in PRESETS else "overrides", str(exc)) from None


def _validate_motion(cfg: Config, source: str) -> None:
    """[motion]: speeds within MAX_SPEED_MM_S, a readout within MAX_READOUT_MS, nothing set while it
    is off, and something that moves during the exposure while it is on."""
    mo, t = cfg.motion, "motion"
    speeds = ("velocity_mm_s", "velocity_y_mm_s", "velocity_z_mm_s")
    for key in speeds:
        _check_symmetric(source, t, key, getattr(mo, key), MAX_SPEED_MM_S, "MAX_SPEED_MM_S")
    if not 0.0 <= mo.rolling_shutter_ms <= MAX_READOUT_MS:
        raise _err(source, t, "rolling_shutter_ms", f"must be in [0, {MAX_READOUT_MS:g}] (MAX_READOUT_MS), "
                   f"got {mo.rolling_shutter_ms}")
    if not mo.enabled:
        for key in speeds + ("rolling_shutter_ms",):
            if getattr(mo, key) != getattr(MotionConfig, key):
                raise _err(source, t, key, "is set but [motion] enabled is false")
        return
    if all(getattr(mo, key) == (0.0, 0.0) for key in speeds):
        raise _err(source, t, "enabled", "B never moves: every velocity range is [0, 0]")
    if cfg.sensor.exposure_time_ms[1] == 0 and mo.rolling_shutter_ms == 0:
        raise _err(source, t, "enabled", "nothing moves during the exposure: [sensor] exposure_time_ms is "
                   "[0, 0] and rolling_shutter_ms is 0")


def _check_kinds(source, table: str, kinds: tuple[str, ...], known: tuple[str, ...], what: str) -> None:
    for k in kinds:
        if k not in known:
            raise _err(source, table, "kinds", f"unknown {what} kind {k!r}")
    if not kinds:
        raise _err(source, table, "kinds", "is empty")


def _validate_occlusion_glare(cfg: Config, source: str) -> None:
    o = cfg.occlusion
    _check_range(source, "occlusion", "occluders", o.occluders, lo=1, hi=8)
    _check_range(source, "occlusion", "gap_mm", o.gap_mm, lo=5)
    _check_kinds(source, "occlusion", o.kinds, ("cable", "bar", "tool", "blob"), "occluder")
    _check_kinds(source, "glare", cfg.glare.kinds, ("lamp_in_view", "specular"), "glare")
    _check_range(source, "glare", "bloom", cfg.glare.bloom, lo=0, hi=1)


def _validate_labels(cfg: Config, source: str) -> None:
    if not 0 <= cfg.labels.min_chroma < 1:
        raise _err(source, "labels", "min_chroma", f"must be in [0, 1), got {cfg.labels.min_chroma}")
    if not 0 < cfg.labels.visible_threshold <= 1:
        raise _err(source, "labels", "visible_threshold",
                   f"must be in (0, 1], got {cfg.labels.visible_threshold}")
