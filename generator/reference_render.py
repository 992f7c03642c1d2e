"""The converged reference's render settings: what ``dockfactory render --reference N`` sets.

A reference renders every marker crop pixel at N samples (no adaptive stopping), without the
denoiser, the coverage correction or its light smoothing at the markers: what the refinement reads
there is converged and nothing of the factory's own estimators is in it; the rest of the frame is
the config's own render. It is for measuring (the factory's physical floor per scene,
bench/render/marker_sampling.py), not for training or acceptance runs. Why 1024 by default: at 256
samples the reference's own noise still moved a scene's pose RMSE by a fifth (docs/rendering.md,
"The converged reference").
"""
from __future__ import annotations

from dockfactory.core.errors import DockfactoryError

__all__ = ["REFERENCE_SAMPLES", "MIN_REFERENCE_SAMPLES", "reference_overrides"]

REFERENCE_SAMPLES = 1024      # samples per crop pixel of ``--reference`` without a count
MIN_REFERENCE_SAMPLES = 256   # fewer is no reference (bench.render.marker_sampling refuses it)


def reference_overrides(samples: int, user_sets: list[str]) -> list[str]:
    """The ``--set`` overrides (``TABLE.KEY=VALUE``) of a converged reference at ``samples`` per crop
    pixel, followed by ``user_sets``. DockfactoryError (one line) when ``samples`` is below
    MIN_REFERENCE_SAMPLES or a user override sets one of the reference's keys (which would quietly
    make it no reference)."""
    if samples < MIN_REFERENCE_SAMPLES:
        raise DockfactoryError(f"--reference: expected at least {MIN_REFERENCE_SAMPLES} samples, got {samples}")
    own = {"render.marker_samples": str(samples), "render.marker_adaptive_threshold": "0",
           "render.marker_adaptive_min_samples": "0", "render.marker_denoise": "off",
           "render.marker_coverage_samples": "0", "render.marker_coverage_source": "render",
           "render.marker_coverage_threshold": "0", "render.marker_light_smoothing_px": "0"}
    clash = sorted({s.split("=", 1)[0].strip() for s in user_sets} & own.keys())
    if clash:
        raise DockfactoryError(f"--reference sets {', '.join(clash)} itself: leave {'it' if len(clash) == 1 else 'them'} "
                               "out of --set")
    return [f"{k}={v}" for k, v in own.items()] + list(user_sets)
