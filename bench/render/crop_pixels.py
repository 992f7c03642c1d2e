"""How many pixels label-aware sampling renders again a frame, and how many of them it blends.

    python -m bench.render.crop_pixels CONFIG [CONFIG ...] [--frames 20]
                                       [--variant HALO_RADII:MARGIN_PX ...] [--out crops.json]

For the first ``--frames`` frames of each config (their sampled scenes; nothing is rendered) the
marker regions are planned as the render worker plans them (generator.marker_regions), once with
the module's constants and once per ``--variant`` (the halo's radius in disc radii and the
rectangle's margin around it, px). Printed per config and setting, per frame on average:

    crops    = render calls (regions after merging);
    pixels   = pixels inside them (what the crops' samples are spent on);
    blended  = of those, pixels whose blend weight is above 0 (the rest is rendered for nothing);
    full     = pixels at full weight;
    ratio    = pixels over the module constants' pixels.

A crop's time is about its pixels times its samples plus a fixed cost per call
(docs/rendering.md, "Label-aware sampling"); bench/results/marker_sampling/README.md reads it.
"""
from __future__ import annotations

import argparse
import sys
from contextlib import contextmanager

from dockfactory.core.config import load_config
from dockfactory.core.io import write_json_atomic
from dockfactory.generator import marker_regions as mr
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.sampler import frame_plan, sample_frame


@contextmanager
def _constants(halo_radii: float, margin_px: float):
    """The module's halo radius and margin replaced for the block (restored after): the worker's
    own planner (marker_regions) reads both at call time."""
    old = mr.HALO_RADII, mr.REGION_MARGIN_PX
    mr.HALO_RADII, mr.REGION_MARGIN_PX = halo_radii, margin_px
    try:
        yield
    finally:
        mr.HALO_RADII, mr.REGION_MARGIN_PX = old


def plan_pixels(frames, static) -> dict:
    """Mean per frame of crops, pixels, blended and full-weight pixels of the planned regions."""
    crops = pixels = blended = full = 0
    for f in frames:
        halos = mr.marker_halos(f, static)
        for r in mr.marker_regions(f, static):
            w = mr.halo_weights(halos, r)
            crops, pixels = crops + 1, pixels + r.area
            blended, full = blended + int((w > 0).sum()), full + int((w >= 1).sum())
    n = max(len(frames), 1)
    return {"crops": crops / n, "pixels": pixels / n, "blended": blended / n, "full": full / n}


def _variant(text: str) -> tuple[float, float]:
    try:
        halo, margin = (float(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--variant {text!r}: want HALO_RADII:MARGIN_PX, e.g. 1.4:6") from None
    return halo, margin


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("configs", nargs="+")
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--variant", type=_variant, action="append", default=[])
    ap.add_argument("--out", help="write the figures as JSON")
    a = ap.parse_args(argv)
    settings = [(mr.HALO_RADII, mr.REGION_MARGIN_PX)] + a.variant
    rows = []
    print("| config | halo radii | margin px | crops | pixels | blended | full | ratio |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for path in a.configs:
        cfg = load_config(path)
        static = static_scene(cfg)
        frames = [sample_frame(cfg, s) for s in frame_plan(cfg)[:a.frames]]
        base = None
        for halo, margin in settings:
            with _constants(halo, margin):
                p = plan_pixels(frames, static)
            base = base or p["pixels"]
            rows.append({"config": path, "halo_radii": halo, "margin_px": margin, **p, "ratio": p["pixels"] / base})
            print(f"| {path} | {halo:g} | {margin:g} | {p['crops']:.2f} | {p['pixels']:.0f} | {p['blended']:.0f} "
                  f"| {p['full']:.0f} | {p['pixels'] / base:.3f} |")
    if a.out:
        write_json_atomic(a.out, {"frames": a.frames, "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
