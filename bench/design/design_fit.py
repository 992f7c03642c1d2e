"""Fit the design predictor's card (models/design_predictor.json) on measured renders, and print
how far the fitted model is from them (in the fit and leaving each scene out).

Inputs (committed results, no render needed): the sensor bench at label-aware sampling
(bench/results/sensor_effects/sampling32_48.json by default; the shipped card: sampling24_48.json,
at the render default: scenes A, B, C, 48 test frames each, three-chip, Bayer bilinear / VNG,
Bayer + JPEG q90) with the scenes' configs (bench/configs/sensor_scene_*.toml, whose test frames'
geometry the predictor redraws exactly), and for the white ring and a three-chip camera's JPEG
the same bench on white-ring renders of scenes A and B and on scene A again (ring/white32_48.json,
jpeg32_a_48.json by default; ring/white24_48.json, jpeg24_a_48.json for the shipped card).

The model (eval.design_predict): RMSE^2 = s0^2 Vn + su^2 Vu + sv^2 Vv per component, Vn the
disc-noise variance at unit scale and Vu, Vv the section offset's at unit shift per axis, mean
over the frames. (s0, su, sv) by non-negative least squares on the relative squared error of the
three-chip camera's X, Y and alpha on the three scenes; each factor as the geometric mean of
measured over predicted.

Run: python -m bench.design.design_fit [--write] [--scenes a,b,c,d] [--sources sampling.json white.json jpeg_a.json]
[--ring-dark dark.json]
(--write: models/design_predictor.json; --sources: the three inputs above by their names under
bench/results/sensor_effects/, for renders at another render default).
"""
from __future__ import annotations

import argparse
import itertools
import json
import os
from pathlib import Path

import dockfactory

dockfactory.pin_label_arithmetic(os.environ)

import numpy as np  # noqa: E402

from dockfactory.core.config import load_config  # noqa: E402
from dockfactory.core.io import write_json_atomic  # noqa: E402
from dockfactory.eval.design_card import CARD_FORMAT  # noqa: E402
from dockfactory.eval.design_noise import CentreNoiseLaw  # noqa: E402
from dockfactory.eval.design_predict import NoiseClass, mean_variances  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results" / "sensor_effects"
SOURCES = ("sampling32_48.json", "ring/white32_48.json", "jpeg32_a_48.json")   # sampling, white ring, JPEG on A
SCENES = ("a", "b", "c")
FIT = ("x", "y", "alpha")
IDX = {"x": 0, "y": 1, "alpha": 3}
BAYER = ("bayer-bilinear", "bayer-vng")
# The centres' noise law (eval.design_noise), measured per marker on the sensor scenes A, B, D and on
# A and B with the other disc size (python -m bench.sensor.ring_width_law; bench/results/design/README.md).
LAW = CentreNoiseLaw(minor_exponent=1.0, floor=5.0, ring_coefficient=8.0, ring_exponent=3.0)


def basis(scene: str, law: CentreNoiseLaw | None = LAW) -> np.ndarray:
    """(3, 3): rows Vn, Vu, Vv; columns X, Y, alpha (mean over the scene's 48 test frames), the
    centres' noise following ``law`` (None: the solver's weights)."""
    cfg = load_config(ROOT / "bench" / "configs" / f"sensor_scene_{scene}.toml")
    rows = []
    for shift in ((0.0, 0.0), (1.0, 0.0), (0.0, 1.0)):
        vn, vs, _ = mean_variances(cfg, NoiseClass(1.0, shift, law), 48)
        rows.append(vn if shift == (0.0, 0.0) else vs)
    return np.array(rows)[:, [IDX[c] for c in FIT]]


def measured(results: dict, scene: str, effect: str) -> np.ndarray:
    [ds] = [k for k in results if k.startswith(f"sensor-scene-{scene}@")]
    rec = results[ds][effect]
    return np.array([rec[f"rmse_{c}"] for c in FIT])


def nnls_relative(bases: dict, targets: dict) -> np.ndarray:
    """(s0, su, sv) >= 0 minimising sum ((V p^2) / m^2 - 1)^2 (active sets enumerated)."""
    a = np.concatenate([bases[s].T / targets[s][:, None] ** 2 for s in targets])
    b = np.ones(len(a))
    best = None
    for active in itertools.product((0, 1), repeat=3):
        idx = [i for i in range(3) if active[i]]
        if not idx:
            continue
        x = np.zeros(3)
        sol, *_ = np.linalg.lstsq(a[:, idx], b, rcond=None)
        if np.any(sol < 0):
            continue
        x[idx] = sol
        res = float(np.sum((a @ x - b) ** 2))
        if best is None or res < best[0]:
            best = (res, x)
    return np.sqrt(best[1])


