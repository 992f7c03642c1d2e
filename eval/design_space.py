"""A design space (TOML, data only): the cameras, lenses, distances, markers and image formats a
user could buy or build, the scene they must work in and the tolerance they must pass.

A design is one camera x lens x one value of each [space] list.

Why and how: docs/design.md, "The design space format".
"""
from __future__ import annotations

import itertools
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

from dockfactory.core.errors import DockfactoryError
from dockfactory.core.layout import RING_REFLECTANCE
from dockfactory.core.layout_patterns import MAX_MARKERS, MIN_MARKERS
from dockfactory.core.sensor_presets import PRESETS

CFAS = ("none", "rggb")
MAX_DESIGNS = 20_000

_DESIGN_KEYS = {"scene", "spec", "test_frames", "repeatability_poses", "repeatability_captures",
                "geometry_frames", "seed", "marker_cost"}
_CAMERA_KEYS = {"name", "width", "height", "pixel_um", "cfa", "preset", "cost"}
_LENS_KEYS = {"focal_mm", "cost", "name"}
_SPACE_KEYS = {"distance_mm", "marker_diameter_mm", "ring", "markers_per_section", "image_format"}

__all__ = ["Camera", "Lens", "Design", "DesignSpace", "load_design_space", "designs_of",
           "jpeg_quality"]


@dataclass(frozen=True)
class Camera:
    name: str
    width: int
    height: int
    pixel_um: float
    cfa: str
    preset: str = ""
    cost: float = 0.0


@dataclass(frozen=True)
class Lens:
    focal_mm: float
    cost: float = 0.0
    name: str = ""


@dataclass(frozen=True)
class Design:
    """One choice of everything: ``focal_px`` = focal_mm / pixel pitch."""
    camera: Camera
    lens: Lens
    distance_mm: tuple[float, float]
    marker_diameter_mm: float
    ring: str
    markers_per_section: int
    image_format: str

    @property
    def focal_px(self) -> float:
        return self.lens.focal_mm * 1000.0 / self.camera.pixel_um

    def cost(self, marker_cost: float) -> float:
        return self.camera.cost + self.lens.cost + marker_cost * 2 * self.markers_per_section

    def label(self) -> str:
        lo, hi = self.distance_mm
        return (f"{self.camera.name} | {self.lens.focal_mm:g} mm | {lo:g}-{hi:g} mm | "
                f"{self.marker_diameter_mm:g} mm {self.ring} x{self.markers_per_section} | {self.image_format}")


@dataclass(frozen=True)
class DesignSpace:
    source: str
    scene: Path
    spec: Path | None
    test_frames: int
    repeatability: tuple[int, int]     # (poses, captures); (0, 0): no estimation block
    geometry_frames: int
    seed: int
    marker_cost: float
    cameras: tuple[Camera, ...]
    lenses: tuple[Lens, ...]
    space: dict


def _bad(src: str, where: str, msg: str) -> DockfactoryError:
    return DockfactoryError(f"{src}: {where}: {msg}")


def _number(src, where, value, lo: float, hi: float, integer: bool = False):
    ok = isinstance(value, int) if integer else isinstance(value, (int, float))
    if isinstance(value, bool) or not ok or not math.isfinite(value) or not lo <= value <= hi:
        kind = "an integer" if integer else "a number"
        raise _bad(src, where, f"expected {kind} in [{lo:g}, {hi:g}], got {value!r}")
    return value


def _keys(src, where, table, allowed) -> dict:
    if not isinstance(table, dict):
        raise _bad(src, where, f"expected a table, got {type(table).__name__}")
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise _bad(src, where, f"unknown key {unknown[0]!r} (known: {', '.join(sorted(allowed))})")
    return table


def jpeg_quality(fmt: str) -> int | None:
    """None for "png", Q for "jpegQ" (1 <= Q <= 100); ValueError otherwise."""
    if fmt == "png":
        return None
    if fmt.startswith("jpeg") and fmt[4:].isdigit() and 1 <= int(fmt[4:]) <= 100:
        return int(fmt[4:])
    raise ValueError(f"image format must be 'png' or 'jpegQ' with Q in 1-100, got {fmt!r}")


