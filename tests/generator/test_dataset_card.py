"""The dataset card (README.md, Hugging Face front matter) and its hf/ view: written when a
dataset completes and by ``dataset card``, outside the manifest, loaded by ``datasets`` (the
``hf`` test extra) with every split, ``repeat`` included, and the label fields."""
import importlib.util
import json

import numpy as np
import pytest
import yaml
from cli_run import one_line_error, run_cli

from dockfactory.core.config import ConfigError, load_config
from dockfactory.core.resources import shipped_config
from dockfactory.generator import render_job
from dockfactory.generator.datasets.card import card_text, size_category
from dockfactory.generator.datasets.check import verify
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.render_job import JobOptions, run_render

SMOKE_SPLITS = {"train": 4, "test": 4, "repeat": 2}   # the smoke config: val_fraction leaves no val frame


def _no_render(*args, **kwargs):
    raise AssertionError("rendered although the dataset is complete")


def front_matter(root) -> dict:
    text = (root / "README.md").read_text()
    assert text.startswith("---\n")
    return yaml.safe_load(text.split("---\n")[1])


def test_a_completed_render_writes_the_card_outside_the_manifest(painted, monkeypatch):
    monkeypatch.setattr(render_job, "_render", _no_render)
    config = shipped_config("smoke")
    manifest = (painted / "manifest.json").read_bytes()
    summary = run_render(load_config(config), painted, config.read_text(), JobOptions(progress=False))
    assert summary.ok and (painted / "README.md").is_file()
    assert (painted / "manifest.json").read_bytes() == manifest   # the card is not content
    listed = {rec["path"] for rec in json.loads(manifest)["files"]}
    assert not any(p.startswith(("hf/", "README")) for p in listed)
    assert verify(painted).ok
    meta = front_matter(painted)
    assert meta["license"] == "cc-by-4.0" and meta["size_categories"] == ["n<1K"]
    assert {"object-detection", "keypoint-detection"} <= set(meta["task_categories"])
    files = {c["split"]: c["path"] for c in meta["configs"][0]["data_files"]}
    assert files == {"train": "hf/train/**", "test": "hf/test/**", "repeat": "hf/repeat/**"}
    for split, n in SMOKE_SPLITS.items():
        assert len((painted / "hf" / split / "metadata.jsonl").read_text().splitlines()) == n
        assert len(list((painted / "hf" / split).glob("*.png"))) == n
    body = (painted / "README.md").read_text()
    ds = Dataset.open(painted)
    for words in (ds.version_id, ds.identity["generator_version"], "| repeat (repeat) | 2 |", "## Camera units",
                  "## Label conventions", "dockfactory dataset verify", "(0, 0) is the centre of the top-left pixel"):
        assert words in body, words


def test_card_command_is_idempotent_and_takes_a_licence(painted, capsys):
    code, out, _ = run_cli(["dataset", "card", painted], capsys)
    assert code == 0 and out.strip() == str(painted / "README.md")
    stamp = {p: p.stat().st_mtime_ns for p in [painted / "README.md", *(painted / "hf").rglob("*")]}
    assert run_cli(["dataset", "card", painted], capsys)[0] == 0
    assert {p: p.stat().st_mtime_ns for p in stamp} == stamp          # nothing rewritten
    assert run_cli(["dataset", "card", painted, "--license", "cc0-1.0"], capsys)[0] == 0
    assert front_matter(painted)["license"] == "cc0-1.0" and verify(painted).ok
    code, _, err = run_cli(["dataset", "card", painted, "--license", "CC BY"], capsys)
    assert code == 2 and "--license 'CC BY'" in one_line_error(err)


def test_a_damaged_dataset_gets_no_card(painted, capsys):
    (painted / "labels" / "000001.json").write_text("{}")
    code, _, err = run_cli(["dataset", "card", painted], capsys)
    assert code == 2 and "damaged dataset" in one_line_error(err) and not (painted / "README.md").exists()


def test_the_licence_comes_from_the_config(tmp_config):
    assert load_config(tmp_config("[dataset]\nlicense = \"mit\"\n")).dataset.license == "mit"
    with pytest.raises(ConfigError, match=r"\[dataset\] license|dataset.*license"):
        load_config(tmp_config("[dataset]\nlicense = \"Creative Commons\"\n"))


def test_size_categories():
    assert [size_category(n) for n in (0, 999, 1000, 3200, 10_000, 2_000_000)] == [
        "n<1K", "n<1K", "1K<n<10K", "1K<n<10K", "10K<n<100K", "1M<n<10M"]


