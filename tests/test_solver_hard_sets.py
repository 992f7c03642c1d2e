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