def predicted(base: np.ndarray, p: np.ndarray) -> np.ndarray:
    return np.sqrt(p[0] ** 2 * base[0] + p[1] ** 2 * base[1] + p[2] ** 2 * base[2])


def geo_factor(pairs) -> float:
    """Geometric mean of measured / predicted over (measured (3,), predicted (3,)) pairs."""
    return float(np.exp(np.mean([np.log(m / p) for m, p in pairs])))


def ratio_rows(name, pairs_by_scene) -> list[dict]:
    return [{"what": name, "scene": s, **{c: round(float(p[i] / m[i]), 3) for i, c in enumerate(FIT)}}
            for s, (m, p) in pairs_by_scene.items()]


def ring_and_jpeg_factors(results: dict, sources=SOURCES, ring_dark: dict | None = None,
                          scenes=("a",)) -> dict:
    """The white ring's factor per camera class, and JPEG q90's on a three-chip camera per ring,
    each the geometric mean over X, Y, alpha of measured over measured on the same frames at
    label-aware sampling: white-ring renders of scenes A and B (``sources[1]``) over the dark-ring
    ones (``results``, read from ``sources[0]``), three-chip for "none", Bayer bilinear and VNG for
    "rggb"; JPEG over PNG on the dark ``scenes`` of ``sources[2]`` ("jpeg_dark"; those of them it
    holds) and on the two white-ring scenes ("jpeg_white"): JPEG costs a dark ring's edge several times what it costs a
    white one's, so one factor pooled over both would be wrong for each. ``ring_dark``: the
    dark-ring results the white ones were measured beside, when they are not ``results`` (white
    renders of an earlier render default: a ratio of one default)."""
    dark = results if ring_dark is None else ring_dark
    white = json.loads((RESULTS / sources[1]).read_text())["datasets"]
    jpeg_src = json.loads((RESULTS / sources[2]).read_text())["datasets"]
    as_scene = {f"sensor-scene-{s}@": white[k] for s in ("a", "b") for k in white if k.startswith(f"sensor-scene-{s}-white@")}
    ring = {"none": [(measured(as_scene, s, "three-chip"), measured(dark, s, "three-chip")) for s in ("a", "b")],
            "rggb": [(measured(as_scene, s, e), measured(dark, s, e)) for s in ("a", "b") for e in BAYER]}
    jpeg_white = [(measured(as_scene, s, "three-chip-jpeg90"), measured(as_scene, s, "three-chip")) for s in ("a", "b")]
    jpeg_dark = [(measured(jpeg_src, s, "three-chip-jpeg90"), measured(jpeg_src, s, "three-chip")) for s in scenes
                 if any(k.startswith(f"sensor-scene-{s}@") for k in jpeg_src)]
    return {"ring_white": {c: geo_factor(v) for c, v in ring.items()},
            "jpeg_dark": geo_factor(jpeg_dark), "jpeg_white": geo_factor(jpeg_white)}


def jpeg_table(other: dict, jpeg_rggb: float) -> dict:
    """The card's ``jpeg_factor`` per ring and camera class: the Bayer camera's white-ring figure
    (not measured: no Bayer + JPEG render of a white ring) is its dark-ring one times the white
    ring's JPEG factor over the dark ring's on the three-chip camera (provisional), and at least 1:
    a JPEG adds noise, it takes none away."""
    white_rggb = max(1.0, jpeg_rggb * other["jpeg_white"] / other["jpeg_dark"])
    return {"dark": {"none": round(other["jpeg_dark"], 3), "rggb": round(jpeg_rggb, 3)},
            "white": {"none": round(other["jpeg_white"], 3), "rggb": round(white_rggb, 3)}}


