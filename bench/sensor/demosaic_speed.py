"""Speed of ``dockfactory.core.camera_chain.demosaic.demosaic``: median wall time per method on a 1280x960 raw
frame, uint16 (12-bit values) and uint8 (float32 with --float). Target: the slowest method under
about 60 ms per uint16 frame on the 2-core machine.

    python -m bench.sensor.demosaic_speed [--repeats 21] [--pattern RGGB] [--float] [--threads N]

Not a test: it prints one line per dtype and method (median and min, ms) and exits 0.
"""
from __future__ import annotations

import argparse
import statistics
import time

import cv2
import numpy as np

from dockfactory.core.camera_chain.cfa import PATTERNS
from dockfactory.core.camera_chain.demosaic import DEMOSAICS, demosaic

HEIGHT, WIDTH = 960, 1280
TARGET_MS = 60.0


def frame(dtype, rng: np.random.Generator) -> np.ndarray:
    """A 1280x960 raw frame: a smooth ramp plus noise, so edge-directed methods see real gradients."""
    y, x = np.mgrid[0:HEIGHT, 0:WIDTH]
    base = 0.1 + 0.8 * (x / WIDTH) * (0.5 + 0.5 * np.sin(y / 37.0))
    level = np.clip(base + 0.02 * rng.standard_normal((HEIGHT, WIDTH)), 0.0, 1.0)
    if dtype == np.float32:
        return level.astype(np.float32)
    top = 255 if dtype == np.uint8 else 4095
    return np.rint(level * top).astype(dtype)


def median_ms(raw: np.ndarray, pattern: str, method: str, repeats: int) -> tuple[float, float]:
    demosaic(raw, pattern, method)   # warm-up (VNG's one-off displacement probe, allocations)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        demosaic(raw, pattern, method)
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times), min(times)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--repeats", type=int, default=21)
    p.add_argument("--pattern", default="RGGB", choices=PATTERNS)
    p.add_argument("--float", action="store_true", help="also time float32 frames")
    p.add_argument("--threads", type=int, help="cv2.setNumThreads (default: OpenCV's own choice)")
    args = p.parse_args()
    if args.threads is not None:
        cv2.setNumThreads(args.threads)
    rng = np.random.default_rng(0)
    dtypes = (np.uint16, np.uint8) + ((np.float32,) if args.float else ())
    print(f"demosaic {WIDTH}x{HEIGHT} {args.pattern}, median (min) of {args.repeats} runs, "
          f"OpenCV {cv2.__version__} on {cv2.getNumThreads()} threads")
    for dtype in dtypes:
        raw = frame(dtype, rng)
        for method in DEMOSAICS:
            med, best = median_ms(raw, args.pattern, method, args.repeats)
            flag = "  > target" if dtype == np.uint16 and med > TARGET_MS else ""
            print(f"  {np.dtype(dtype).name:8s} {method:11s} {med:7.1f} ms  ({best:.1f}){flag}")


if __name__ == "__main__":
    main()
