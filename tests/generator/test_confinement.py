"""Issue 10, finding 5: writes and reads stay inside the dataset.

- frame ids and split names from label files are checked against the dataset's plan before any
  export path is built (a label with ``split = "../../../../outside"`` or a foreign frame id is
  refused, nothing is written outside the dataset);
- ``dataset verify`` refuses manifest entries outside the dataset (absolute paths, ``..``) without
  reading them, and reports symlinks inside the dataset (to outside, dangling, or replacing a
  listed file) as problems.

No rendering: the export dataset of tests/generator/test_exports.py and the painted smoke dataset of
tests/pipeline_data.py.
"""
import hashlib
import json
import os
import shutil
from pathlib import Path

import pytest
from test_exports import write_dataset

from dockfactory.generator.datasets import tools as dt
from dockfactory.generator.datasets.folder import DatasetError


@pytest.fixture(scope="module")
def export_source(tmp_path_factory):
    return write_dataset(tmp_path_factory.mktemp("confine-src") / "ds")


@pytest.fixture
def export_ds(export_source, tmp_path):
    root = tmp_path / "ds"
    shutil.copytree(export_source, root)
    return root


def _edit_label(root, frame_id, edit):
    path = root / "labels" / f"{frame_id}.json"
    label = json.loads(path.read_text())
    edit(label)
    path.write_text(json.dumps(label))


def _files_under(folder):
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*")) if folder.exists() else []


ESCAPE = "../../../../outside"   # from exports/<tmp>/images/<split>/ up to the dataset's parent


def _set_split(label):
    label["spec"]["split"] = ESCAPE


def _set_frame_id(label):
    label["frame_id"] = ESCAPE + "/evil"


def _set_foreign_split(label):
    label["spec"]["split"] = "val" if label["spec"]["split"] != "val" else "train"


@pytest.mark.parametrize("fmt", ["yolo", "bop", "coco"])
@pytest.mark.parametrize("edit", [_set_split, _set_frame_id, _set_foreign_split], ids=["split", "frame_id", "other_split"])
def test_export_refuses_labels_whose_id_or_split_is_not_the_plans(export_ds, tmp_path, fmt, edit):
    """Finding 5: a tampered label's split or frame id never becomes a path."""
    _edit_label(export_ds, "000001", edit)
    before = set(_files_under(tmp_path))
    with pytest.raises(DatasetError, match="000001"):
        dt.export(export_ds, fmt)
    assert not (tmp_path / "outside").exists()
    new = {p for p in set(_files_under(tmp_path)) - before if not p.startswith("ds/logs") and p != "ds/exports"}
    assert not new, new   # nothing written anywhere (no partial export either)


def test_export_refuses_a_stray_label_not_in_the_plan(export_ds):
    src = export_ds / "labels" / "000001.json"
    label = json.loads(src.read_text())
    label["frame_id"] = "999999"
    (export_ds / "labels" / "999999.json").write_text(json.dumps(label))
    with pytest.raises(DatasetError, match="999999"):
        dt.export(export_ds, "yolo")


def test_export_refuses_an_image_that_is_a_symlink(export_ds, tmp_path):
    outside = tmp_path / "secret.png"
    outside.write_bytes(b"not yours")
    img = export_ds / "images" / "000002.png"
    img.unlink()
    img.symlink_to(outside)
    with pytest.raises(DatasetError, match="symlink"):
        dt.export(export_ds, "coco")


def test_a_clean_export_still_works(export_ds):
    out = dt.export(export_ds, "yolo")
    assert (out / "data.yaml").is_file()


# ----------------------------------------------------------------------------- verify

def _manifest_add(root, rec):
    path = root / "manifest.json"
    m = json.loads(path.read_text())
    m["files"].append(rec)
    path.write_text(json.dumps(m))


@pytest.mark.parametrize("entry", ["/etc/passwd", "../outside.txt", "images/../../outside.txt"])
def test_verify_refuses_manifest_entries_outside_the_dataset(painted, tmp_path, entry):
    """Finding 5: a manifest entry outside the dataset is a problem, and it is not read."""
    (tmp_path / "outside.txt").write_text("x\n")
    target = "/etc/passwd" if entry.startswith("/") else str(tmp_path / "outside.txt")
    data = Path(target).read_bytes()
    _manifest_add(painted, {"path": entry, "bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()})
    report = dt.verify(painted)
    assert not report.ok
    assert entry in report.text() and "outside the dataset" in report.text()


def test_verify_of_the_clean_painted_dataset_is_ok(painted):
    report = dt.verify(painted)
    assert report.ok, report.text()


def test_verify_reports_a_symlink_to_outside(painted):
    (painted / "etc").symlink_to("/etc")
    report = dt.verify(painted)
    assert not report.ok and "etc" in report.text() and "symlink" in report.text()


def test_verify_reports_a_dangling_label_symlink(painted):
    (painted / "labels" / "999999.json").symlink_to(painted / "labels" / "nowhere.json")
    report = dt.verify(painted)
    assert not report.ok and "labels/999999.json" in report.text() and "symlink" in report.text()


def test_verify_reports_a_listed_file_replaced_by_a_symlink_with_the_same_bytes(painted, tmp_path):
    """The bytes match the manifest, but the file lives outside the dataset."""
    label = painted / "labels" / "000001.json"
    copy = tmp_path / "elsewhere.json"
    shutil.copyfile(label, copy)
    label.unlink()
    os.symlink(copy, label)
    report = dt.verify(painted)
    assert not report.ok and "labels/000001.json" in report.text() and "symlink" in report.text()


def test_frame_done_ignores_meta_records_outside_the_frame(painted):
    """A tampered meta record cannot make render stat (or the manifest list) a file elsewhere."""
    from dockfactory.generator.datasets.folder import frame_done
    meta = painted / "meta" / "000001.json"
    rec = json.loads(meta.read_text())
    assert frame_done(painted, "000001", keep_exr=True)
    rec["files"]["image"]["path"] = "/etc/passwd"
    rec["files"]["image"]["bytes"] = os.stat("/etc/passwd").st_size
    meta.write_text(json.dumps(rec))
    assert not frame_done(painted, "000001", keep_exr=True)