def _camera(src, i, t) -> Camera:
    w = f"[[camera]] {i + 1}"
    t = _keys(src, w, t, _CAMERA_KEYS)
    for k in ("width", "height", "pixel_um", "cfa"):
        if k not in t:
            raise _bad(src, w, f"missing key {k!r}")
    if t["cfa"] not in CFAS:
        raise _bad(src, f"{w} cfa", f"expected one of {', '.join(CFAS)}, got {t['cfa']!r}")
    if t["cfa"] != "none" and not t.get("preset"):
        raise _bad(src, f"{w} preset", f"a colour ({t['cfa']}) camera needs a sensor preset "
                   f"(known: {', '.join(sorted(PRESETS))})")
    if t.get("preset", "") not in ("", *PRESETS):
        raise _bad(src, f"{w} preset", f"unknown sensor preset {t['preset']!r} (known: {', '.join(sorted(PRESETS))})")
    name = t.get("name", f"camera {i + 1}")
    if not isinstance(name, str) or not name.strip():
        raise _bad(src, f"{w} name", f"expected a non-empty string, got {name!r}")
    return Camera(name, _number(src, f"{w} width", t["width"], 64, 16384, True),
                  _number(src, f"{w} height", t["height"], 64, 16384, True),
                  float(_number(src, f"{w} pixel_um", t["pixel_um"], 0.5, 50.0)), t["cfa"],
                  t.get("preset", ""), float(_number(src, f"{w} cost", t.get("cost", 0.0), 0.0, 1e12)))


def _lens(src, i, t) -> Lens:
    w = f"[[lens]] {i + 1}"
    t = _keys(src, w, t, _LENS_KEYS)
    if "focal_mm" not in t:
        raise _bad(src, w, "missing key 'focal_mm'")
    return Lens(float(_number(src, f"{w} focal_mm", t["focal_mm"], 1.0, 2000.0)),
                float(_number(src, f"{w} cost", t.get("cost", 0.0), 0.0, 1e12)), str(t.get("name", "")))


def _list(src, key, value) -> list:
    if not isinstance(value, list) or not value:
        raise _bad(src, f"[space] {key}", f"expected a non-empty list, got {value!r}")
    if len(set(map(repr, value))) != len(value):
        raise _bad(src, f"[space] {key}", "a value is listed twice")
    return value


def _space_values(src, key, values) -> tuple:
    """The checked values of one [space] list."""
    w = f"[space] {key}"
    if key == "distance_mm":
        out = []
        for v in values:
            if not (isinstance(v, list) and len(v) == 2):
                raise _bad(src, w, f"expected ranges [near, far] in mm, got {v!r}")
            lo, hi = (float(_number(src, w, x, 100.0, 100_000.0)) for x in v)
            if lo > hi:
                raise _bad(src, w, f"near {lo:g} mm is beyond far {hi:g} mm")
            out.append((lo, hi))
        return tuple(out)
    if key == "marker_diameter_mm":
        return tuple(float(_number(src, w, v, 2.0, 200.0)) for v in values)
    if key == "markers_per_section":
        return tuple(_number(src, w, v, MIN_MARKERS, MAX_MARKERS, True) for v in values)
    if key == "ring":
        for v in values:
            if v not in RING_REFLECTANCE:
                raise _bad(src, w, f"expected one of {', '.join(RING_REFLECTANCE)}, got {v!r}")
        return tuple(values)
    for v in values:
        try:
            jpeg_quality(v if isinstance(v, str) else repr(v))
        except ValueError as exc:
            raise _bad(src, w, str(exc)) from None
    return tuple(values)


def _space(src, data: dict) -> dict:
    t = _keys(src, "[space]", data.get("space", {}), _SPACE_KEYS)
    return {k: _space_values(src, k, _list(src, k, v)) for k, v in t.items()}


