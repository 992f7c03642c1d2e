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
measured over predicted; the Bayer camera's (bilinear, the factory's demosaic) with a size exponent k
fitted beside it (noise g (10 / b)^k per marker: :func:`size_fit`), and JPEG figures above q90 from
q95 beside q90 on the same frames (``--jpeg95``).

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
from dockfactory.eval.design_predict import NoiseClass, mean_variances, median_minor_px  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results" / "sensor_effects"
SOURCES = ("sampling32_48.json", "ring/white32_48.json", "jpeg32_a_48.json")   # sampling, white ring, JPEG on A
SCENES = ("a", "b", "c")
FIT = ("x", "y", "alpha")
IDX = {"x": 0, "y": 1, "alpha": 3}
# The Bayer cameras the card's Bayer figures are fitted on: the factory's demosaic (bilinear, what a
# design's renders use, ``dockfactory design --verify``); VNG is measured beside it (--bayer-effects).
BAYER = ("bayer-bilinear",)
# The centres' noise law (eval.design_noise), measured per marker on the sensor scenes A, B, D and on
# A and B with the other disc size (python -m bench.sensor.ring_width_law; bench/results/design/README.md).
LAW = CentreNoiseLaw(minor_exponent=1.0, floor=5.0, ring_coefficient=8.0, ring_exponent=3.0)


# The Bayer camera's size exponents tried (eval.design_noise.size_factors; 0: one factor for every disc).
SIZE_GRID = tuple(np.round(np.arange(0.0, 2.01, 0.25), 2))


def basis(scene: str, law: CentreNoiseLaw | None = LAW, size_exponent: float = 0.0) -> np.ndarray:
    """(3, 3): rows Vn, Vu, Vv; columns X, Y, alpha (mean over the scene's 48 test frames), the
    centres' noise following ``law`` (None: the solver's weights) times the class's size factors
    at ``size_exponent``."""
    cfg = load_config(ROOT / "bench" / "configs" / f"sensor_scene_{scene}.toml")
    rows = []
    for shift in ((0.0, 0.0), (1.0, 0.0), (0.0, 1.0)):
        vn, vs, _ = mean_variances(cfg, NoiseClass(1.0, shift, law, size_exponent), 48)
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


def size_fit(results: dict, scenes, p: np.ndarray, law: CentreNoiseLaw, grid=SIZE_GRID,
             bayer=BAYER) -> tuple[float, float]:
    """(size exponent, factor) of the Bayer cameras ``bayer`` on ``scenes``: for each exponent of
    ``grid`` the factor is the geometric mean of measured over predicted (three-chip scale ``p``),
    and the exponent kept is the one whose log ratios have the least sum of squares."""
    best = None
    for k in grid:
        pairs = [(measured(results, s, e), predicted(basis(s, law, k), p)) for s in scenes for e in bayer]
        g = geo_factor(pairs)
        score = sum(float(np.sum(np.log(m / (g * q)) ** 2)) for m, q in pairs)
        if best is None or score < best[0]:
            best = (score, float(k), g)
    return best[1], best[2]


def bayer_rows(results: dict, scenes, p: np.ndarray, law: CentreNoiseLaw, k: float, g: float,
               grid=SIZE_GRID, bayer=BAYER) -> list[dict]:
    """Predicted over measured of each Bayer camera of ``bayer`` on ``scenes`` at exponent ``k`` and
    factor ``g``, and each scene predicted from an exponent (of ``grid``) and factor fitted on the
    others."""
    rows = []
    for e in bayer:
        rows += ratio_rows(e, {s: (measured(results, s, e), g * predicted(basis(s, law, k), p)) for s in scenes})
    for out in scenes if len(scenes) > 2 else ():
        k_o, g_o = size_fit(results, [s for s in scenes if s != out], p, law, grid, bayer)
        for e in bayer:
            rows += ratio_rows(f"{e}, scene {out.upper()} left out (exponent {k_o:g})",
                               {out: (measured(results, out, e), g_o * predicted(basis(out, law, k_o), p))})
    return rows


def ratio_rows(name, pairs_by_scene) -> list[dict]:
    return [{"what": name, "scene": s, **{c: round(float(p[i] / m[i]), 3) for i, c in enumerate(FIT)}}
            for s, (m, p) in pairs_by_scene.items()]


