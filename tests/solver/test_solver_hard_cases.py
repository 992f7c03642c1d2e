"""Hard cases found by the solver benchmark, kept as regression tests: a single-section start
that slides to the orthographic limit, and an identification that must shed a stray pair."""
from __future__ import annotations

import numpy as np

from dockfactory.solver.estimate import estimate_pnpf
from dockfactory.solver.synthetic import default_layout

LAYOUT = default_layout()


def test_runaway_focal_falls_back_to_the_other_starts():
    # section B's markers 1, 2, 4, 5, 6 (mm, B frame) and their detections (px) in that frame
    ids = ["B1", "B2", "B4", "B5", "B6"]
    by_id = {m.id: m for m in LAYOUT}
    p3 = np.array([by_id[i].center_mm for i in ids], dtype=float)
    p2 = np.array(UV_132)
    pp = np.array([639.5, 479.5])
    ref = estimate_pnpf(p3, p2, pp, check_focal=False, accept_rmse=2.5, rescue_below=10.0)
    # true focal 1937.5 px, detections with 0.5 px noise: the right basin ends near 1885 px
    # with 0.42 px RMS; the runaway ended at 9e11 px with 26 px RMS
    assert ref.rmse_px < 1.0
    assert abs(ref.focal_px / 1937.53 - 1) < 0.05


UV_132 = [[890.044549, 681.286891], [846.164196, 529.266177], [828.071231, 289.181957],
          [886.159545, 221.569453], [930.972526, 850.007595]]


def test_identification_sheds_a_stray_pair():
    """Identification benchmark case (seed [0, 888], trial 99): markers A1 and A2 are missing
    and a spurious detection lies where A2 would project; the first search pairs them, the fit
    fails, and without a second, one-pair-shedding search the frame was refused."""
    from dockfactory.solver import identify_markers
    res = identify_markers(LAYOUT, (639.5, 479.5), (np.array(CLASSES_99), np.array(UV_99)))
    assert list(res.marker_ids) == TRUTH_99


CLASSES_99 = [0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 0, 1]
UV_99 = [[547.990725, 852.229743], [397.599477, 388.353285], [545.181262, 272.765254],
         [488.740193, 144.846018], [401.583066, 874.381977], [852.165098, 656.182770],
         [915.741410, 242.115110], [760.951491, 158.961548], [834.040627, 80.238348],
         [906.575868, 865.706771], [605.408330, 386.915180], [667.624669, 606.884473],
         [537.920143, 536.504838]]
TRUTH_99 = ['A0', 'A3', 'A4', 'A5', 'A6', 'B1', 'B3', 'B4', 'B5', 'B6', None, None, None]
