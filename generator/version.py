"""Versions that identify a dataset: generator version, Blender version, config hash."""
from __future__ import annotations

import hashlib
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


# the modules whose code decides what a rendered dataset contains
OUTPUT_SOURCES = ("generator/config.py", "generator/layout.py", "generator/geometry.py",
                  "generator/scene.py", "generator/sampler.py", "generator/sensor.py",
                  "generator/labels.py", "generator/exr.py", "generator/frame_output.py",
                  "blender_scenes/meshes.py", "blender_scenes/materials.py",
                  "blender_scenes/scene_builder.py", "blender_scenes/frame_update.py")


def generator_source_fingerprint() -> str:
    """Hash of the sources that shape a dataset's content: any change to them is a new version,
    so two datasets with one version id hold the same bytes."""
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for rel in OUTPUT_SOURCES:
        h.update(rel.encode())
        h.update((root / rel).read_bytes())
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