def ring_and_jpeg_factors(results: dict, sources=SOURCES, ring_dark: dict | None = None,
                          scenes=("a",), bayer=BAYER) -> dict:
    """The white ring's factor per camera class, and JPEG q90's on a three-chip camera per ring,
    each the geometric mean over X, Y, alpha of measured over measured on the same frames at
    label-aware sampling: white-ring renders of scenes A and B (``sources[1]``) over the dark-ring
    ones (``results``, read from ``sources[0]``), three-chip for "none", the ``bayer`` effects for
    "rggb"; JPEG over PNG on the dark ``scenes`` of ``sources[2]`` ("jpeg_dark"; those of them it
    holds) and on the two white-ring scenes ("jpeg_white"): JPEG costs a dark ring's edge several times what it costs a
    white one's, so one factor pooled over both would be wrong for each. ``ring_dark``: the
    dark-ring results the white ones were measured beside, when they are not ``results`` (white
    renders of an earlier render default: a ratio of one default)."""
    dark = results if ring_dark is None else ring_dark
    white = json.loads((RESULTS / sources[1]).read_text())["datasets"]
    jpeg_src = json.loads((RESULTS / sources[2]).read_text())["datasets"]
    as_scene = {f"sensor-scene-{s}@": white[k] for s in "abcd" for k in white if k.startswith(f"sensor-scene-{s}-white@")}
    rings = [s for s in "abcd" if f"sensor-scene-{s}@" in as_scene and any(k.startswith(f"sensor-scene-{s}@") for k in dark)]
    ring = {"none": [(measured(as_scene, s, "three-chip"), measured(dark, s, "three-chip")) for s in rings],
            "rggb": [(measured(as_scene, s, e), measured(dark, s, e)) for s in rings for e in bayer]}
    jpeg_white = [(measured(as_scene, s, "three-chip-jpeg90"), measured(as_scene, s, "three-chip")) for s in rings]
    # a Bayer + JPEG camera's white ring over its dark one, where the white bench has it
    bj = [(measured(as_scene, s, "bayer-jpeg90"), measured(dark, s, "bayer-jpeg90")) for s in rings
          if "bayer-jpeg90" in as_scene[f"sensor-scene-{s}@"]]
    # and over its own PNG twin (the white ring's Bayer camera without the JPEG)
    bw = [(measured(as_scene, s, "bayer-jpeg90"), measured(as_scene, s, bayer[0])) for s in rings
          if "bayer-jpeg90" in as_scene[f"sensor-scene-{s}@"]]
    jpeg_dark = [(measured(jpeg_src, s, "three-chip-jpeg90"), measured(jpeg_src, s, "three-chip")) for s in scenes
                 if any(k.startswith(f"sensor-scene-{s}@") for k in jpeg_src)]
    return {"ring_white": {c: geo_factor(v) for c, v in ring.items()},
            "jpeg_dark": geo_factor(jpeg_dark), "jpeg_white": geo_factor(jpeg_white),
            "bayer_jpeg_white_over_dark": geo_factor(bj) if bj else None,
            "bayer_jpeg_white_over_png": geo_factor(bw) if bw else None, "white_scenes": rings}


def jpeg_table(other: dict, jpeg_rggb: float, own_twin: bool = False) -> tuple[dict, list[str]]:
    """(the card's ``jpeg_factor`` per ring and camera class, the provisional factors). The Bayer
    camera's white-ring figure: measured where the white bench has a Bayer + JPEG camera (its
    white over dark ratio times the dark JPEG factor, over the white ring's Bayer factor, which the
    card multiplies with it; with ``own_twin``, its RMSE over its own PNG twin's, as the
    three-chip camera's: for white renders measured beside a dark bench other than the one the
    dark JPEG factor comes from, where the first would mix two benches' JPEG); else its dark-ring
    one times the white ring's JPEG factor over the dark ring's on the three-chip camera
    (provisional). At least 1: a JPEG adds noise, it takes none away."""
    measured_ratio = other.get("bayer_jpeg_white_over_dark")
    if own_twin and other.get("bayer_jpeg_white_over_png") is not None:
        white_rggb, prov = max(1.0, other["bayer_jpeg_white_over_png"]), []
    elif measured_ratio is not None:
        white_rggb, prov = max(1.0, measured_ratio * jpeg_rggb / other["ring_white"]["rggb"]), []
    else:
        white_rggb, prov = max(1.0, jpeg_rggb * other["jpeg_white"] / other["jpeg_dark"]), ["jpeg_factor.white.rggb"]
    return ({"dark": {"none": round(other["jpeg_dark"], 3), "rggb": round(jpeg_rggb, 3)},
             "white": {"none": round(other["jpeg_white"], 3), "rggb": round(white_rggb, 3)}}, prov)


def merged(*files) -> dict:
    """{dataset: {effect: record}} of results files under RESULTS, merged (the same dataset's
    effects from several runs of the same frames)."""
    out: dict = {}
    for name in files:
        for ds, effects in json.loads((RESULTS / name).read_text())["datasets"].items():
            out.setdefault(ds, {}).update(effects)
    return out