def fit(sources=SOURCES, scenes=SCENES, ring_dark: str | None = None, law: CentreNoiseLaw = LAW) -> dict:
    """The card (models/design_predictor.json's content) fitted on ``sources`` (SOURCES' order)
    over the sensor scenes ``scenes`` (each in ``sources[0]``) with the centres' noise ``law``;
    ``ring_dark``: the dark-ring results beside the white ones (:func:`ring_and_jpeg_factors`;
    None: ``sources[0]``)."""
    results = json.loads((RESULTS / sources[0]).read_text())["datasets"]
    bases = {s: basis(s, law) for s in scenes}
    tc = {s: measured(results, s, "three-chip") for s in scenes}
    p = nnls_relative(bases, tc)
    rows = ratio_rows("three-chip (fit)", {s: (tc[s], predicted(bases[s], p)) for s in scenes})
    for out in scenes:
        q = nnls_relative(bases, {s: tc[s] for s in scenes if s != out})
        rows += ratio_rows(f"three-chip, scene {out.upper()} left out", {out: (tc[out], predicted(bases[out], q))})
    bayer = [(measured(results, s, e), predicted(bases[s], p)) for s in scenes for e in BAYER]
    g = geo_factor(bayer)
    for e in BAYER:
        rows += ratio_rows(e, {s: (measured(results, s, e), g * predicted(bases[s], p)) for s in scenes})
    jpeg = geo_factor([(measured(results, s, "bayer-jpeg90"), g * predicted(bases[s], p)) for s in scenes])
    rows += ratio_rows("bayer-jpeg90", {s: (measured(results, s, "bayer-jpeg90"),
                                            g * jpeg * predicted(bases[s], p)) for s in scenes})
    dark = None if ring_dark is None else json.loads((RESULTS / ring_dark).read_text())["datasets"]
    other = ring_and_jpeg_factors(results, sources, dark, scenes)
    versions = sorted(results)
    return {"format": CARD_FORMAT, "scale_px": round(float(p[0]), 5),
            "shift_px": [round(float(p[1]), 5), round(float(p[2]), 5)],
            "cfa_factor": {"none": 1.0, "rggb": round(g, 3)},
            "ring_factor": {"dark": {"none": 1.0, "rggb": 1.0},
                            "white": {c: round(v, 3) for c, v in other["ring_white"].items()}},
            "jpeg_factor": jpeg_table(other, jpeg),
            "jpeg_min_quality": 90, "centre_noise": dict(vars(law)),
            "bound_factor": {c: 1.0 for c in ("x", "y", "z", "alpha", "beta", "gamma")},
            "provisional": ["jpeg_factor.white.rggb"],
            "fitted_on": {"renders": versions, "frames_each": 48, "condition": "normal",
                          "weights": "yolov5n_se_rings_markers.pt",
                          "source": f"bench/results/sensor_effects/{sources[0]}",
                          "ring_and_jpeg_source": [f"bench/results/sensor_effects/{n}" for n in sources[1:]]
                          + ([f"bench/results/sensor_effects/{ring_dark}"] if ring_dark else []),
                          "components_checked": list(FIT)},
            "error": {"predicted_over_measured": rows}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--write", action="store_true", help="write models/design_predictor.json")
    ap.add_argument("--card-out", type=Path, default=None,
                    help="write the card here instead (a card tried with `dockfactory design --card`, not shipped)")
    ap.add_argument("--scenes", default=",".join(SCENES),
                    help="the sensor scenes fitted on, comma-separated (bench/configs/sensor_scene_<s>.toml; default: %(default)s)")
    ap.add_argument("--sources", nargs=3, default=SOURCES, metavar=("SAMPLING", "WHITE", "JPEG_A"),
                    help="the inputs under bench/results/sensor_effects/ (default: %(default)s)")
    ap.add_argument("--ring-dark", default=None, metavar="DARK",
                    help="the dark-ring results the white ones were measured beside, if not SAMPLING")
    ap.add_argument("--law", default=None, metavar="P,FLOOR,C,K",
                    help="the centres' noise law: minor exponent, floor, ring coefficient, ring exponent "
                         "(default: LAW, the measured one)")
    args = ap.parse_args()
    law = LAW if args.law is None else CentreNoiseLaw(*(float(v) for v in args.law.split(",")))
    card = fit(tuple(args.sources), tuple(args.scenes.split(",")), args.ring_dark, law)
    print(f"scale {card['scale_px']} px, offset {card['shift_px']} px, "
          f"rggb x{card['cfa_factor']['rggb']}, "
          f"jpeg x{card['jpeg_factor']} (provisional: {card['provisional']}), white ring x{card['ring_factor']['white']}")
    print("| what | scene | X | Y | alpha (predicted / measured) |\n| --- | --- | --- | --- | --- |")
    for r in card["error"]["predicted_over_measured"]:
        print(f"| {r['what']} | {r['scene'].upper()} | {r['x']:.2f} | {r['y']:.2f} | {r['alpha']:.2f} |")
    if args.write or args.card_out:
        write_json_atomic(args.card_out or ROOT / "models" / "design_predictor.json", card)


if __name__ == "__main__":
    main()