def _beside(src_path: Path, name, key: str, shipped) -> Path:
    """A file named in the space: beside it, else ``shipped(name)`` (a shipped config)."""
    if not isinstance(name, str) or not name:
        raise DockfactoryError(f"{src_path}: [design] {key}: expected a file name, got {name!r}")
    path = src_path.parent / name
    if path.is_file():
        return path
    try:
        return shipped(name)
    except DockfactoryError:
        raise DockfactoryError(f"{src_path}: [design] {key}: no file {name!r} beside the space "
                               f"and no shipped config of that name") from None


def _design_table(src, path: Path, t: dict, resolve) -> dict:
    t = _keys(src, "[design]", t, _DESIGN_KEYS)
    if "scene" not in t:
        raise _bad(src, "[design]", "missing key 'scene' (a dataset config: the sections and pose ranges)")
    reps = (_number(src, "[design] repeatability_poses", t.get("repeatability_poses", 0), 0, 1000, True),
            _number(src, "[design] repeatability_captures", t.get("repeatability_captures", 0), 0, 1000, True))
    if (reps[0] == 0) != (reps[1] == 0) or reps[1] == 1:
        raise _bad(src, "[design] repeatability_captures", "give poses and captures (at least 2) together")
    return {"scene": _beside(path, t["scene"], "scene", resolve),
            "spec": None if "spec" not in t else _beside(path, t["spec"], "spec", resolve),
            "test_frames": _number(src, "[design] test_frames", t.get("test_frames", 40), 2, 100_000, True),
            "repeatability": reps,
            "geometry_frames": _number(src, "[design] geometry_frames", t.get("geometry_frames", 24), 1, 1000, True),
            "seed": _number(src, "[design] seed", t.get("seed", 0), 0, 2 ** 63 - 1, True),
            "marker_cost": float(_number(src, "[design] marker_cost", t.get("marker_cost", 0.0), 0.0, 1e12))}


def load_design_space(path, resolve) -> DesignSpace:
    """Read and check a design space (module docstring). ``resolve(name)`` finds a shipped config
    by name (DockfactoryError when there is none). DockfactoryError (one line naming the file,
    table and key) on any problem, and when the space holds more than MAX_DESIGNS designs."""
    path = Path(path)
    src = str(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise DockfactoryError(f"{src}: cannot read the design space: {exc.strerror}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise DockfactoryError(f"{src}: not valid TOML: {exc}") from None
    _keys(src, "the design space", data, {"design", "camera", "lens", "space"})
    for key in ("camera", "lens"):
        if not isinstance(data.get(key), list) or not data[key]:
            raise _bad(src, f"[[{key}]]", f"at least one [[{key}]] table is needed")
    cameras = tuple(_camera(src, i, t) for i, t in enumerate(data["camera"]))
    lenses = tuple(_lens(src, i, t) for i, t in enumerate(data["lens"]))
    for what, names in (("camera", [c.name for c in cameras]), ("lens", [ln.focal_mm for ln in lenses])):
        if len(set(names)) != len(names):
            raise _bad(src, f"[[{what}]]", "two tables have the same name" if what == "camera"
                       else "two lenses have the same focal_mm")
    space = DesignSpace(src, cameras=cameras, lenses=lenses, space=_space(src, data),
                        **_design_table(src, path, data.get("design", {}), resolve))
    n = len(cameras) * len(lenses) * math.prod(len(v) for v in space.space.values())
    if n > MAX_DESIGNS:
        raise _bad(src, "[space]", f"{n} designs: at most {MAX_DESIGNS} (split the space)")
    return space


def designs_of(space: DesignSpace, scene_cfg) -> list[Design]:
    """Every design of ``space``; a [space] key left out takes the scene config's value
    (distance, marker diameter and ring) or 7 markers per section and PNG."""
    sv = space.space
    axes = (sv.get("distance_mm", (tuple(scene_cfg.camera.distance_mm),)),
            sv.get("marker_diameter_mm", (scene_cfg.markers.diameter_mm,)),
            sv.get("ring", (scene_cfg.markers.ring if scene_cfg.markers.ring in RING_REFLECTANCE else "dark",)),
            sv.get("markers_per_section", (7,)), sv.get("image_format", ("png",)))
    return [Design(cam, lens, *combo) for cam in space.cameras for lens in space.lenses
            for combo in itertools.product(*axes)]