def jpeg_above(table: dict, dark: dict, white: dict, quality: int) -> dict:
    """The card's ``jpeg_factor`` table at ``quality`` from the one at q90 (``table``): per ring
    and camera class, times the geometric mean of the JPEG camera's RMSE at ``quality`` over at q90
    on the same frames (three-chip for "none", Bayer bilinear for "rggb"; the ``dark`` and
    ``white`` results, {dataset: {effect: record}}, each holding both), at least 1."""
    cams = {"none": "three-chip-jpeg", "rggb": "bayer-jpeg"}
    out = {}
    for ring, results in (("dark", dark), ("white", white)):
        out[ring] = {}
        for cfa, cam in cams.items():
            pairs = [(np.array([v[f"{cam}{quality}"][f"rmse_{c}"] for c in FIT]),
                      np.array([v[f"{cam}90"][f"rmse_{c}"] for c in FIT]))
                     for v in results.values() if f"{cam}{quality}" in v and f"{cam}90" in v]
            if not pairs:
                raise SystemExit(f"no {cam}{quality} beside {cam}90 in the {ring}-ring results")
            out[ring][cfa] = round(max(1.0, table[ring][cfa] * geo_factor(pairs)), 3)
    return out


def bayer_part(results: dict, scenes, p: np.ndarray, law: CentreNoiseLaw, size_exponent: float | None,
               bayer=BAYER):
    """(size exponent, Bayer factor, Bayer + JPEG q90 factor, rows of predicted over measured) on
    ``scenes`` at the three-chip scale ``p``: the exponent fitted (:func:`size_fit`) when
    ``size_exponent`` is None, else that one with its factor."""
    grid = SIZE_GRID if size_exponent is None else (size_exponent,)
    k, g = size_fit(results, scenes, p, law, grid, bayer)
    rows = bayer_rows(results, scenes, p, law, k, g, grid, bayer)
    pred = {s: g * predicted(basis(s, law, k), p) for s in scenes}
    jpeg = geo_factor([(measured(results, s, "bayer-jpeg90"), pred[s]) for s in scenes])
    rows += ratio_rows("bayer-jpeg90", {s: (measured(results, s, "bayer-jpeg90"), jpeg * pred[s]) for s in scenes})
    return k, g, jpeg, rows


