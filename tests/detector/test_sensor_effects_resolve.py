"""bench/sensor/sensor_effects.py ``--resolve``: a results file's rows solved again from their kept
detections (no detector) by the solver as it is now, on the painted smoke dataset: detections at
the labels' exact centres give poses within 0.05 mm / 0.005 deg of the truth on every test frame;
the file's other figures are rebuilt from the new rows; a file naming a dataset not given, or
written without rows, is one line."""
from __future__ import annotations

import json

import pytest

from bench.sensor import sensor_effects as se
from dockfactory.core.errors import DockfactoryError
from dockfactory.generator.datasets.reader import Dataset


def _rows_file(tmp_path, ds, with_rows=True):
    rows = []
    for fid in ds.frames("test"):
        dets = [{"class_id": m["class_id"], "center_px": m["outline_centroid_px"], "score": 1.0, "refined": True,
                 "bbox_px": m["bbox_px"]} for m in ds.labels[fid]["markers"] if m.get("visibility") == 2]
        rows.append({"frame": fid, "ok": False, "centres": [], "dets": dets, "used": None})
    effect = {"frames": len(rows), "solved": 0} | ({"rows": rows} if with_rows else {})
    path = tmp_path / "rows.json"
    path.write_text(json.dumps({"datasets": {f"{ds.config.dataset.name}@{ds.version_id}": {"three-chip": effect}}}))
    return path


def test_rows_are_solved_again_from_their_detections(painted_source, tmp_path):
    ds = Dataset.open(painted_source, full=False)
    out = se.resolved(str(_rows_file(tmp_path, ds)), [str(painted_source)], 0.02)
    res = next(iter(out["datasets"].values()))["three-chip"]
    assert res["solved"] == res["frames"] == len(ds.frames("test")) > 0
    assert all(r["ok"] and abs(r["err_x"]) < 0.05 and abs(r["err_alpha"]) < 0.005 for r in res["rows"])
    assert res["rmse_x"] < 0.05 and res["centre_median_px"] < 0.01


def test_a_file_the_datasets_do_not_match_or_without_rows_is_one_line(painted_source, tmp_path):
    ds = Dataset.open(painted_source, full=False)
    with pytest.raises(DockfactoryError, match="is not among the DATASET arguments"):
        se.resolved(str(_rows_file(tmp_path, ds)), [], 0.02)
    with pytest.raises(DockfactoryError, match="written without its rows"):
        se.resolved(str(_rows_file(tmp_path, ds, with_rows=False)), [str(painted_source)], 0.02)
