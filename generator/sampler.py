"""Deterministic scene sampling: frame i of a dataset is a function of (config, seed, i) alone.

Every random choice comes from a ``numpy.random.Generator`` seeded with
``SeedSequence([seed, stream, ...])``: the plan (conditions, splits), a frame's geometry and a
frame's look (light, noise, occluders) each draw from their own stream, so a frame is the same
whatever the shard, worker count or render order, and the captures of a repeatability pose share
their geometry while their lighting and noise differ.

This module holds the frame plan and the per-frame sampling: its entry points ``frame_plan``, ``sample_frame``
and the checks (``check_focal_fits``, ``check_rolling_fits``) alone read the whole ``Config``. The streams and
the draws it shares are in ``generator.random_draws``, the camera units' lenses in ``generator.camera_units``
and the docking runs in ``generator.docking_runs``.

Why and how: docs/datasets.md, "Sampling a frame".
"""
from __future__ import annotations

import colorsys
import dataclasses

import numpy as np

from dockfactory.core.camera_chain import ColourChain
from dockfactory.core.config import (
    CONDITIONS,
    CameraConfig,
    ConditionsConfig,
    Config,
    ConfigError,
    DatasetConfig,
    OcclusionConfig,
    PoseConfig,
    RenderConfig,
    SensorConfig,
)
from dockfactory.core.geometry import make_transform, rot_x, rot_y
from dockfactory.core.layout import marker_points, ring_reflectance
from dockfactory.core.scene import (
    CLUTTER_KINDS,
    CLUTTER_SLOTS,
    Appearance,
    CameraModel,
    FrameScene,
    FrameSpec,
    Light,
    Prop,
    RenderSettings,
    SensorParams,
    StaticScene,
    floor_y_mm,
    mat4,
    vec,
)
from dockfactory.generator.camera_units import (
    ImageFit,
    UnitLens,
    balanced_units,
    camera_model,
    check_lenses,
    largest_fitting_focal,
    repeat_unit,
    unit_lens,
    unit_sensor,
)
from dockfactory.generator.random_draws import (
    STREAM_FRAME_ISP,
    STREAM_GEOMETRY,
    STREAM_LOOK,
    STREAM_PLAN,
    STREAM_REPEAT_GEOMETRY,
    STREAM_REPEAT_LOOK,
    STREAM_RUN_LOOK,
    STREAM_RUN_PLAN,
    aim_camera,
    markers_in_d,
    rng_for,
    sample_pose,
    static_scene,
    uniform,
)
from dockfactory.generator.silhouette import section_silhouette
from dockfactory.generator.motion import check_rolling, frame_motion
from dockfactory.generator.docking_runs import check_runs_fit, run_count, run_pose, run_time, unit_camera

LIGHT_LEVEL_W = 400.0  # area-light power (W) that gives the reference light level at 1 m


# ----------------------------------------------------------------------------- plan

def condition_counts(weights: dict[str, float], total: int) -> dict[str, int]:
    """Exact counts per condition from weights (largest remainder, ties in CONDITIONS order)."""
    wsum = sum(weights.values())
    if total == 0 or wsum <= 0:
        return {k: 0 for k in weights}
    quotas = {k: total * w / wsum for k, w in weights.items()}
    counts = {k: int(np.floor(q)) for k, q in quotas.items()}
    rest = total - sum(counts.values())
    order = sorted(weights, key=lambda k: (-(quotas[k] - counts[k]), CONDITIONS.index(k)))
    for k in order[:rest]:
        counts[k] += 1
    return counts


def _split_members(dataset: DatasetConfig, members: np.ndarray, ci: int,
                   stream: int = STREAM_PLAN) -> dict[str, np.ndarray]:
    """Item indices (frames, or runs) of group ``ci`` per split: test, then val carved from train
    ([dataset] train_fraction, val_fraction; the permutation from ``stream``, key 1 + ci, of its seed).

    One permutation of the condition's items decides everything: its first
    round(train_fraction * n) items are train + val, the rest test (so ``val_fraction`` never
    moves an item into or out of the test split); the first round(val_fraction * n_train) of
    the train items are val.
    """
    n_train = int(np.floor(dataset.train_fraction * len(members) + 0.5))
    n_val = int(np.floor(dataset.val_fraction * n_train + 0.5))
    order = rng_for(dataset.seed, stream, 1 + ci).permutation(len(members))
    return {"val": members[order[:n_val]], "train": members[order[n_val:n_train]],
            "test": members[order[n_train:]]}


