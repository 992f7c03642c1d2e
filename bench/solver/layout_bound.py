"""How the marker layout and the camera distance limit the pose: Cramer-Rao bounds.

    python -m bench.solver.layout_bound [--sigma 0.1] [--frames 200]

For each variant, the RMS over sampled frames (the sampler's cameras and poses) of the Cramer-Rao
standard deviation of X, Y, alpha, beta of d_from_b, joint problem (shared unknown focal), at
``sigma`` px of isotropic centre noise.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

from dockfactory.core.config import config_from_dict  # noqa: E402
from dockfactory.core.layout import DEFAULT_LAYOUT_A, DEFAULT_LAYOUT_B, marker_points  # noqa: E402
from dockfactory.generator.random_draws import static_scene  # noqa: E402
from dockfactory.generator.sampler import frame_plan, sample_frame  # noqa: E402
from dockfactory.solver import crb_d_from_b  # noqa: E402


def bound(data: dict, sigma: float) -> np.ndarray:
    cfg = config_from_dict(data, "<layout_bound>")
    st = static_scene(cfg)
    pa, pb = marker_points(st.markers, "A"), marker_points(st.markers, "B")
    out = []
    for spec in frame_plan(cfg):
        f = sample_frame(cfg, spec)
        c = f.camera.cam_from_d_array()
        b = crb_d_from_b(pa, c, pb, c @ f.d_from_b_array(), f.camera.focal_px, f.camera.principal_point, sigma)
        out.append([b.std["x_mm"], b.std["y_mm"], b.std["alpha_deg"], b.std["beta_deg"]])
    return np.sqrt(np.mean(np.square(out), axis=0))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sigma", type=float, default=0.1)
    ap.add_argument("--frames", type=int, default=200)
    args = ap.parse_args()
    narrow = ([(s, p * 0.6) for s, p in DEFAULT_LAYOUT_A], [(s, p * 0.6) for s, p in DEFAULT_LAYOUT_B])
    longer = ([(50 + (s - 47) * 2.3, p) for s, p in DEFAULT_LAYOUT_A], [(50 + (s - 48) * 2.3, p) for s, p in DEFAULT_LAYOUT_B])
    variants = [
        ("default layout (+-60 deg, s 47-158 mm)", {}),
        ("angles x0.6 (+-36 deg)", {"markers": {"layout_a": narrow[0], "layout_b": narrow[1]}}),
        ("axial spread x2.3 (s 50-300 mm)", {"markers": {"layout_a": longer[0], "layout_b": longer[1]}}),
        ("default layout, camera 0.8-1.0 m", {"camera": {"distance_mm": [800.0, 1000.0]}}),
    ]
    print(f"Cramer-Rao bound (RMS over {args.frames} sampled frames), joint problem, sigma = {args.sigma} px")
    for name, extra in variants:
        data = {"dataset": {"frames": args.frames, "seed": 3}, **extra}
        b = bound(data, args.sigma)
        print(f"  {name:42s} X {b[0]:.3f} mm  Y {b[1]:.3f} mm  alpha {b[2]:.4f} deg  beta {b[3]:.3f} deg")
    return 0


if __name__ == "__main__":
    sys.exit(main())
