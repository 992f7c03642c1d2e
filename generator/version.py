"""Versions that identify a dataset: generator version, Blender version, config hash."""
from __future__ import annotations

import hashlib
import importlib.util
from importlib import metadata
from pathlib import Path

GENERATOR_VERSION = "0.1.0"


def package_version(name: str) -> str:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "not installed"


def blender_version() -> str:
    """Version of the bpy package the render workers will import (read without importing bpy)."""
    return package_version("bpy")


# the modules whose code decides what a rendered dataset contains: every dockfactory module the
# render worker process imports (tests/generator/test_version.py checks the list against a real worker)
OUTPUT_SOURCES = (
    "dockfactory.core.calibration_files",
    "dockfactory.core.camera_chain.order", "dockfactory.core.camera_chain.lens",
    "dockfactory.core.camera_chain.light", "dockfactory.core.camera_chain.plain_sensor",
    "dockfactory.core.camera_chain.colour_sensor", "dockfactory.core.camera_chain.cfa",
    "dockfactory.core.camera_chain.emva", "dockfactory.core.camera_chain.isp",
    "dockfactory.core.camera_chain.demosaic", "dockfactory.core.camera_chain.encoding",
    "dockfactory.core.config", "dockfactory.core.config_calibration", "dockfactory.core.config_files",
    "dockfactory.core.config_parts",
    "dockfactory.core.cv",
    "dockfactory.core.mesh_base", "dockfactory.core.mesh_files",
    "dockfactory.core.mesh_gltf", "dockfactory.core.mesh_markers", "dockfactory.core.mesh_ply",
    "dockfactory.core.distortion", "dockfactory.core.errors", "dockfactory.core.geometry",
    "dockfactory.core.io", "dockfactory.core.layout", "dockfactory.core.names",
    "dockfactory.core.scene", "dockfactory.core.sensor_presets", "dockfactory.core.user_files",
    "dockfactory.generator.camera_units", "dockfactory.generator.random_draws", "dockfactory.generator.exr",
    "dockfactory.generator.frame_output", "dockfactory.generator.labels", "dockfactory.generator.motion",
    "dockfactory.generator.silhouette", "dockfactory.generator.marker_regions",
    "dockfactory.generator.marker_coverage", "dockfactory.generator.coverage_geometry",
    "dockfactory.blender_scenes.coverage",
    "dockfactory.generator.render_worker",
    "dockfactory.generator.docking_runs", "dockfactory.generator.sampler",
    "dockfactory.blender_scenes.crops",
    "dockfactory.blender_scenes.frame_update", "dockfactory.blender_scenes.materials",
    "dockfactory.blender_scenes.meshes", "dockfactory.blender_scenes.render",
    "dockfactory.blender_scenes.scene_builder",
)


def module_source(name: str) -> bytes:
    """The source bytes of an installed dockfactory module (found without importing it)."""
    spec = importlib.util.find_spec(name)
    if spec is None or not spec.origin or not spec.origin.endswith(".py"):
        raise RuntimeError(f"{name}: source not found (a broken install?)")
    return Path(spec.origin).read_bytes()


def generator_source_fingerprint() -> str:
    """Hash of the sources that shape a dataset's content: any change to them is a new version,
    so two datasets with one version id hold the same bytes."""
    h = hashlib.sha256()
    for name in OUTPUT_SOURCES:
        h.update(name.encode())
        h.update(module_source(name))
    return h.hexdigest()[:16]


def generator_version() -> str:
    """``GENERATOR_VERSION+<source fingerprint>``."""
    return f"{GENERATOR_VERSION}+{generator_source_fingerprint()}"


def dataset_version_id(canonical_config_json: str, blender: str | None = None,
                       generator: str | None = None) -> str:
    """Hash of (resolved config, generator version with its source fingerprint, Blender
    version): 16 hex digits."""
    blender = blender_version() if blender is None else blender
    generator = generator_version() if generator is None else generator
    text = f"{canonical_config_json}\ngenerator={generator}\nblender={blender}"
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]
