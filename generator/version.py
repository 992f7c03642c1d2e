"""Versions that identify a dataset: generator version, Blender version, config hash."""
from __future__ import annotations

import hashlib
from importlib import metadata

GENERATOR_VERSION = "0.1.0"


def package_version(name: str) -> str:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "not installed"


def blender_version() -> str:
    """Version of the bpy package the render workers will import (read without importing bpy)."""
    return package_version("bpy")


def dataset_version_id(canonical_config_json: str, blender: str | None = None) -> str:
    """Hash of (resolved config, generator version, Blender version): 16 hex digits."""
    blender = blender_version() if blender is None else blender
    text = f"{canonical_config_json}\ngenerator={GENERATOR_VERSION}\nblender={blender}"
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]
