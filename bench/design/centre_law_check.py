"""A rendered design's refined centres against the card's centre-noise law, binned by the disc
image's minor semi-axis b: where the law holds and where it does not (no render, no detector).

Per test frame of a ``dockfactory design --verify`` run folder (VERIFY/ID): each refined detection
matched to its label's marker (same class, within 3 px of the outline centroid); b from the label's
disc (solver.disc_noise.disc_ellipses), the ring width w from b and the disc's diameter; per b bin
the RMS error per axis and a robust one (median |e| / 0.6745) over the law's std per axis
(scale x sqrt(law(b, w)), the shipped card's dark-ring monochrome figures).

    python -m bench.design.centre_law_check out/s16/confirm3_wide3/verify/a87c68d9e2 [...]
"""
import glob
import json
import os
import sys

import numpy as np

from dockfactory.solver.disc_noise import disc_ellipses
from dockfactory.eval.design_noise import ring_width_px
from dockfactory.core.resources import shipped_design_card
from dockfactory.eval.design_card import load_design_card

CARD = load_design_card(shipped_design_card())
LAW, SCALE = CARD.law, CARD.scale_px
BINS = ((0, 3), (3, 4), (4, 5), (5, 6), (6, 8), (8, 11), (11, 30))
def run(folder):
    if not os.path.exists(f'{folder}/run/detections.json'): print(folder, 'no run'); return
    dets = json.load(open(f'{folder}/run/detections.json'))['frames']
    rows = []
    for f in sorted(glob.glob(f'{folder}/run/dataset/labels/*.json')):
        lab = json.load(open(f)); fid = lab['frame_id']
        if lab['spec'].get('split') != 'test' or fid not in dets: continue
        cam = np.array(lab['camera']['cam_from_d']); focal = lab['camera']['focal_px']
        for m in lab['markers']:
            if not m['in_frame']: continue
            c = np.array(m['center_d_mm']) @ cam[:3, :3].T + cam[:3, 3]; n = np.array(m['normal_d']) @ cam[:3, :3].T
            ell = disc_ellipses(c[None], n[None], [m['diameter_mm']], focal)
            b = float(np.sqrt(np.linalg.eigvalsh(ell)[0, 0]))
            t = np.array(m['outline_centroid_px'])
            best = None
            for d in dets[fid]:
                if d['class_id'] != m['class_id'] or not d.get('refined'): continue
                e = np.array(d['center_px']) - t
                if np.hypot(*e) < 3 and (best is None or np.hypot(*e) < np.hypot(*best)): best = e
            if best is not None:
                w = float(ring_width_px([b], [m['diameter_mm']])[0])
                rows.append((b, w, best[0], best[1], SCALE * np.sqrt(LAW.variance([b], [w])[0])))
    r = np.array(rows)
    print(folder, len(r), 'b median %.2f' % np.median(r[:, 0]))
    for lo, hi in BINS:
        k = r[(r[:, 0] >= lo) & (r[:, 0] < hi)]
        if len(k) < 10: continue
        rms = np.sqrt(np.mean(k[:, 2:4] ** 2)); pred = np.sqrt(np.mean(k[:, 4] ** 2))
        med = np.median(np.abs(k[:, 2:4]))/0.6745
        print(f'  b {lo}-{hi}: n {len(k)} rms/axis {rms:.4f} robust {med:.4f} law {pred:.4f} ratio {rms/pred:.2f} robust ratio {med/pred:.2f}')
if __name__ == "__main__":
    for folder in sys.argv[1:]:
        run(folder)
