"""Dataset.open, the one dataset contract: what it returns and what it checks (the damage x
consumer matrix is tests/contracts/test_dataset_contract.py)."""
import json

import pytest

from dockfactory.generator.datasets.folder import DatasetError
from dockfactory.generator.datasets.check import verify
from dockfactory.generator.datasets.reader import Dataset


def test_frames_are_the_plans_in_plan_order(painted_source):
    ds = Dataset.open(painted_source)
    manifest = json.loads((painted_source / "manifest.json").read_text())
    assert ds.frames() == [f["frame_id"] for f in manifest["frames"]] == [s.frame_id for s in ds.plan]
    assert ds.frames("repeat") == ["rep000_00", "rep000_01"]
    assert set(ds.frames(("test", "repeat"))) == set(ds.frames("test")) | set(ds.frames("repeat"))
    assert [lab["frame_id"] for lab in ds.labels_of("test")] == ds.frames("test")
    assert "999999" not in ds.labels and len(ds.labels) == len(ds.plan)
    with pytest.raises(KeyError):
        ds.labels["999999"]
    with pytest.raises(DatasetError, match="not a frame of this dataset"):
        ds.image_path("999999")


def test_a_label_changed_after_open_is_refused_when_read(painted):
    ds = Dataset.open(painted)
    path = painted / "labels" / f"{ds.frames('test')[0]}.json"
    path.write_text(path.read_text().replace('"frame_id"', '"frame_id" ', 1))
    with pytest.raises(DatasetError, match="changed since the dataset was finished"):
        ds.labels_of("test")


def test_full_hashes_images_and_the_cheap_check_compares_their_sizes(painted):
    """An image whose bytes change but not its size (a flipped byte, or two images of one size
    swapped): only the full check, every command's, sees it."""
    image = painted / "images" / f"{Dataset.open(painted).frames('test')[0]}.png"
    data = bytearray(image.read_bytes())
    data[len(data) // 2] ^= 0xFF
    image.write_bytes(bytes(data))
    Dataset.open(painted, full=False)
    with pytest.raises(DatasetError, match="corrupt.*sha256"):
        Dataset.open(painted)


def test_an_edited_config_does_not_give_its_version_id(painted):
    path = painted / "dataset.json"
    ident = json.loads(path.read_text())
    ident["config"]["labels"]["visible_threshold"] = 0.25
    path.write_text(json.dumps(ident, indent=1))
    report = verify(painted)
    assert any(what == "dataset.json" and "give version" in why for what, why in report.inconsistent), report.text()
    with pytest.raises(DatasetError, match="inconsistent: dataset.json"):
        Dataset.open(painted)


def test_a_self_consistent_manifest_without_a_frame_disagrees_with_the_plan(painted):
    path = painted / "manifest.json"
    m = json.loads(path.read_text())
    gone = m["frames"][1]["frame_id"]
    m["frames"] = [f for f in m["frames"] if f["frame_id"] != gone]
    m["files"] = [f for f in m["files"] if gone not in f["path"]]
    path.write_text(json.dumps(m))
    for rel in (f"images/{gone}.png", f"labels/{gone}.json", f"meta/{gone}.json"):
        (painted / rel).unlink()
    with pytest.raises(DatasetError, match=f"frame {gone} of the plan is not listed"):
        Dataset.open(painted)


def test_not_a_directory_and_incomplete(painted, tmp_path):
    with pytest.raises(DatasetError, match="no such dataset directory"):
        Dataset.open(tmp_path / "nowhere")
    (painted / "manifest.json").unlink()
    with pytest.raises(DatasetError, match="not complete"):
        Dataset.open(painted)


def _rewrite_identity(root, edit) -> None:
    """Apply ``edit`` to dataset.json as an older dockfactory would have written it (its version id
    recomputed from the stored config), and re-seal the manifest's record of it."""
    from dockfactory.core.io import sha256_file
    from dockfactory.generator.version import dataset_version_id
    path = root / "dataset.json"
    ident = json.loads(path.read_text())
    edit(ident)
    canonical = json.dumps(ident["config"], sort_keys=True, separators=(",", ":"))
    ident["version_id"] = dataset_version_id(canonical, ident["blender_version"], ident["generator_version"])
    path.write_text(json.dumps(ident, indent=1) + "\n")
    m = json.loads((root / "manifest.json").read_text())
    m["version_id"] = ident["version_id"]
    for rec in m["files"]:
        if rec["path"] == "dataset.json":
            rec.update(bytes=path.stat().st_size, sha256=sha256_file(path))
    (root / "manifest.json").write_text(json.dumps(m))


def test_a_dataset_of_an_older_generator_and_config_schema_still_opens(painted):
    """Datasets outlive the code: one written by another generator version, whose stored config
    lacks a key a later schema added with its default, opens (its frames are still its config's)."""
    from dockfactory.core.config import config_from_dict
    defaults = config_from_dict({}).to_dict()

    def older(ident):
        ident["generator_version"] = "0.0.1+oldsource0000"
        section = next(k for k, v in ident["config"].items() if isinstance(v, dict)
                       and any(v[f] == defaults[k].get(f) for f in v))
        key = next(f for f, v in ident["config"][section].items() if v == defaults[section].get(f))
        del ident["config"][section][key]
    _rewrite_identity(painted, older)
    ds = Dataset.open(painted)
    assert ds.identity["generator_version"].startswith("0.0.1") and len(ds.labels_of()) == len(ds.plan)


def test_this_generators_manifest_must_carry_the_plans_splits(painted):
    m = json.loads((painted / "manifest.json").read_text())
    f = next(f for f in m["frames"] if f["split"] == "train")
    f["split"] = "test"
    (painted / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(DatasetError, match=f"frame {f['frame_id']}: split or condition differ"):
        Dataset.open(painted)
