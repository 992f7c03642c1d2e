"""bench/paper_results.py: render figures of an interrupted render, Table 1 and the ranking check."""
import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from paper_results import main, ranking_check, render_figures, table1  # noqa: E402


def _rows(starts_and_counts, step=5.0, total=4.5):
    rows = []
    for start, count in starts_and_counts:
        rows += [{"finished_at": start + i * step, "total": total, "cycles": 4.0, "rss_mb": 600.0 + i}
                 for i in range(count)]
    return rows


def test_render_figures_leave_the_pauses_out():
    one = render_figures(_rows([(1000.0, 10)]))
    assert one["frames"] == 10 and one["segments"] == 1
    assert one["active_wall_s"] == pytest.approx(4.5 + 9 * 5.0)
    two = render_figures(_rows([(1000.0, 10), (90000.0, 10)]))   # resumed a day later
    assert two["segments"] == 2
    assert two["active_wall_s"] == pytest.approx(2 * (4.5 + 9 * 5.0))
    assert two["frames_per_hour"] == pytest.approx(3600 * 20 / two["active_wall_s"], rel=1e-3)
    assert two["peak_worker_rss_mb"] == 609.0


def _rec(att, seed, m50, m5095):
    return {"attention": att, "seed": seed, "mAP50": m50, "mAP50_95": m5095}


def test_table1_means_stds_and_the_ranking_in_sigmas():
    recs = [_rec("se", s, 0.99, v) for s, v in enumerate((0.84, 0.85, 0.86))]
    recs += [_rec("eca", s, 0.99, v) for s, v in enumerate((0.82, 0.83, 0.84))]
    recs += [_rec("none", 0, 0.98, 0.80)]
    t1 = table1(recs)
    assert t1["se"]["mAP50_95"]["mean"] == pytest.approx(0.85)
    assert t1["se"]["mAP50_95"]["std"] == pytest.approx(0.01)
    assert t1["none"]["mAP50_95"]["std"] is None             # one seed: no spread to quote
    pairs = ranking_check(t1)
    assert pairs[0]["pair"] == "se > eca" and pairs[0]["holds"]
    assert pairs[0]["sigmas"] == pytest.approx(2.0)          # 0.02 apart, pooled std 0.01
    assert [p["pair"] for p in pairs] == ["se > eca"]        # a2 has no runs: the pair is left out


def test_main_writes_what_it_has_and_marks_the_rest(tmp_path, capsys):
    ds = tmp_path / "ds"
    (ds / "logs").mkdir(parents=True)
    (ds / "logs" / "timings.jsonl").write_text("\n".join(json.dumps(r) for r in _rows([(0.0, 3)])) + "\n")
    rec = tmp_path / "t1"
    rec.mkdir()
    (rec / "se_seed0.json").write_text(json.dumps(_rec("se", 0, 0.99, 0.85)))
    assert main(["--dataset", str(ds), "--out", str(tmp_path / "out"), "--table1", str(rec)]) == 0
    doc = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert doc["dataset"]["complete"] is False and doc["render"]["frames"] == 3
    table = (tmp_path / "out" / "report.md").read_text()
    assert "| YOLOv5s + SE: mAP50:95 | 0.834 | 0.850 ± — (1 seeds) |" in table
    assert "| YOLOv5s + ECA: mAP50 | 0.995 | not run yet |" in table
    assert "localization alpha" in capsys.readouterr().out
