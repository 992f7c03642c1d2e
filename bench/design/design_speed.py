"""How long `dockfactory design` takes for a space of 200 designs, every one of them predicted
(none infeasible): the whole process, import and outputs included, each run timed by the wall
clock. Target (issue 48): 200 designs in under 60 s on 2 cores.

Run: python -m bench.design.design_speed [--runs 3] [--card CARD.json] [--jobs N] [--no-refusals]
(--card: another predictor card; --jobs: the command's processes, default its own, one per core;
--no-refusals: without the frames the gate refuses simulated)
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SPACE = """\
[design]
scene = "quick"
test_frames = 40
repeatability_poses = 3
repeatability_captures = 10
geometry_frames = 24

{cameras}
[[lens]]
focal_mm = 4.0

[[lens]]
focal_mm = 5.0

[space]
distance_mm = [[1500, 2500], [1800, 2600]]
marker_diameter_mm = [16, 20, 24, 30, 36]
markers_per_section = [6, 7, 9, 12, 16]
"""
CAMERA = """[[camera]]
name = "{name}"
width = {w}
height = {h}
pixel_um = {p}
cfa = "{cfa}"
preset = "imx273"
"""


def space_text() -> str:
    """2 cameras x 2 lenses x 2 distances x 5 diameters x 5 counts = 200 designs."""
    cams = [CAMERA.format(name="mono", w=1440, h=1080, p=3.45, cfa="none"),
            CAMERA.format(name="colour", w=1440, h=1080, p=3.45, cfa="rggb")]
    return SPACE.format(cameras="\n".join(cams))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--card", default=None, help="a predictor card (default: the shipped one)")
    ap.add_argument("--jobs", type=int, default=None, help="the command's --jobs (default: its own)")
    ap.add_argument("--no-refusals", action="store_true", help="pass --no-refusals")
    args = ap.parse_args()
    card = ["--card", str(Path(args.card).resolve())] if args.card else []
    card += (["--jobs", str(args.jobs)] if args.jobs else []) + (["--no-refusals"] if args.no_refusals else [])
    with tempfile.TemporaryDirectory() as tmp:
        space = Path(tmp) / "space.toml"
        space.write_text(space_text())
        times = []
        for k in range(args.runs):
            t0 = time.monotonic()
            subprocess.run([sys.executable, "-m", "dockfactory", "design", str(space), "--out", f"{tmp}/o{k}", *card],
                           check=True, stdout=subprocess.DEVNULL)
            times.append(time.monotonic() - t0)
        rows = json.loads((Path(tmp) / "o0" / "design.json").read_text())["designs"]
    predicted = sum(r["status"] in ("passes", "undecided", "fails") for r in rows)
    simulated = sum(bool(r.get("no_pose", {}).get("simulated")) for r in rows)
    print(f"{len(rows)} designs, {predicted} predicted, {simulated} with frames simulated; wall time per run: "
          + ", ".join(f"{t:.1f} s" for t in times) + f" (median {sorted(times)[len(times) // 2]:.1f} s)")


if __name__ == "__main__":
    main()
