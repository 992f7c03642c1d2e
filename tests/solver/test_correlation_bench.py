"""bench/cli/model_error_runs.py's correlation table (what the run bias field's length rests on): errors
drawn with a known structure give it back."""
from __future__ import annotations

import numpy as np
import pytest

from bench.cli import model_error_runs as mer


def _row_value(table: str, label: str) -> tuple[float, float]:
    line = next(ln for ln in table.splitlines() if ln.startswith(f"| {label}"))
    return tuple(float(v) for v in line.strip("|").split("|")[-2:])


def test_table_gives_back_a_known_correlation():
    """Pairs of A markers 50 px apart share half their y error's variance (correlation 0.5) and
    none of x; markers 1000 px apart are independent; one marker repeats 0.8 of its error over a
    run's two frames. Within 0.05 over 4000 frames; gross errors (over 0.8 px) are left out."""
    rng = np.random.default_rng(3)
    rows = []
    for k in range(4000):
        common = rng.normal(0, 0.1)
        near = [np.array([rng.normal(0, 0.1), np.sqrt(0.5) * (common + rng.normal(0, 0.1))]) for _ in range(2)]
        rows += [(k, None, "A0", np.array([100.0, 100.0]), near[0]),
                 (k, None, "A1", np.array([100.0, 150.0]), near[1]),
                 (k, None, "A2", np.array([1100.0, 150.0]), rng.normal(0, 0.1, 2))]
    rows.append((0, None, "A3", np.array([0.0, 0.0]), np.array([5.0, 5.0])))   # gross: left out
    persistent = rng.normal(0, 0.1, (2000, 2))
    for k in range(2000):
        for f in range(2):
            rows.append((f"r{k}_{f}", ("u", k), "B0", np.array([500.0, 500.0]),
                         np.sqrt(0.8) * persistent[k] + np.sqrt(0.2) * rng.normal(0, 0.1, 2)))
    table = mer.correlation_table(rows)
    x, y = _row_value(table, "same section, 0-100 px")
    assert x == pytest.approx(0.0, abs=0.05) and y == pytest.approx(0.5, abs=0.05)
    assert all(v == pytest.approx(0.0, abs=0.05) for v in _row_value(table, "same section, 400-100000 px"))
    assert all(v == pytest.approx(0.8, abs=0.05) for v in _row_value(table, "one marker, two frames of a run"))