def test_card_text_names_only_the_splits_that_have_frames(painted_source):
    meta = yaml.safe_load(card_text(Dataset.open(painted_source)).split("---\n")[1])
    assert [c["split"] for c in meta["configs"][0]["data_files"]] == ["train", "test", "repeat"]


@pytest.mark.skipif(importlib.util.find_spec("datasets") is None,
                    reason="datasets is not installed (pip install '.[hf]')")
def test_hugging_face_datasets_loads_every_split_and_the_labels(painted, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setenv("HF_DATASETS_OFFLINE", "1")
    assert run_cli(["dataset", "card", painted], capsys)[0] == 0
    from datasets import load_dataset
    by_card = load_dataset(str(painted), cache_dir=str(tmp_path / "cache"))
    files = {"train": "hf/train/**", "test": "hf/test/**", "repeat": "hf/repeat/**"}
    by_folder = load_dataset("imagefolder", data_dir=str(painted), data_files=files, cache_dir=str(tmp_path / "c2"))
    ds = Dataset.open(painted)
    sha = {rec["path"]: rec["sha256"] for rec in ds.manifest["files"]}
    category = by_card["train"].features["objects"]["category"].feature   # the card declares the features
    assert type(category).__name__ == "ClassLabel" and category.names == ["RedA", "BlueB"]
    assert by_card["train"].features["objects"]["marker_id"] == by_folder["train"].features["objects"]["marker_id"]
    for loaded in (by_card, by_folder):
        assert {k: len(v) for k, v in loaded.items()} == SMOKE_SPLITS
        for split, rows in loaded.items():
            for row in rows:
                label = ds.labels[row["frame_id"]]
                assert row["split"] == split == label["spec"]["split"] and row["image"].size == (320, 240)
                assert np.allclose(row["K"], label["camera"]["K"], atol=0, rtol=0)
                assert row["pose"]["alpha_deg"] == label["pose_b_in_d"]["alpha_deg"]
                boxed = [m for m in label["markers"] if m["bbox_px"] is not None]
                assert row["objects"]["marker_id"] == [m["id"] for m in boxed]
                x0, y0, x1, y1 = boxed[0]["bbox_px"]
                assert row["objects"]["bbox"][0] == pytest.approx([x0 + 0.5, y0 + 0.5, x1 - x0, y1 - y0], abs=1e-12)
                assert row["objects"]["center_px"][0] == boxed[0]["center_px"]
                assert row["label_sha256"] == sha[row["label_file"]]


@pytest.fixture
def lens_dataset(tmp_path):
    """Two camera units (distortion, JPEG) and all four splits, val included (6 painted frames)."""
    from pipeline_data import LENS_CHECK, write_painted_dataset
    config = tmp_path / "lens.toml"
    config.write_text(LENS_CHECK.replace("[dataset]", "[dataset]\nval_fraction = 0.5\ntrain_fraction = 0.75\n"
                                         "license = \"cc0-1.0\"")
                      + "[repeatability]\nposes = 1\ncaptures = 2\n")
    root = tmp_path / "lens"
    write_painted_dataset(root, config)
    return root


def test_every_split_and_every_camera_unit(lens_dataset, tmp_path, monkeypatch, capsys):
    assert run_cli(["dataset", "card", lens_dataset], capsys)[0] == 0
    meta = front_matter(lens_dataset)
    assert meta["license"] == "cc0-1.0"
    assert [c["split"] for c in meta["configs"][0]["data_files"]] == ["train", "validation", "test", "repeat"]
    text = (lens_dataset / "README.md").read_text()
    units = [ln for ln in text.splitlines() if ln.endswith("| generic noise model | none |")]
    assert [ln.split(" | ")[0] for ln in units] == ["| 0", "| 1"]                 # one row per unit
    assert sum(int(ln.split(" | ")[1]) for ln in units) == 6                      # their frames
    assert all(" | none | generic" not in ln for ln in units)                    # both have a JPEG quality
    if importlib.util.find_spec("datasets") is None:
        pytest.skip("datasets is not installed (pip install '.[hf]')")
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    from datasets import load_dataset
    loaded = load_dataset(str(lens_dataset), cache_dir=str(tmp_path / "cache"))
    assert {k: len(v) for k, v in loaded.items()} == {"train": 1, "validation": 2, "test": 1, "repeat": 2}
    row = loaded["validation"][0]
    assert row["split"] == "val" and row["dist_coeffs"][0] < -0.09 and row["camera_unit"] in (0, 1)
