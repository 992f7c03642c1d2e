"""Fingerprint v3 of a published dataset from a re-render of some of its frames (generator.datasets.fingerprints_libm).

The published paper dataset's labels were computed by a generator whose numpy took its AVX-512
paths for sin and cos; dockfactory now pins libm's on every CPU, so a re-render differs from them
in the last bits of its geometry. This writes, for the re-rendered frames, their label cores as the
pinned generator computes them (fingerprints_v3.npz beside the manifest, merged with the frames it
already holds), after checking each frame's index-pass numbers against v2's; `dataset verify
--manifest` then accepts either core. Nothing is written if any frame is refused.

Run: python -m bench.render.derive_fingerprints_v3 RERENDER [--manifest results/paper/manifest.json] [--out FILE]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import os

import dockfactory

dockfactory.pin_label_arithmetic(os.environ)   # before numpy loads: labels as the command computes them
from dockfactory.generator.datasets.fingerprints_libm import derive


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rerender", type=Path)
    ap.add_argument("--manifest", type=Path, default=Path("results/paper/manifest.json"))
    ap.add_argument("--out", type=Path)
    args = ap.parse_args(argv)
    der = derive(args.rerender, args.manifest, args.out)
    for problem in der.problems:
        print(problem)
    print(der.text() + ("" if not der.problems else f"; {len(der.problems)} refused, nothing written"))
    return 1 if der.problems else 0


if __name__ == "__main__":
    raise SystemExit(main())