def fit(sources=SOURCES, scenes=SCENES, ring_dark: str | None = None, law: CentreNoiseLaw = LAW,
        size_exponent: float | None = None, bayer=BAYER, q95: tuple[str, str] | None = None,
        own_twin: bool = False) -> dict:
    """The card (models/design_predictor.json's content) fitted on ``sources`` (SOURCES' order)
    over the sensor scenes ``scenes`` (each in ``sources[0]``) with the centres' noise ``law``;
    ``ring_dark``: the dark-ring results beside the white ones (:func:`ring_and_jpeg_factors`;
    None: ``sources[0]``); ``size_exponent``: the Bayer camera's (None: fitted, :func:`size_fit`);
    ``bayer``: the Bayer effects its Bayer figures are fitted on; ``q95``: the dark- and white-ring
    results holding JPEG q95 beside q90 (:func:`jpeg_above`; None: no figure above q90);
    ``own_twin``: the white ring's Bayer JPEG figure over its own PNG twin (:func:`jpeg_table`)."""
    results = json.loads((RESULTS / sources[0]).read_text())["datasets"]
    bases = {s: basis(s, law) for s in scenes}
    tc = {s: measured(results, s, "three-chip") for s in scenes}
    p = nnls_relative(bases, tc)
    rows = ratio_rows("three-chip (fit)", {s: (tc[s], predicted(bases[s], p)) for s in scenes})
    for out in scenes:
        q = nnls_relative(bases, {s: tc[s] for s in scenes if s != out})
        rows += ratio_rows(f"three-chip, scene {out.upper()} left out", {out: (tc[out], predicted(bases[out], q))})
    k, g, jpeg, more = bayer_part(results, scenes, p, law, size_exponent, bayer)
    rows += more
    dark = None if ring_dark is None else json.loads((RESULTS / ring_dark).read_text())["datasets"]
    other = ring_and_jpeg_factors(results, sources, dark, scenes, bayer)
    versions = sorted(results)
    discs = [median_minor_px(load_config(ROOT / "bench" / "configs" / f"sensor_scene_{s}.toml"), 48) for s in scenes]
    jpeg_factor, provisional = jpeg_table(other, jpeg, own_twin)
    above = {} if q95 is None else {"95": jpeg_above(jpeg_factor, merged(sources[0], q95[0]),
                                                     merged(sources[1], q95[1]), 95)}
    return {"format": CARD_FORMAT, "scale_px": round(float(p[0]), 5),
            "shift_px": [round(float(p[1]), 5), round(float(p[2]), 5)],
            "cfa_factor": {"none": 1.0, "rggb": round(g, 3)},
            "cfa_size_exponent": {"none": 0.0, "rggb": k},
            "ring_factor": {"dark": {"none": 1.0, "rggb": 1.0},
                            "white": {c: round(v, 3) for c, v in other["ring_white"].items()}},
            "jpeg_factor": jpeg_factor, "jpeg_factor_above": above,
            "jpeg_min_quality": 90, "centre_noise": dict(vars(law)),
            "bound_factor": {c: 1.0 for c in ("x", "y", "z", "alpha", "beta", "gamma")},
            "provisional": provisional,
            "fitted_on": {"renders": versions, "frames_each": 48, "condition": "normal",
                          "weights": "yolov5n_se_rings_markers.pt",
                          "source": f"bench/results/sensor_effects/{sources[0]}",
                          "ring_and_jpeg_source": [f"bench/results/sensor_effects/{n}" for n in sources[1:]]
                          + ([f"bench/results/sensor_effects/{ring_dark}"] if ring_dark else [])
                          + [f"bench/results/sensor_effects/{n}" for n in q95 or ()],
                          "disc_minor_median_px": [round(min(discs), 2), round(max(discs), 2)],
                          "white_ring_scenes": other["white_scenes"], "bayer_effects": list(bayer), "components_checked": list(FIT),
                          **({"white_bayer_jpeg": "over its own PNG twin"} if own_twin else {})},
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
    ap.add_argument("--bayer-size", type=float, default=None, metavar="K",
                    help="the Bayer camera's size exponent (eval.design_noise.size_factors; 0: one factor "
                         "for every disc; default: fitted over SIZE_GRID)")
    ap.add_argument("--bayer-effects", default=",".join(BAYER),
                    help="the Bayer effects the Bayer figures are fitted on, comma-separated (default: %(default)s)")
    ap.add_argument("--sensor", default=None, metavar="WELLS",
                    help="results under bench/results/sensor_effects/ with the sensor's noise turned down beside the "
                         "reference (bench.design.sensor_share): the card's sensor_noise")
    ap.add_argument("--jpeg95", nargs=2, default=None, metavar=("DARK", "WHITE"),
                    help="results under bench/results/sensor_effects/ with JPEG q95 beside q90 on the dark- and "
                         "white-ring scenes: the card's figures above q90")
    ap.add_argument("--white-jpeg-own-twin", action="store_true",
                    help="the white ring's Bayer JPEG factor as its RMSE over its own PNG twin's (with --ring-dark "
                         "from another bench than SAMPLING; default: through the dark ring's JPEG factor)")
    ap.add_argument("--provisional", default="", metavar="NAME,NAME",
                    help="factors to mark provisional beside those the fit marks (a blind set missed them: "
                         "every design that uses one says so), comma-separated, e.g. ring_factor.white.none")
    args = ap.parse_args()
    law = LAW if args.law is None else CentreNoiseLaw(*(float(v) for v in args.law.split(",")))
    card = fit(tuple(args.sources), tuple(args.scenes.split(",")), args.ring_dark, law, args.bayer_size,
               tuple(args.bayer_effects.split(",")), args.jpeg95, args.white_jpeg_own_twin)
    print(f"scale {card['scale_px']} px, offset {card['shift_px']} px, "
          f"rggb x{card['cfa_factor']['rggb']} size exponent {card['cfa_size_exponent']['rggb']}, "
          f"jpeg x{card['jpeg_factor']} (provisional: {card['provisional']}), white ring x{card['ring_factor']['white']}")
    if card["jpeg_factor_above"]:
        print(f"jpeg above q90: {card['jpeg_factor_above']}")
    print("| what | scene | X | Y | alpha (predicted / measured) |\n| --- | --- | --- | --- | --- |")
    for r in card["error"]["predicted_over_measured"]:
        print(f"| {r['what']} | {r['scene'].upper()} | {r['x']:.2f} | {r['y']:.2f} | {r['alpha']:.2f} |")
    card["provisional"] += [n for n in args.provisional.split(",") if n and n not in card["provisional"]]
    if args.sensor:
        from bench.design.sensor_share import sensor_noise
        card["sensor_noise"], lines = sensor_noise(RESULTS / args.sensor)
        card["fitted_on"]["sensor_source"] = f"bench/results/sensor_effects/{args.sensor}"
        print("\n".join(lines))
    if args.write or args.card_out:
        write_json_atomic(args.card_out or ROOT / "models" / "design_predictor.json", card)


if __name__ == "__main__":
    main()
