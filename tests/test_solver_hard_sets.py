"""Issue 12: single-section solves on the pipeline's hard frames (what occlusion leaves: 5 of a
section's markers; markers within +-20 deg of the line facing the camera: near-planar) are
neither refused nor stuck in wrong minima. Before the fix, near-planar 10-point sets at 1 px were
refused 32 % of the time ("focal length is not observable") and 5-point sets at 1 px returned
wrong minima (RMS 30-55 px, 100-240 bound-sigmas in rotation) once the refusal was lifted.
The full figures (5000 trials per case) come from ``bench/solver_bench.py --hard-only``."""
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from solver_bench import run_hard  # noqa: E402


@pytest.mark.slow   # 200 seeded solves per case, ~20 s in all
@pytest.mark.parametrize("kind", ["near-planar-10", "5-point"])
@pytest.mark.parametrize("sigma", [0.3, 1.0])
def test_hard_sets_are_solved_at_the_bound(kind, sigma):
    r = run_hard(kind, sigma, 200, seed=12)
    assert r["refused"] <= 2, r                  # <= 1 %
    assert r["wild"] == 0, r                     # none beyond 6 bound-sigmas in rotation, t_x, t_y
    # local minima (an RMS above the truth-started fit's) within the bound: measured 0-3 of 200
    assert r["wrong"] <= 4, r
    # target 1.15 on 5000 trials (the bench); on 200 the RMS ratio's sampling error is ~5 %
    for k in ("ratio_rot", "ratio_tx", "ratio_ty"):
        assert r[k] <= 1.25, (k, r)
    if kind == "near-planar-10" and sigma == 1.0:
        assert r["flagged"] >= 20, r             # the undetermined focal is said, not hidden


# A real case (out/detector_run, configs/detector.toml 1c6b939ff88e2de6, frame 000177, occlusion):
# the five fully visible red markers, rightly paired, as identification fits them; the cheapest
# closed form lands at 59.6 px RMS (f 8786 px), beyond the identification's rescue, and the frame
# was refused ("could not identify 4 or more markers"); the right basin fits to 0.07 px, f 2120 px
# (true 2124).
P3_177 = [[-47.0, 122.4277, 274.9772], [-88.0, 209.0922, 216.5213], [-62.0, -36.6827, 298.7564],
          [-100.0, -159.5057, 255.2625], [-50.0, -240.3893, 181.1463]]
UV_177 = [[466.3065, 266.1627], [408.8229, 153.9172], [448.1458, 499.6516], [399.776, 678.5941],
          [478.3789, 779.0573]]


def test_a_right_five_point_hypothesis_is_not_lost_to_a_wrong_basin():
    from dockfactory.solver.estimate import estimate_pnpf
    from dockfactory.solver.options import IdentifyOptions
    o = IdentifyOptions()
    est = estimate_pnpf(np.array(P3_177), np.array(UV_177), np.array([639.5, 479.5]), accept_rmse=o.max_rmse,
                        rescue_below=o.rescue_rmse_factor * o.max_rmse)
    assert est.rmse_px < 0.1 and abs(est.focal_px - 2124.1) < 20.0
