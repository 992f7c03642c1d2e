"""Cost of the colour camera stage (core.camera_chain.develop) on a 1280 x 960 frame, per CFA and
demosaic, and of its parts; the median of repeated runs in this process.

    python -m bench.sensor.sensor_speed [--repeats N] [--threads T]

Target: at most 0.15 s per 1280 x 960 frame for the whole stage (sensor and ISP; JPEG is timed
apart). Run it on a quiet machine: another process on the two cores doubles the figures.
"""
from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from dockfactory.core.camera_chain import ColourChain, develop, jpeg_round_trip
from dockfactory.core.camera_chain.colour_sensor import configured_sensor, sense
from dockfactory.core.camera_chain.isp import process

TARGET_S = 0.15


def median_time(fn, repeats: int) -> float:
    fn()   # caches (fixed patterns, LUTs) and warm-up
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def scene(h: int = 960, w: int = 1280) -> np.ndarray:
    rng = np.random.default_rng(0)
    small = rng.uniform(0.02, 0.6, (h // 16, w // 16, 3)).astype(np.float32)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_NEAREST)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=9)
    p.add_argument("--threads", type=int, default=0, help="OpenCV threads (0: its default)")
    args = p.parse_args()
    if args.threads:
        cv2.setNumThreads(args.threads)
    lin = scene()
    sensor = configured_sensor("imx273", (), 12)
    print("| cfa | demosaic | sense s | ISP s | whole stage s | within 0.15 s |")
    print("| --- | --- | --- | --- | --- | --- |")
    for cfa, method in [("none", "bilinear"), ("RGGB", "bilinear"), ("RGGB", "edge_aware"), ("RGGB", "vng"),
                        ("RGGB", "mhc")]:
        c = ColourChain(cfa, sensor, 1, 0.02, 0.01, method, (0.05, -0.05), True, "srgb", "off", 0.5, 1.0)
        raw = sense(lin, c, np.random.default_rng(1))
        t_sense = median_time(lambda: sense(lin, c, np.random.default_rng(1)), args.repeats)
        t_isp = median_time(lambda: process(raw, c), args.repeats)
        t_all = median_time(lambda: develop(lin, c, np.random.default_rng(1)), args.repeats)
        print(f"| {cfa} | {method} | {t_sense:.3f} | {t_isp:.3f} | {t_all:.3f} | {'yes' if t_all <= TARGET_S else 'NO'} |")
    img = process(raw, c)
    print(f"JPEG q90 4:2:0 round trip: {median_time(lambda: jpeg_round_trip(img, 90), args.repeats):.3f} s")


if __name__ == "__main__":
    main()
