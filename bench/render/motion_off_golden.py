"""Digests of what a config without [motion] samples and labels, for tests/generator/test_motion.py.

Run on the commit before motion existed (0724401) it recorded tests/data/motion_off_golden.json:
per shipped config and frame, the sha256 of the frame's scene (``to_dict(sample_frame)``, keys
sorted) and of its label text before rendering (``frame_labels`` without an index pass). The test
recomputes both with the current code: a config without [motion] must give the same bytes.
Recorded again on a CPU without AVX-512 once numpy's trigonometry was pinned to libm's paths
(bench/results/paper/fingerprints_v3_2026-12-03.txt): scenes at 0724401, labels at 6d3579f.

    python -m bench.render.motion_off_golden [out.json]
"""
import hashlib
import json
import subprocess
import sys
from pathlib import Path

import os

import dockfactory

dockfactory.pin_label_arithmetic(os.environ)   # before numpy loads: labels as the command computes them
from dockfactory.core.config import load_config
from dockfactory.core.scene import to_dict
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.frame_output import label_text
from dockfactory.generator.labels import frame_labels
from dockfactory.generator.sampler import frame_plan, sample_frame

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = ("quick", "realistic", "ideal")


def sha(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def digests(name: str) -> dict:
    """{frame_id: [scene sha256, label sha256]} of every frame of configs/<name>.toml."""
    cfg = load_config(ROOT / "configs" / f"{name}.toml")
    static = static_scene(cfg)
    out = {}
    for spec in frame_plan(cfg):
        frame = sample_frame(cfg, spec)
        label = frame_labels(frame, static, None, cfg.labels.visible_threshold)
        out[spec.frame_id] = [sha(json.dumps(to_dict(frame), sort_keys=True)), sha(label_text(label))]
    return out


def main() -> int:
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "tests" / "data" / "motion_off_golden.json"
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    doc = {"about": f"sha256 of to_dict(sample_frame) (json, sorted keys) and of the label text without an index "
                    f"pass, per frame of the shipped configs, made by bench/render/motion_off_golden.py at commit {commit}",
           "commit": commit, "configs": {name: digests(name) for name in CONFIGS}}
    out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"{out}: {sum(len(v) for v in doc['configs'].values())} frames")
    return 0


if __name__ == "__main__":
    sys.exit(main())
