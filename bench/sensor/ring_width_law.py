"""The ring's width in a refined centre's noise: at the same disc image, is a larger disc (a thinner
ring: the factory's ring is RING_EXTRA_MM wide whatever the disc) noisier?

    python -m bench.sensor.ring_width_law ROWS.json [ROWS.json ...] --datasets DIR [DIR ...] [--effects three-chip,bayer-vng] [--json OUT]

Each ROWS.json a ``bench.sensor.sensor_effects`` output with its rows; DIR the sensor scenes they
were run on (their labels and configs: the disc diameter). Errors as bench.sensor.disc_noise_law
takes them (about each section's mean in the frame, gross errors left out), each dataset's top
percent of squared errors left out too. Per effect, over every
dataset together with one common scale (what a law must do: the same scale whatever the
geometry), the Gaussian likelihood of three laws of the variance per axis: the solver's (b alone,
shipped constants), the best in b alone, and the best of eval.design_noise.CentreNoiseLaw (b and
the ring's width w across the minor axis, px); and each dataset's scale over the common one under
each (1 for all: the law carries the geometry). The grid's best (b, w) law of the first effect is
what the design predictor's card takes (bench/design/design_fit.py, ``LAW``).
"""
from __future__ import annotations

import argparse
import itertools

import numpy as np

from bench.sensor.disc_noise_law import GRID_FLOOR, GRID_P, inputs, law_data
from dockfactory.eval.design_noise import CentreNoiseLaw, ring_width_px
from dockfactory.solver.disc_noise import MINOR_EXPONENT, NOISE_FLOOR

GRID_C = (0.0, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0)
GRID_K = (1.0, 2.0, 3.0, 4.0)
TRIM = 0.99   # each dataset's markers above this quantile of squared error left out (a few gross centres a
              # Gaussian likelihood would be ruled by; the same share of every dataset)


def effect_data(rows_files: list[str], roots: list[str], effect: str) -> list[tuple[str, np.ndarray]]:
    """[(dataset name, (n, 3) rows: minor px, ring width px, squared error per axis px^2)] of
    ``effect`` in every ROWS file, refined centres only (a centre the refinement refused is the
    detector's box centre: another noise)."""
    out = []
    for path in rows_files:
        items = [(n, ds, eff, [dict(r, dets=[d for d in r["dets"] if d.get("refined")]) for r in rows])
                 for n, ds, eff, rows in inputs(path, roots) if eff == effect]   # refined centres only
        for name, d in law_data(items).items():
            ds = next(it[1] for it in items if it[0] == name)
            w = ring_width_px(d[:, 0], ds.config.markers.diameter_mm)
            label = f"{name.split()[0]}@{ds.version_id[:6]} d{ds.config.markers.diameter_mm:g}"
            e2 = 0.5 * (d[:, 1] ** 2 + d[:, 2] ** 2)
            keep = e2 <= np.quantile(e2, TRIM)
            out.append((label, np.c_[d[:, 0], w, e2][keep]))
    return out


def fit_of(data: list[tuple[str, np.ndarray]], law: CentreNoiseLaw) -> dict:
    """{nll: mean negative log-likelihood (per marker, constants dropped) at the common scale,
    scale_px, relative: {dataset: its own scale over the common one}}."""
    v = [law.variance(d[:, 0], d[:, 1]) for _, d in data]
    q = np.concatenate([d[:, 2] / vi for (_, d), vi in zip(data, v)])
    s2 = float(q.mean())
    nll = float(np.mean(np.log(s2 * np.concatenate(v)) + q / s2))
    rel = {n: round(float(np.sqrt(np.mean(d[:, 2] / vi) / s2)), 3) for (n, d), vi in zip(data, v)}
    return {"nll": nll, "scale_px": float(np.sqrt(s2)), "relative": rel}


def best_fit(data, grid) -> tuple[CentreNoiseLaw, dict]:
    """The law of ``grid`` (CentreNoiseLaw iterable) of least :func:`fit_of` nll, and its fit."""
    return min(((law, fit_of(data, law)) for law in grid), key=lambda lf: lf[1]["nll"])


def laws_of(data) -> dict:
    """{"solver": ..., "minor only": ..., "minor and ring": ...}: each law and its fit."""
    shipped = CentreNoiseLaw(MINOR_EXPONENT, NOISE_FLOOR, 0.0, 1.0)
    minor = best_fit(data, (CentreNoiseLaw(p, f, 0.0, 1.0) for p in GRID_P for f in GRID_FLOOR))
    ring = best_fit(data, (CentreNoiseLaw(p, f, c, k) for p, f, c, k in
                           itertools.product(GRID_P, GRID_FLOOR, GRID_C, GRID_K)))
    return {"solver": (shipped, fit_of(data, shipped)), "minor only": minor, "minor and ring": ring}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("rows", nargs="+")
    ap.add_argument("--datasets", nargs="+", required=True)
    ap.add_argument("--effects", default="three-chip,bayer-vng")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    out = {}
    print("| effect | law | minor exponent, floor, ring coefficient, ring exponent | nll | each dataset's scale / the common one |")
    print("| --- | --- | --- | --- | --- |")
    for effect in args.effects.split(","):
        data = effect_data(args.rows, args.datasets, effect)
        out[effect] = {}
        for name, (law, f) in laws_of(data).items():
            out[effect][name] = {"law": vars(law), **f}
            rel = ", ".join(f"{k} {v:.2f}" for k, v in f["relative"].items())
            print(f"| {effect} | {name} | {law.minor_exponent:g}, {law.floor:g}, {law.ring_coefficient:g}, "
                  f"{law.ring_exponent:g} | {f['nll']:.4f} | {rel} |")
    if args.json:
        from dockfactory.core.io import write_json_atomic
        write_json_atomic(args.json, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
