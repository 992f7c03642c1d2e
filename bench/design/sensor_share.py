"""The reference sensor's share of the centre variance, per camera class: the card's
``sensor_noise`` (eval.design_sensor), fitted on the sensor bench run with the sensor's temporal
noise turned down (deeper wells, the same DN) and through another sensor preset.

Input: a results file of bench.sensor.sensor_effects holding, per scene, the reference effect of a
camera class (``three-chip``, ``bayer-bilinear``) beside its variants (``<class>-wells4``,
``-wells100``, ``-imx174``: the effects' own sensors). Per scene and variant the centres' median
radial error m against the reference's m_ref; the share s by least squares of
m^2 / m_ref^2 - 1 = -s (1 - v / v_ref), v the sensors' relative temporal variance
(eval.design_sensor.relative_variance). Printed: s per class, each scene left out, and the pose
RMSE ratios beside the factor s predicts for them.

    python -m bench.design.sensor_share bench/results/sensor_effects/sensor_wells_abd_48.json
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from bench.sensor.sensor_effects import EFFECTS
from dockfactory.eval.design_sensor import relative_variance, sensor_factor

CLASSES = {"none": "three-chip", "rggb": "bayer-bilinear"}
VARIANTS = ("wells4", "wells100", "imx174")

__all__ = ["effect_variance", "share_points", "fit_share", "sensor_noise"]


def effect_variance(effect: str) -> float:
    """Relative temporal variance of the bench effect's sensor."""
    s = EFFECTS[effect][0](0).sensor
    return relative_variance(s.saturation_e, s.dark_noise_e, s.gain_dn_per_e)


def _median_radial(res: dict) -> float:
    c = np.array([x for r in res["rows"] for x in r["centres"]], dtype=float).reshape(-1, 3)
    return float(np.median(np.hypot(c[:, 1], c[:, 2])))


def share_points(datasets: dict, cfa: str) -> list[dict]:
    """Per scene and variant of class ``cfa``: scene, variant, v / v_ref, the measured centre
    variance ratio and the pose RMSE ratios (x, y, alpha)."""
    ref = CLASSES[cfa]
    cls = "three-chip" if cfa == "none" else "bayer"
    v_ref = effect_variance(ref)
    out = []
    for key, effects in datasets.items():
        for var in VARIANTS:
            name = f"{cls}-{var}"
            if name not in effects or ref not in effects:
                continue
            out.append({"scene": key.split("@")[0], "variant": var, "v_ratio": effect_variance(name) / v_ref,
                        "centre_var_ratio": (_median_radial(effects[name]) / _median_radial(effects[ref])) ** 2,
                        **{c: effects[name][f"rmse_{c}"] / effects[ref][f"rmse_{c}"] for c in ("x", "y", "alpha")}})
    return out


def fit_share(points: list[dict]) -> float:
    """The least-squares share in [0, 1] of ``points`` (:func:`share_points`); 0 without points."""
    a = np.array([-(1.0 - p["v_ratio"]) for p in points])
    b = np.array([p["centre_var_ratio"] - 1.0 for p in points])
    return 0.0 if not a.size else float(np.clip(a @ b / (a @ a), 0.0, 1.0))


def sensor_noise(path: Path, reference: str = "imx273") -> tuple[dict, list[str]]:
    """(the card's ``sensor_noise`` table fitted on results file ``path``, the printed lines)."""
    datasets = json.loads(Path(path).read_text())["datasets"]
    shares, lines = {}, []
    for cfa in CLASSES:
        pts = share_points(datasets, cfa)
        shares[cfa] = round(fit_share(pts), 3)
        scenes = sorted({p["scene"] for p in pts})
        left = ", ".join(f"{s} out {fit_share([p for p in pts if p['scene'] != s]):.3f}" for s in scenes)
        lines.append(f"{CLASSES[cfa]}: share {shares[cfa]} ({left})")
        lines.append("| scene | variant | v / v_ref | centre var ratio | factor predicted | X / Y / alpha RMSE ratio |")
        lines.append("| --- | --- | --- | --- | --- | --- |")
        for p in pts:
            lines.append(f"| {p['scene']} | {p['variant']} | {p['v_ratio']:.3f} | {p['centre_var_ratio']:.3f} | "
                         f"{sensor_factor(shares[cfa], p['v_ratio']):.3f} | {p['x']:.2f} / {p['y']:.2f} / {p['alpha']:.2f} |")
    return {"reference": reference, "share": shares}, lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", type=Path)
    args = ap.parse_args(argv)
    table, lines = sensor_noise(args.results)
    print("\n".join(lines))
    print(json.dumps(table))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
