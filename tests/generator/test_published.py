"""A re-render checked against a published manifest (generator.datasets.published; issue 13).

The published dataset is the painted smoke dataset (tests/pipeline_data.py, no Blender); a
"re-render" is a copy of some of its frames without the manifest, as ``dockfactory render
--frames`` leaves it, then damaged in the ways another machine or an edit would.
"""
import json
import shutil

import cv2
import numpy as np
import pytest

from dockfactory.cli import main
from dockfactory.generator.datasets import published
from dockfactory.generator.datasets.folder import DatasetError
from dockfactory.generator.datasets.fingerprints import read_fingerprints_v2
from dockfactory.generator.datasets.label_prints import index_difference, index_measurements, label_core_sha256


def test_publish_copies_the_manifest_and_fingerprints_every_image(painted_source, tmp_path):
    pub = tmp_path / "pub"
    msg = published.publish(painted_source, pub)
    assert (pub / "manifest.json").read_bytes() == (painted_source / "manifest.json").read_bytes()
    manifest = json.loads((pub / "manifest.json").read_text())
    with np.load(pub / published.FINGERPRINTS_NAME, allow_pickle=False) as z:
        assert list(z["frame_ids"]) == [f["frame_id"] for f in manifest["frames"]]
        img = cv2.imread(str(painted_source / "images" / f"{manifest['frames'][0]['frame_id']}.png"))
        h, w = img.shape[:2]
        assert z["tiles"].shape[1:] == (-(-h // 80), -(-w // 80), 3)
        assert z["tiles"][0, 0, 0, 0] == pytest.approx(img[:80, :80, 0].mean(), abs=1e-3)
        assert len(z["label_geometry"]) == len(manifest["frames"]) and len(str(z["label_geometry"][0])) == 64
    assert f"published {len(manifest['frames'])} frames" in msg


def test_publish_refuses_a_damaged_dataset_and_writes_nothing(painted, tmp_path):
    next((painted / "images").glob("*.png")).unlink()
    with pytest.raises(DatasetError, match="missing: images/"):
        published.publish(painted, tmp_path / "pub")
    assert not (tmp_path / "pub").exists()


def test_a_faithful_subset_passes_byte_for_byte(release):
    pub, sub, ids = release
    rep = published.verify_against(sub, pub / "manifest.json")
    assert rep.ok, rep.text()
    assert (rep.frames, rep.labels_identical, rep.images_identical, rep.images_within) == (3, 3, 3, 0)


def test_a_label_whose_image_measurements_differ_passes_on_its_geometry(release):
    pub, sub, ids = release
    path = sub / "labels" / f"{ids[0]}.json"
    label = json.loads(path.read_text())
    measured = [m for m in label["markers"] if m.get("chroma") is not None]
    assert measured
    measured[0]["chroma"] += 0.004                      # another CPU's pixels: another chroma
    label["derived"]["auto_exposure_scale"] *= 1.0001
    path.write_text(json.dumps(label, indent=1) + "\n")
    rep = published.verify_against(sub, pub / "manifest.json")
    assert rep.ok and (rep.labels_identical, rep.labels_geometry) == (2, 1), rep.text()
    measured[0]["center_px"][0] += 0.001                # a geometric field: a real difference
    path.write_text(json.dumps(label, indent=1) + "\n")
    rep = published.verify_against(sub, pub / "manifest.json")
    assert f"labels/{ids[0]}.json: differs from the manifest beyond its image and index-pass measurements" \
        in rep.problems


def test_an_image_with_other_bits_passes_within_the_tolerance_and_fails_beyond(release):
    pub, sub, ids = release
    path = sub / "images" / f"{ids[0]}.png"
    img = cv2.imread(str(path))
    noise = np.random.default_rng(0).integers(-1, 2, img.shape)     # +-1 level: another CPU's bits
    cv2.imwrite(str(path), np.clip(img.astype(int) + noise, 0, 255).astype(np.uint8))
    rep = published.verify_against(sub, pub / "manifest.json")
    assert rep.ok and (rep.images_identical, rep.images_within) == (2, 1), rep.text()
    assert 0 < rep.max_tile_diff < 0.1
    img[100:160, 200:260] = 0                                        # a changed region: not noise
    cv2.imwrite(str(path), img)
    rep = published.verify_against(sub, pub / "manifest.json")
    assert not rep.ok
    assert any(p.startswith(f"images/{ids[0]}.png: tile means differ") for p in rep.problems), rep.text()


def test_an_edited_label_a_foreign_frame_and_another_version_fail(release):
    pub, sub, ids = release
    label = sub / "labels" / f"{ids[1]}.json"
    label.write_text(label.read_text().replace("0", "1", 1))
    shutil.copy(sub / "labels" / f"{ids[2]}.json", sub / "labels" / "999999.json")
    rep = published.verify_against(sub, pub / "manifest.json")
    assert f"labels/{ids[1]}.json: differs from the manifest beyond its image and index-pass measurements" \
        in rep.problems
    assert "labels/999999.json: frame 999999 is not in the manifest" in rep.problems
    ident = json.loads((sub / "dataset.json").read_text())
    # another generator alone (same config and Blender): the frames are still compared, and the
    # edited label still fails; another Blender or another config: refused before any frame
    ident.update(version_id="0" * 16, generator_version="9.9.9+0000000000000000")
    (sub / "dataset.json").write_text(json.dumps(ident))
    rep = published.verify_against(sub, pub / "manifest.json")
    assert rep.frames == len(ids) and "generator 9.9.9+0000000000000000" in rep.notes[0]
    assert f"labels/{ids[1]}.json: differs from the manifest beyond its image and index-pass measurements" \
        in rep.problems
    for key, value, why in (("blender_version", "4.2.0", "another Blender: 4.2.0"),
                            ("config", {**ident["config"], "dataset": {**ident["config"]["dataset"], "seed": 1}},
                             "another config")):
        (sub / "dataset.json").write_text(json.dumps({**ident, key: value}))
        rep = published.verify_against(sub, pub / "manifest.json")
        assert not rep.ok and rep.frames == 0 and why in rep.problems[0], rep.problems


def test_an_image_without_fingerprints_cannot_pass_on_tolerance(release):
    pub, sub, ids = release
    (pub / published.FINGERPRINTS_NAME).unlink()
    path = sub / "images" / f"{ids[0]}.png"
    img = cv2.imread(str(path))
    img[0, 0, 0] ^= 1
    cv2.imwrite(str(path), img)
    rep = published.verify_against(sub, pub / "manifest.json")
    assert not rep.ok and "no fingerprint to compare it with" in rep.problems[0]


def test_cli_verify_manifest_exit_status(release, capsys):
    pub, sub, ids = release
    assert main(["dataset", "verify", str(sub), "--manifest", str(pub / "manifest.json")]) == 0
    assert "3 frames checked: labels 3/3 byte for byte" in capsys.readouterr().out
    (sub / "images" / f"{ids[0]}.png").write_bytes(b"not a png")
    assert main(["dataset", "verify", str(sub), "--manifest", str(pub / "manifest.json")]) == 1
    assert f"images/{ids[0]}.png: unreadable image" in capsys.readouterr().out


def test_a_manifest_that_is_not_one_is_a_one_line_error(release, capsys):
    pub, sub, ids = release
    (pub / "manifest.json").write_text("[1, 2]")
    with pytest.raises(DatasetError, match="not a published dataset manifest"):
        published.verify_against(sub, pub / "manifest.json")


# fingerprint v2 (generator/datasets/label_prints.py): a label whose object-edge pixels went to a neighbour
# on another CPU (measured: one section pixel, 49 of 3,200 paper frames) against a real difference

def _edit_label(sub, fid, edit) -> None:
    path = sub / "labels" / f"{fid}.json"
    label = json.loads(path.read_text())
    edit(label)
    path.write_text(json.dumps(label, indent=1) + "\n")


def _section_pixels(delta):
    def edit(label):
        s = label["sections"][1]
        s["pixels_visible"] += delta
        s["visible_fraction"] = min(1.0, s["pixels_visible"] / s["pixels_all"])
    return edit


def test_publish_writes_fingerprint_v2_of_every_label(painted_source, tmp_path):
    pub = tmp_path / "pub"
    msg = published.publish(painted_source, pub)
    assert published.FINGERPRINTS_V2_NAME in msg
    manifest = json.loads((pub / "manifest.json").read_text())
    prints = read_fingerprints_v2(pub / published.FINGERPRINTS_V2_NAME)
    assert list(prints) == [f["frame_id"] for f in manifest["frames"]]
    fid = manifest["frames"][-1]["frame_id"]
    text = (painted_source / "labels" / f"{fid}.json").read_bytes()
    core, index = prints[fid]
    assert core == label_core_sha256(text)
    np.testing.assert_array_equal(index, index_measurements(text))
    label = json.loads(text)
    assert len(index) == 5 * (len(label["markers"]) + len(label["sections"]))
    assert index[5 * len(label["markers"])] == label["sections"][0]["pixels_visible"] > 0


def test_an_index_pass_pixel_off_passes_on_v2_and_fails_on_v1_alone(release):
    pub, sub, ids = release
    _edit_label(sub, ids[0], _section_pixels(+1))
    rep = published.verify_against(sub, pub / "manifest.json")
    assert rep.ok and (rep.labels_identical, rep.labels_index_within, rep.max_index_diff) == (2, 1, 1.0), rep.text()
    assert "1 with index-pass pixels within 2 px (max 1)" in rep.text()
    (pub / published.FINGERPRINTS_V2_NAME).unlink()                    # a release with v1 only
    rep = published.verify_against(sub, pub / "manifest.json")
    assert rep.problems == [f"labels/{ids[0]}.json: differs from the manifest beyond its image measurements"]


def test_index_pass_pixels_beyond_the_tolerance_or_a_moved_box_edge_fail(release):
    pub, sub, ids = release
    _edit_label(sub, ids[0], _section_pixels(+3))
    _edit_label(sub, ids[1], lambda lab: lab["sections"][0]["bbox_visible_px"].__setitem__(0, -100.5))
    rep = published.verify_against(sub, pub / "manifest.json")
    assert f"labels/{ids[0]}.json: index-pass pixel counts or boxes differ from the manifest by up to 3 px " \
           "(tolerance 2 px)" in rep.problems
    assert any(p.startswith(f"labels/{ids[1]}.json: index-pass") for p in rep.problems), rep.text()
    assert rep.labels_index_within == 0


def test_a_changed_class_or_a_lost_box_is_a_difference_not_a_pixel_off(release):
    pub, sub, ids = release
    def hide_marker(label):
        m = next(m for m in label["markers"] if m.get("visibility") == 2)
        m["visibility"] = 1                     # the class the exports use: exact, even if the count is close
    _edit_label(sub, ids[0], hide_marker)
    _edit_label(sub, ids[1], lambda lab: lab["sections"][0].__setitem__("bbox_visible_px", None))
    rep = published.verify_against(sub, pub / "manifest.json")
    assert f"labels/{ids[0]}.json: differs from the manifest beyond its image and index-pass measurements" \
        in rep.problems
    assert f"labels/{ids[1]}.json: index-pass pixel counts or boxes differ from the manifest by another set " \
           "of counts and boxes (tolerance 2 px)" in rep.problems


def test_index_difference_is_none_for_another_structure():
    a = np.array([10.0, 1.5, np.nan])
    assert index_difference(a, np.array([11.0, 0.5, np.nan])) == 1.0
    assert index_difference(a, np.array([10.0, 1.5, 3.0])) is None
    assert index_difference(a, a[:2]) is None


# the markers themselves (generator/datasets/marker_check.py): a tile mean barely moves when a marker is
# erased, moved or recoloured; the check compares each marker's colour with its verified label

def _checked_markers(sub, fid):
    from dockfactory.generator.datasets.marker_check import MIN_PIXELS
    label = json.loads((sub / "labels" / f"{fid}.json").read_text())
    return [m for m in label["markers"] if m.get("legible") and (m.get("visible_pixels") or 0) >= MIN_PIXELS
            and m.get("visible_fraction", 0) >= 0.99]


def _box_slices(m, pad: int = 2):
    x0, y0, x1, y1 = m["bbox_visible_px"]
    return slice(int(y0 + 0.5) - pad, int(y1 + 0.5) + pad), slice(int(x0 + 0.5) - pad, int(x1 + 0.5) + pad)


def _rewrite(path, edit) -> None:
    img = cv2.imread(str(path))
    edit(img)
    cv2.imwrite(str(path), img)


def test_erased_markers_fail_though_the_tile_means_barely_move(release):
    pub, sub, ids = release
    markers = _checked_markers(sub, ids[0])
    assert len(markers) >= 3
    path = sub / "images" / f"{ids[0]}.png"

    def erase(img):
        for m in markers[:3]:
            ys, xs = _box_slices(m)
            border = np.concatenate([img[ys.start - 1, xs], img[ys.stop, xs]])
            img[ys, xs] = np.median(border, axis=0).astype(np.uint8)   # painted over with its surroundings
    _rewrite(path, erase)
    rep = published.verify_against(sub, pub / "manifest.json")
    assert rep.max_tile_diff < published.DEFAULT_TOLERANCE, rep.text()    # the tiles cannot see it
    erased = [p for p in rep.problems if "erased, recoloured or moved" in p]
    assert not rep.ok and len(erased) == 3, rep.text()
    assert all(f"marker {m['id']}:" in " ".join(erased) for m in markers[:3])


def test_a_recoloured_or_moved_marker_fails_and_noise_passes_with_markers_checked(release):
    pub, sub, ids = release
    path = sub / "images" / f"{ids[1]}.png"
    original = cv2.imread(str(path))
    noise = np.random.default_rng(1).integers(-2, 3, original.shape)   # another CPU's bits, +-2 levels
    cv2.imwrite(str(path), np.clip(original.astype(int) + noise, 0, 255).astype(np.uint8))
    rep = published.verify_against(sub, pub / "manifest.json")
    assert rep.ok and rep.markers_checked == len(_checked_markers(sub, ids[1])) >= 1, rep.text()
    m = max(_checked_markers(sub, ids[1]), key=lambda m: m["visible_pixels"])
    ys, xs = _box_slices(m, pad=0)

    def recolour(img):
        img[ys, xs] = img[ys, xs][..., ::-1]          # red and blue exchanged on the marker's box
    cv2.imwrite(str(path), original)
    _rewrite(path, recolour)
    rep = published.verify_against(sub, pub / "manifest.json")
    assert any(f"marker {m['id']}:" in p for p in rep.problems), rep.text()

    def move(img):
        ys2, xs2 = _box_slices(m, pad=6)
        img[ys2, xs2] = np.roll(original[ys2, xs2], 4, axis=1)   # the disc moved 4 px to the right
    cv2.imwrite(str(path), original)
    _rewrite(path, move)
    rep = published.verify_against(sub, pub / "manifest.json")
    assert any(f"marker {m['id']}: its colour's centroid is" in p for p in rep.problems), rep.text()


@pytest.mark.parametrize("tolerance", [float("nan"), -1.0, 0.0, float("inf")])
def test_a_tolerance_must_be_finite_and_positive(release, capsys, tolerance):
    pub, sub, ids = release
    with pytest.raises(DatasetError, match="--tolerance: expected a finite number"):
        published.verify_against(sub, pub / "manifest.json", tolerance)
    with pytest.raises(SystemExit) as exit_:   # argparse refuses it before any work
        main(["dataset", "verify", str(sub), "--manifest", str(pub / "manifest.json"), "--tolerance", str(tolerance)])
    assert exit_.value.code == 2 and "--tolerance" in capsys.readouterr().err.strip().splitlines()[-1]


def _forge(pub, edit):
    manifest = json.loads((pub / "manifest.json").read_text())
    edit(manifest)
    (pub / "manifest.json").write_text(json.dumps(manifest))


@pytest.mark.parametrize("edit, key", [
    (lambda m: m.update(frames="000000"), "frames: expected a list"),
    (lambda m: m.update(frames=[1, 2]), "frames[0].frame_id"),
    (lambda m: m["frames"][0].pop("frame_id"), "frames[0].frame_id"),
    (lambda m: m["files"][0].pop("bytes"), "files[0].bytes"),
    (lambda m: m["files"][1].update(sha256=None), "files[1].sha256"),
    (lambda m: m.update(version_id=7), "version_id"),
    (lambda m: m.update(software=[]), "software"),
])
def test_a_forged_manifest_is_a_one_line_error(release, capsys, edit, key):
    pub, sub, ids = release
    _forge(pub, edit)
    assert main(["dataset", "verify", str(sub), "--manifest", str(pub / "manifest.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0] and key in err[0] and "manifest.json" in err[0], err


@pytest.mark.parametrize("damage", ["truncated", "wrong-shape", "short-ids"])
def test_a_forged_fingerprint_file_is_a_one_line_error(release, capsys, damage):
    pub, sub, ids = release
    path = pub / published.FINGERPRINTS_NAME
    if damage == "truncated":
        path.write_bytes(path.read_bytes()[:200])
    else:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        if damage == "wrong-shape":
            arrays["tiles"] = arrays["tiles"][:, 0]
        else:
            arrays["frame_ids"] = arrays["frame_ids"][:1]
        np.savez(path.with_suffix(""), **arrays)
    assert main(["dataset", "verify", str(sub), "--manifest", str(pub / "manifest.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a fingerprint file" in err[0] and published.FINGERPRINTS_NAME in err[0], err


def test_a_gpu_rerender_is_checked_against_a_cpu_release_within_the_tolerance(release):
    """[render] device = "gpu" re-render of a CPU release (another version id: the device is part
    of the identity): compared frame by frame, with a note; images with other bits (+-1 level, as
    another device gives) pass within the tolerance; any other config difference is still refused."""
    from dockfactory.core.config import config_from_identity
    from dockfactory.generator.version import dataset_version_id
    pub, sub, ids = release
    ident = json.loads((sub / "dataset.json").read_text())
    cfg = config_from_identity({**ident["config"], "render": {**ident["config"]["render"], "device": "gpu"}})
    ident.update(config=cfg.to_dict(), version_id=dataset_version_id(cfg.canonical_json(), ident["blender_version"],
                                                                     ident["generator_version"]))
    (sub / "dataset.json").write_text(json.dumps(ident))
    (sub / "config.toml").write_text((sub / "config.toml").read_text() + '\n[render]\ndevice = "gpu"\n')
    path = sub / "images" / f"{ids[0]}.png"
    img = cv2.imread(str(path))
    noise = np.random.default_rng(1).integers(-1, 2, img.shape)
    cv2.imwrite(str(path), np.clip(img.astype(int) + noise, 0, 255).astype(np.uint8))
    rep = published.verify_against(sub, pub / "manifest.json")
    assert rep.ok and rep.frames == len(ids) and (rep.images_identical, rep.images_within) == (2, 1), rep.text()
    assert "rendered on gpu, published on cpu" in rep.notes[0]
    other = {**ident["config"], "dataset": {**ident["config"]["dataset"], "seed": 1}}
    (sub / "dataset.json").write_text(json.dumps({**ident, "config": other}))
    rep = published.verify_against(sub, pub / "manifest.json")
    assert not rep.ok and "another config" in rep.problems[0]


def test_a_config_text_that_states_a_moved_default_still_verifies_and_another_config_does_not(release):
    """Config texts that differ in a key stated or left out at its identity-neutral value (paper.toml
    pins label-aware sampling off since 32 became the default; its published text left it out):
    the same config, a note, not a problem. A text that resolves to another config is still one."""
    pub, sub, ids = release
    text = (sub / "config.toml").read_text()
    assert "\nmarker_samples = 0\n" in text and "[markers]" not in text   # the smoke config pins one, not the other
    # a text of the time before either default moved: it leaves out what was the default then
    # (sampling off) and states what was not (the flat marker)
    (sub / "config.toml").write_text(text.replace("\nmarker_samples = 0\n", "\n# left to the default\n", 1)
                                     + '\n[markers]\nform = "flat"\n')
    rep = published.verify_against(sub, pub / "manifest.json")
    assert rep.ok, rep.text()
    assert any("config.toml: its text is not the published one" in n for n in rep.notes)
    # a text of today's that states the flat form the default renders anyway
    (sub / "config.toml").write_text(text + '\n[markers]\nform = "flat"\nraise_mm = 0.1\n')
    assert published.verify_against(sub, pub / "manifest.json").ok
    (sub / "config.toml").write_text(text.replace("\nmarker_samples = 0\n", "\nmarker_samples = 8\n", 1))
    rep = published.verify_against(sub, pub / "manifest.json")
    assert not rep.ok and "config.toml: differs from the manifest" in rep.problems


def test_a_publish_that_stops_half_way_over_an_earlier_one_is_refused(painted_source, release, tmp_path, monkeypatch):
    """Publishing over an earlier release, stopped after the fingerprints and before the manifest:
    the folder then holds the earlier manifest beside fingerprints of another; verify refuses
    it in one line naming the file (before: it compared a re-render against a mix). A finished
    publish binds every fingerprint file to its manifest."""
    pub, sub, _ = release
    assert published.bound_manifest_sha256(pub / published.FINGERPRINTS_NAME) == \
        published.manifest_binding(json.loads((pub / "manifest.json").read_text()))
    other = tmp_path / "other"
    shutil.copytree(painted_source, other)
    doc = json.loads((other / "manifest.json").read_text())
    doc["created_at"] = "another publish"               # another manifest of the same frames
    (other / "manifest.json").write_text(json.dumps(doc))
    real = published.write_bytes_atomic

    def stop_at_manifest(path, data):
        if path.name == "manifest.json":
            raise KeyboardInterrupt                     # the machine goes down
        return real(path, data)
    monkeypatch.setattr(published, "write_bytes_atomic", stop_at_manifest)
    monkeypatch.setattr(published, "verify", lambda root: type("R", (), {"ok": True})())
    with pytest.raises(KeyboardInterrupt):
        published.publish(other, pub)
    monkeypatch.undo()
    with pytest.raises(DatasetError, match=r"manifest.json: not the manifest fingerprints.npz was published with"):
        published.verify_against(sub, pub / "manifest.json")