def _condition_groups(conditions: ConditionsConfig, seed: int, n: int, stream: int) -> list[np.ndarray]:
    """Members (sorted item indices) of each condition, in CONDITIONS order: exact counts from the
    [conditions] weights, dealt by one permutation of ``stream`` of the dataset ``seed``."""
    counts = condition_counts(dataclasses.asdict(conditions), n)
    perm = rng_for(seed, stream).permutation(n)
    starts = np.cumsum([0] + [counts[c] for c in CONDITIONS])
    return [np.sort(perm[starts[i]:starts[i + 1]]) for i in range(len(CONDITIONS))]


def _stratified_splits(dataset: DatasetConfig, groups: list[np.ndarray], n: int, stream: int) -> np.ndarray:
    """Split ("train", "val" or "test") of each of ``n`` items, (n,) object: drawn within each
    group (stratum) separately (``_split_members``)."""
    split_of = np.empty(n, dtype=object)
    for gi, members in enumerate(groups):
        for split, idx in _split_members(dataset, members, gi, stream).items():
            split_of[idx] = split
    return split_of


def _main_specs(cfg: Config) -> list[FrameSpec]:
    """Main frames. Without runs every frame draws its condition, split (stratified by condition)
    and unit. With runs every run does (frames i * per .. (i + 1) * per - 1 form run i; splits
    stratified by camera unit, so each unit has runs in train and test) and its frames share them."""
    seed, n, units = cfg.dataset.seed, cfg.dataset.frames, cfg.camera_units.count
    per = cfg.runs.frames_per_run
    items = n if per == 0 else run_count(cfg.runs, n)
    stream = STREAM_PLAN if per == 0 else STREAM_RUN_PLAN
    groups = _condition_groups(cfg.conditions, seed, items, stream)
    condition = np.empty(items, dtype=object)
    for cond, members in zip(CONDITIONS, groups):
        condition[members] = cond
    unit = balanced_units(seed, items, units, 0 if per == 0 else 1)
    if per == 0:
        split = _stratified_splits(cfg.dataset, groups, items, stream)
        return [FrameSpec(f"{i:06d}", i, "main", str(split[i]), str(condition[i]), -1, -1, int(unit[i]))
                for i in range(n)]
    split = _stratified_splits(cfg.dataset, [np.flatnonzero(unit == u) for u in range(units)], items, stream)
    return [FrameSpec(f"{i:06d}", i, "main", str(split[i // per]), str(condition[i // per]), -1, -1,
                      int(unit[i // per]), i // per, i % per) for i in range(n)]


def frame_plan(cfg: Config) -> tuple[FrameSpec, ...]:
    """Every frame of the dataset: main frames (train/val/test, stratified by condition) then the
    repeatability subset (all on one camera unit)."""
    specs = _main_specs(cfg)
    n, r, unit = cfg.dataset.frames, cfg.repeatability, repeat_unit(cfg.dataset.seed, cfg.camera_units.count)
    for p in range(r.poses):
        for c in range(r.captures):
            specs.append(FrameSpec(f"rep{p:03d}_{c:02d}", n + p * r.captures + c, "repeat",
                                   "repeat", r.condition, p, c, unit))
    return tuple(specs)


def _streams(seed: int, spec: FrameSpec) -> tuple[np.random.Generator, np.random.Generator]:
    """The (geometry, look) streams of a planned frame of the dataset ``seed``: a repeatability
    capture shares its pose's geometry stream and has its own look stream."""
    if spec.kind == "repeat":
        return (rng_for(seed, STREAM_REPEAT_GEOMETRY, spec.pose_index),
                rng_for(seed, STREAM_REPEAT_LOOK, spec.pose_index, spec.capture))
    return rng_for(seed, STREAM_GEOMETRY, spec.index), rng_for(seed, STREAM_LOOK, spec.index)


# ----------------------------------------------------------------------------- geometry

def sample_geometry(pose: PoseConfig, camera: CameraConfig, static: StaticScene, fit: ImageFit,
                    rng: np.random.Generator, lens: UnitLens | None = None):
    """One frame's geometry, drawn from ``rng`` in a fixed order: B's pose ([pose]), the camera's
    aim ([camera], at B's axial gap), then the zoom's uniform variate u_focal in [0, 1).

    Returns (d_from_b (4, 4), cam_from_d (4, 4), f_cap px: the largest focal that keeps the
    markers inside the image through ``lens`` (``fit``), u_focal, eye (3,) mm, target (3,) mm; D
    frame)."""
    d_from_b = sample_pose(pose, rng)
    cam_from_d, eye, target = aim_camera(camera, static.radius_mm, rng, d_from_b[0, 3])
    f_cap = largest_fitting_focal(fit, cam_from_d, markers_in_d(static, d_from_b), lens)
    u_focal = float(rng.uniform())
    return d_from_b, cam_from_d, f_cap, u_focal, eye, target


# ----------------------------------------------------------------------------- feasibility

def check_focal_fits(cfg: Config, source: str = "<config>") -> None:
    """Raise ConfigError if some planned frame cannot fit its markers at the smallest focal (with
    runs: at its unit's focal), a unit's lens is unusable, or (with a rolling shutter) some
    frame's B moves too fast for it (``generator.motion.check_rolling``)."""
    check_lenses(cfg.camera_units, cfg.image, cfg.dataset.seed, cfg.camera.focal_px[0], source)
    if cfg.runs.frames_per_run > 0:
        check_runs_fit(cfg, frame_plan(cfg), source)
    else:
        _check_single_shot_focal(cfg, source)
    check_rolling_fits(cfg, source)


def _check_single_shot_focal(cfg: Config, source: str) -> None:
    """Without runs: every frame fits its markers at the smallest focal of [camera] focal_px."""
    static, fit, seed = static_scene(cfg), ImageFit.of(cfg), cfg.dataset.seed
    worst = np.inf
    for spec in frame_plan(cfg):
        geo_rng, _ = _streams(seed, spec)
        lens = unit_lens(cfg.camera_units, seed, spec.unit)
        worst = min(worst, sample_geometry(cfg.pose, cfg.camera, static, fit, geo_rng, lens)[2])
    f_min = cfg.camera.focal_px[0]
    if worst < f_min:
        raise ConfigError(
            f"{source}: [camera] focal_px: min {f_min:g} px cannot fit all markers "
            f"{cfg.camera.margin_px:g} px inside a {cfg.image.width}x{cfg.image.height} image "
            f"for every frame (largest focal that fits the worst frame: {worst:.0f} px); lower "
            f"focal_px, raise distance_mm or reduce margin_px")


def check_rolling_fits(cfg: Config, source: str = "<config>") -> None:
    """With [motion] and a rolling shutter, sample every frame (sample_frame checks the rolling
    shutter) and raise its ConfigError naming ``source``; nothing to do otherwise."""
    if not (cfg.motion.enabled and cfg.motion.rolling_shutter_ms > 0):
        return
    for spec in frame_plan(cfg):
        try:
            sample_frame(cfg, spec)
        except ConfigError as exc:
            raise ConfigError(f"{source}: {exc}") from None


# ----------------------------------------------------------------------------- look

def _kelvin_tint(rng) -> tuple[float, float, float]:
    """A light colour between warm (3200 K-ish) and cool (6500 K-ish), unit luminance."""
    t = rng.uniform()
    warm, cool = np.array([1.0, 0.78, 0.56]), np.array([0.92, 0.97, 1.08])
    c = warm * (1 - t) + cool * t
    return vec(c / (0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]))


def _hsv_linear(h, s, v) -> tuple[float, float, float]:
    srgb = np.array(colorsys.hsv_to_rgb(h % 1.0, s, v))
    lin = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
    return vec(lin)


PAINTS = ((0.55, 0.55, 0.55), (0.30, 0.31, 0.32), (0.70, 0.68, 0.62), (0.42, 0.50, 0.40),
          (0.68, 0.56, 0.20), (0.38, 0.45, 0.55), (0.14, 0.15, 0.16), (0.60, 0.62, 0.66))
PROP_COLORS = ((0.03, 0.03, 0.03), (0.12, 0.12, 0.12), (0.60, 0.25, 0.02), (0.65, 0.50, 0.03),
               (0.05, 0.18, 0.06), (0.40, 0.40, 0.38), (0.50, 0.03, 0.02), (0.02, 0.06, 0.40))


def _jitter_color(rng, base, amount=0.12):
    return vec(np.clip(np.array(base) * rng.uniform(1 - amount, 1 + amount, size=3), 0, 1))


def _area_light(name, rng, target, azimuth_deg, elevation_deg, dist_mm, size_mm, rel_power):
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    direction = np.array([np.sin(az) * np.cos(el), np.sin(el), np.cos(az) * np.cos(el)])
    pos = target + dist_mm * direction
    # Blender lights shine down their local -Z: build d_from_light with +Z pointing away from target
    z = direction
    x = np.cross([0.0, 1.0, 0.0], z)
    x = x / np.linalg.norm(x) if np.linalg.norm(x) > 1e-9 else np.array([1.0, 0.0, 0.0])
    y = np.cross(z, x)
    d_from_light = make_transform(np.stack([x, y, z], axis=1), pos)
    # irradiance ~ P / d^2: scale power with distance so rel_power sets the light level
    power = rel_power * (dist_mm / 1000.0) ** 2 * LIGHT_LEVEL_W
    return Light(name, "AREA", mat4(d_from_light), float(power), float(size_mm), _kelvin_tint(rng))


def sample_lights(rng, target, condition: str) -> tuple[Light, ...]:
    if condition == "ideal":
        key = _area_light("key", rng, target, 0.0, 25.0, 2500.0, 1800.0, 1.0)
        fill = _area_light("fill", rng, target, 180.0 - 0.0, 60.0, 2500.0, 1800.0, 0.0)
        white = (1.0, 1.0, 1.0)
        return (dataclasses.replace(key, color=white), dataclasses.replace(fill, color=white))
    key = _area_light("key", rng, target, rng.uniform(-70, 70), rng.uniform(15, 65),
                      rng.uniform(1500, 3500), rng.uniform(300, 1500), rng.uniform(0.6, 1.6))
    fill = _area_light("fill", rng, target, rng.uniform(-80, 80), rng.uniform(-10, 40),
                       rng.uniform(1500, 3500), rng.uniform(500, 2000), rng.uniform(0.05, 0.4))
    return key, fill


def sample_appearance(rng, condition: str, ring: str = "dark") -> Appearance:
    """The frame's materials and world light; ``ring`` the marker ring's design
    (``core.layout.ring_reflectance``: one draw whatever the design, so the rest of the stream is the same)."""
    ideal = condition == "ideal"
    return Appearance(
        section_color_a=_jitter_color(rng, PAINTS[rng.integers(len(PAINTS))]),
        section_color_b=_jitter_color(rng, PAINTS[rng.integers(len(PAINTS))]),
        metallic=float(rng.uniform(0.1, 0.6)),
        roughness=float(rng.uniform(0.25, 0.55)),
        roughness_variation=0.0 if ideal else float(rng.uniform(0.05, 0.25)),
        grime=0.0 if ideal else float(rng.uniform(0.0, 0.2)),
        texture_scale=float(rng.uniform(2.0, 12.0)),
        texture_offset=vec(rng.uniform(-100, 100, size=3)),
        marker_red=_hsv_linear(rng.uniform(-0.02, 0.02), rng.uniform(0.75, 0.95), rng.uniform(0.55, 0.85)),
        marker_blue=_hsv_linear(rng.uniform(0.58, 0.66), rng.uniform(0.75, 0.95), rng.uniform(0.55, 0.85)),
        ring_color=vec([ring_reflectance(ring, rng.uniform())] * 3),
        floor_color=_jitter_color(rng, (0.25, 0.24, 0.22), 0.4),
        wall_color=_jitter_color(rng, PAINTS[rng.integers(len(PAINTS))], 0.3),
        world_color=_jitter_color(rng, (0.9, 0.92, 1.0), 0.08),
        world_strength=float(rng.uniform(0.03, 0.25)),
    )


def sample_clutter(rng, radius_mm: float) -> tuple[Prop, ...]:
    """Background boxes and drums on the floor behind and beside the sections."""
    props = []
    floor = floor_y_mm(radius_mm)
    for slot in range(CLUTTER_SLOTS):
        kind = CLUTTER_KINDS[slot % len(CLUTTER_KINDS)]
        size = rng.uniform([150, 150, 150], [900, 1200, 900])
        if kind == "drum":
            size[2] = size[0]
        pos = np.array([rng.uniform(-2500, 2500), floor + size[1] / 2, rng.uniform(-3500, -radius_mm - 400)])
        if rng.uniform() < 0.25:  # some stand beside the sections, nearer the camera
            pos[0] = rng.choice([-1, 1]) * rng.uniform(1400, 2500)
            pos[2] = rng.uniform(-radius_mm, 600)
        rot = make_transform(rot_y(rng.uniform(0, 2 * np.pi)) @ rot_x(-np.pi / 2 if kind == "drum" else 0.0), pos)
        color = PROP_COLORS[rng.integers(len(PROP_COLORS))]
        props.append(Prop(kind, slot // len(CLUTTER_KINDS), mat4(rot), vec(size), _jitter_color(rng, color)))
    return tuple(props)


def sample_occluders(occlusion: OcclusionConfig, marker_diameter_mm: float, rng, static: StaticScene, points_d,
                     eye) -> tuple[Prop, ...]:
    """An occlusion frame's occluders ([occlusion]: count, kinds, gap), each across the line of
    sight from ``eye`` ((3,) mm in D) to a marker drawn from ``points_d`` ((N, 3) mm in D, the
    markers of ``static`` in layout order), near enough to cover a disc of ``marker_diameter_mm``."""
    n = int(rng.integers(occlusion.occluders[0], occlusion.occluders[1] + 1))
    slots: dict[str, int] = {}
    props = []
    for _ in range(n):
        kind = str(occlusion.kinds[rng.integers(len(occlusion.kinds))])
        slot = slots.get(kind, 0)
        slots[kind] = slot + 1
        mi = int(rng.integers(len(static.markers)))
        marker = points_d[mi]
        ray = eye - marker
        ray /= np.linalg.norm(ray)
        # orthonormal basis: w along the ray, u/v across it
        u = np.cross([0.0, 1.0, 0.0], ray)
        u /= np.linalg.norm(u)
        v = np.cross(ray, u)
        theta = rng.uniform(0, np.pi)
        axis = np.cos(theta) * u + np.sin(theta) * v     # long axis, across the line of sight
        across = np.cross(ray, axis)
        if kind == "cable":
            d = rng.uniform(8, 24)
            size = np.array([rng.uniform(600, 1500), d, d])
        elif kind == "bar":
            size = np.array([rng.uniform(300, 900), rng.uniform(15, 45), rng.uniform(15, 45)])
        elif kind == "tool":
            size = np.array([rng.uniform(160, 300), rng.uniform(30, 60), rng.uniform(15, 30)])
        else:  # hand-sized blob
            size = np.array([rng.uniform(80, 120), rng.uniform(60, 95), rng.uniform(30, 55)])
        half_width = size[1] / 2 + marker_diameter_mm / 2
        gap = uniform(rng, occlusion.gap_mm)
        shift_along = rng.uniform(-0.4, 0.4) * size[0] if kind in ("tool", "blob") else 0.0
        centre = marker + gap * ray + rng.uniform(-1.2, 1.2) * half_width * across + shift_along * axis
        rotation = np.stack([axis, across, np.cross(axis, across)], axis=1)
        color = PROP_COLORS[rng.integers(len(PROP_COLORS))]
        props.append(Prop(kind, slot, mat4(make_transform(rotation, centre)), vec(size),
                          _jitter_color(rng, color), 0.0, static.markers[mi].id))
    return tuple(props)


def sample_glare(rng, kind: str, static: StaticScene, cam: CameraModel, eye):
    """A glare frame's source of ``kind``: a lamp in ``cam``'s view, or a specular light mirrored
    off A's surface toward ``eye`` ((3,) mm in D). Returns (props, lights, roughness override or None)."""
    if kind == "lamp_in_view":
        w, h = cam.width, cam.height
        if rng.uniform() < 0.6:  # above the sections
            px = np.array([rng.uniform(0.05, 0.95) * w, rng.uniform(0.02, 0.2) * h])
        else:  # beside them
            px = np.array([rng.choice([rng.uniform(0.02, 0.12), rng.uniform(0.88, 0.98)]) * w,
                           rng.uniform(0.1, 0.9) * h])
        k = cam.k()
        ray_cam = np.linalg.solve(k, np.array([px[0], px[1], 1.0]))
        d_from_cam = np.linalg.inv(cam.cam_from_d_array())
        depth = rng.uniform(2500, 5000)
        pos = d_from_cam[:3, :3] @ (ray_cam * depth) + d_from_cam[:3, 3]
        radius = rng.uniform(25, 70)
        lamp = Prop("lamp", 0, mat4(make_transform(np.eye(3), pos)), vec([2 * radius] * 3),
                    (1.0, 0.95, 0.85), float(rng.uniform(200, 2000)))
        return (lamp,), (), None
    # specular: a strong small light at the mirror direction of a point on the cylinder
    r = static.radius_mm
    phi = np.radians(rng.uniform(-30, 30))
    p = np.array([rng.uniform(-180, 180), r * np.sin(phi), r * np.cos(phi)])
    n = np.array([0.0, np.sin(phi), np.cos(phi)])
    view = (eye - p) / np.linalg.norm(eye - p)
    mirror = 2 * np.dot(n, view) * n - view
    dist = rng.uniform(900, 2200)
    pos = p + dist * mirror
    z = mirror
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    # 1.5 to 4 times the key light's level: on the glossy paint a small source saturates in a
    # highlight without flooding the whole scene with diffuse light
    light = Light("glare", "AREA", mat4(make_transform(np.stack([x, np.cross(z, x), z], axis=1), pos)),
                  float(rng.uniform(1.5, 4.0) * LIGHT_LEVEL_W * (dist / 1000) ** 2), float(rng.uniform(40, 150)),
                  (1.0, 0.97, 0.92))
    return (), (light,), float(rng.uniform(0.08, 0.2))


def frame_chain(sensor: SensorConfig, seed: int, spec: FrameSpec) -> ColourChain | None:
    """The colour camera of a frame: its unit's sensor and ISP ([sensor]), and the frame's own
    draws from its STREAM_FRAME_ISP stream of the dataset ``seed`` (exposure time, white-balance
    error of the red and blue gains, in that order); None without [sensor] presets."""
    unit = unit_sensor(sensor, seed, spec.unit)
    if unit is None:
        return None
    rng = rng_for(seed, STREAM_FRAME_ISP, spec.index)
    exposure_s = uniform(rng, sensor.exposure_time_ms) / 1000.0
    wb = (uniform(rng, sensor.wb_error), uniform(rng, sensor.wb_error))
    return ColourChain(unit.cfa, unit.sensor, unit.seed, unit.crosstalk, exposure_s, unit.demosaic, wb,
                       sensor.colour_correction, sensor.tone, sensor.denoise, unit.sharpen, sensor.sharpen_sigma_px)


def sample_sensor(sensor: SensorConfig, rng, condition: str, bloom: float,
                  chain: ColourChain | None = None) -> SensorParams:
    """The frame's sensor parameters from [sensor] (the look stream's draws, in a fixed order
    whether or not a colour ``chain`` replaces the three-chip noise model)."""
    seed = int(rng.integers(2**62))
    if condition == "ideal":
        return SensorParams(True, 0.0, 0.0, 1.0, 0.0, sensor.adc_bits, 0.0, 0.0, seed)
    if condition == "low_light":
        ev, gain = uniform(rng, sensor.low_light_ev), uniform(rng, sensor.low_light_gain_ev)
    else:
        ev, gain = uniform(rng, sensor.exposure_ev), 0.0
    return SensorParams(False, ev, gain, uniform(rng, sensor.full_well_e), uniform(rng, sensor.read_noise_e),
                        sensor.adc_bits, uniform(rng, sensor.vignetting), bloom, seed, chain)


# ----------------------------------------------------------------------------- frame

def render_settings(render: RenderConfig) -> RenderSettings:
    """What Cycles needs of [render], per frame."""
    return RenderSettings(render.samples, render.denoise, render.max_bounces, render.adaptive_threshold,
                          render.adaptive_min_samples, render.filter_width_px, render.denoise_prefilter,
                          render.sampling_pattern, render.post_filter, marker_samples=render.marker_samples,
                          marker_denoise=render.marker_denoise,
                          marker_adaptive_threshold=render.rendered_adaptive_threshold(),
                          marker_adaptive_min_samples=render.rendered_adaptive_min_samples(),
                          light_tree=render.rendered_light_tree(),
                          marker_coverage_samples=render.rendered_coverage_samples(),
                          marker_coverage_threshold=render.rendered_coverage_threshold(),
                          marker_light_smoothing_px=render.rendered_light_smoothing(),
                          marker_coverage_source=render.rendered_coverage_source())


def _single_geometry(cfg: Config, spec: FrameSpec, static: StaticScene, lens: UnitLens):
    """Without runs: the frame's own pose and camera (geometry stream; the zoom within [camera]
    focal_px, capped so the markers fit through the unit's ``lens``); (d_from_b, camera, eye,
    target, geometry stream, look stream), the streams where the geometry left them."""
    geo_rng, look_rng = _streams(cfg.dataset.seed, spec)
    d_from_b, cam_from_d, f_cap, u_focal, eye, target = sample_geometry(cfg.pose, cfg.camera, static,
                                                                        ImageFit.of(cfg), geo_rng, lens)
    f_lo, f_hi = cfg.camera.focal_px[0], min(cfg.camera.focal_px[1], f_cap)
    if f_hi < f_lo:
        raise ConfigError(f"[camera] focal_px: frame {spec.frame_id} cannot fit its markers at "
                          f"{f_lo:g} px (largest that fits: {f_cap:.0f} px)")
    camera = camera_model(cfg.image, cfg.camera_units, lens, f_lo + u_focal * (f_hi - f_lo), cam_from_d, eye, target)
    return d_from_b, camera, eye, target, geo_rng, look_rng


def _single_shot(cfg: Config, spec: FrameSpec, static: StaticScene, lens: UnitLens):
    """Without runs: the frame's geometry (:func:`_single_geometry`), its stage (appearance,
    clutter: geometry stream; lights: look stream) and the look stream for the rest."""
    d_from_b, camera, eye, target, geo_rng, look_rng = _single_geometry(cfg, spec, static, lens)
    appearance = sample_appearance(geo_rng, spec.condition, cfg.markers.ring)
    clutter = sample_clutter(geo_rng, static.radius_mm)
    lights = sample_lights(look_rng, target, spec.condition)
    return d_from_b, camera, eye, (appearance, clutter, lights), look_rng


def _run_geometry(cfg: Config, spec: FrameSpec, static: StaticScene, lens: UnitLens):
    """With runs: the unit's fixed camera and the frame's pose (a main frame's from its run's
    trajectory, a repeatability pose's from the repeat streams); (d_from_b, camera, eye, target,
    stage stream, light stream, look stream)."""
    seed = cfg.dataset.seed
    cam_from_d, focal, eye, target = unit_camera(cfg.camera, cfg.pose, cfg.runs, seed, lens, static, ImageFit.of(cfg))
    camera = camera_model(cfg.image, cfg.camera_units, lens, focal, cam_from_d, eye, target)
    if spec.kind == "repeat":
        stage_rng = rng_for(seed, STREAM_REPEAT_GEOMETRY, spec.pose_index)
        look_rng = rng_for(seed, STREAM_REPEAT_LOOK, spec.pose_index, spec.capture)
        d_from_b = sample_pose(cfg.pose, stage_rng)
        light_rng = look_rng
    else:
        stage_rng = light_rng = rng_for(seed, STREAM_RUN_LOOK, spec.run)
        look_rng = rng_for(seed, STREAM_LOOK, spec.index)
        t = run_time(cfg.runs, cfg.dataset.frames, spec.run, spec.run_frame)
        d_from_b = run_pose(cfg.pose, cfg.runs, seed, spec.run, t)
    return d_from_b, camera, eye, target, stage_rng, light_rng, look_rng


def _run_shot(cfg: Config, spec: FrameSpec, static: StaticScene, lens: UnitLens):
    """With runs: the frame's geometry (:func:`_run_geometry`); its stage (appearance, clutter,
    lights) from the run's stream, so they hold for the whole run (a repeatability pose's from
    the repeat streams)."""
    d_from_b, camera, eye, target, stage_rng, light_rng, look_rng = _run_geometry(cfg, spec, static, lens)
    appearance = sample_appearance(stage_rng, spec.condition, cfg.markers.ring)
    clutter = sample_clutter(stage_rng, static.radius_mm)
    lights = sample_lights(light_rng, target, spec.condition)
    return d_from_b, camera, eye, (appearance, clutter, lights), look_rng


def frame_geometry(cfg: Config, spec: FrameSpec) -> tuple[np.ndarray, CameraModel]:
    """(d_from_b (4, 4), camera) of one planned frame: :func:`sample_frame`'s, without drawing its
    stage, lights, sensor or motion (the design predictor's frames need only where B and the
    camera are; mid-exposure with [motion]). ConfigError as :func:`sample_frame`'s."""
    static = static_scene(cfg)
    lens = unit_lens(cfg.camera_units, cfg.dataset.seed, spec.unit)
    geometry = (_run_geometry if cfg.runs.frames_per_run > 0 else _single_geometry)(cfg, spec, static, lens)
    return geometry[0], geometry[1]


def sample_frame(cfg: Config, spec: FrameSpec) -> FrameScene:
    """The full scene of one planned frame (pure and deterministic): the config is read here and
    its sections handed down to the helpers. With [motion], ``d_from_b`` is B at mid-exposure and
    ``motion`` how it moves (``generator.motion``). Raises ConfigError when the frame's markers
    cannot fit its image or its rolling shutter cannot image B."""
    static, seed = static_scene(cfg), cfg.dataset.seed
    shot = _run_shot if cfg.runs.frames_per_run > 0 else _single_shot
    d_from_b, camera, eye, (appearance, clutter, lights), look_rng = shot(
        cfg, spec, static, unit_lens(cfg.camera_units, seed, spec.unit))
    cond = spec.condition
    props = list(clutter)
    glare_kind = "none"
    bloom = 0.0
    if cond == "occlusion":
        props += sample_occluders(cfg.occlusion, cfg.markers.diameter_mm, look_rng, static,
                                  markers_in_d(static, d_from_b), eye)
    if cond == "glare":
        glare_kind = str(cfg.glare.kinds[look_rng.integers(len(cfg.glare.kinds))])
        glare_props, glare_lights, rough = sample_glare(look_rng, glare_kind, static, camera, eye)
        props += glare_props
        lights = lights + glare_lights
        bloom = uniform(look_rng, cfg.glare.bloom)
        if rough is not None:
            appearance = dataclasses.replace(appearance, roughness=rough,
                                             roughness_variation=min(appearance.roughness_variation, 0.05))
    sensor = sample_sensor(cfg.sensor, look_rng, cond, bloom, frame_chain(cfg.sensor, seed, spec))
    motion = frame_motion(cfg.motion, cfg.sensor.exposure_time_ms, seed, spec.index)
    frame = FrameScene(spec=spec, d_from_b=mat4(d_from_b), camera=camera, lights=tuple(lights),
                       props=tuple(props), appearance=appearance, sensor=sensor,
                       glare_kind=glare_kind, render_seed=int(look_rng.integers(2**31 - 1)),
                       render=render_settings(cfg.render), motion=motion)
    check_rolling(frame, np.vstack([marker_points(static.markers, "B"), section_silhouette(static, "B")]))
    return frame
