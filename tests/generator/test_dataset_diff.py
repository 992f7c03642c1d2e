"""``dockfactory dataset diff A B`` compares content on disk (sizes and sha256, labels field by
field), whatever the manifests say, and exits like ``git diff --exit-code``: 0 identical,
1 different, 2 bad input."""
import json
import os
import shutil

import pytest
from cli_run import one_line_error, run_cli

from dockfactory.generator.datasets.diff import MAX_FIELDS, diff, field_differences


@pytest.fixture
def pair(painted, tmp_path):
    """(A, B): the painted smoke dataset and a byte-identical copy of it."""
    b = tmp_path / "b"
    shutil.copytree(painted, b)
    return painted, b


def _diff(a, b, capsys, *flags):
    return run_cli(["dataset", "diff", a, b, *flags], capsys)


def test_identical_copies_exit_0(pair, capsys):
    a, b = pair
    code, out, err = _diff(a, b, capsys)
    assert code == 0 and out.rstrip().endswith("identical") and "0 different" in out and not err
    d = diff(a, b)
    assert d["identical"] and d["same"] == len(json.loads((a / "manifest.json").read_text())["files"]) + 1


def test_one_byte_of_an_image_changed_is_named(pair, capsys):
    """The manifest of B is untouched (a corrupted copy): only the bytes on disk tell."""
    a, b = pair
    image = sorted((b / "images").glob("*.png"))[2]
    data = bytearray(image.read_bytes())
    data[len(data) // 2] ^= 0x01
    image.write_bytes(bytes(data))
    code, out, _ = _diff(a, b, capsys)
    rel = f"images/{image.name}"
    assert code == 1 and f"~ {rel} (same size, sha256 differs)" in out and out.rstrip().endswith("different")
    d = diff(a, b)
    assert d["different"] == [rel] and not d["only_in_a"] and not d["only_in_b"] and not d["identical"]


def test_a_label_value_changed_is_named_field_by_field(pair, capsys):
    a, b = pair
    path = b / "labels" / "000003.json"
    label = json.loads(path.read_text())
    label["markers"][2]["center_px"][0] += 0.5
    label["pose_b_in_d"]["x_mm"] = 1.0
    path.write_text(json.dumps(label, indent=1))
    code, out, _ = _diff(a, b, capsys, "--json")
    d = json.loads(out)
    assert code == 1 and d["different"] == ["labels/000003.json"] and not d["identical"]
    fields = d["label_fields"]["labels/000003.json"]
    assert len(fields) == 2 and fields[0].startswith("markers[2].center_px[0]: ")
    assert fields[1].startswith("pose_b_in_d.x_mm: ") and fields[1].endswith("-> 1.0")
    code, text, _ = _diff(a, b, capsys)
    assert code == 1 and "~ labels/000003.json" in text and "      markers[2].center_px[0]: " in text


def test_files_only_on_one_side_and_a_size_change(pair, capsys):
    a, b = pair
    (b / "meta" / "000000.json").unlink()
    (b / "labels" / "999999.json").write_text("{}")
    (b / "layout.json").write_text((b / "layout.json").read_text() + " ")
    code, out, _ = _diff(a, b, capsys)
    assert code == 1 and "- meta/000000.json" in out and "+ labels/999999.json" in out
    assert "~ layout.json (A: " in out and "bytes, B: " in out


def test_a_symlink_is_compared_by_its_target_never_followed(pair, capsys, tmp_path):
    a, b = pair
    outside = tmp_path / "outside.png"
    shutil.copy(b / "images" / "000001.png", outside)   # the same bytes, behind a link
    (b / "images" / "000001.png").unlink()
    os.symlink(outside, b / "images" / "000001.png")
    code, out, _ = _diff(a, b, capsys)
    assert code == 1 and "~ images/000001.png (A: " in out and f"B: a symlink to {outside})" in out


def test_derived_files_and_config_differences(pair, capsys):
    """Exports, logs and the card are derived: not compared. A changed config is a difference."""
    a, b = pair
    for rel in ("exports/coco/x.json", "logs/timings.jsonl", "hf/train/metadata.jsonl", "README.md"):
        (b / rel).parent.mkdir(parents=True, exist_ok=True)
        (b / rel).write_text("derived\n")
    assert _diff(a, b, capsys)[0] == 0
    ident = json.loads((b / "dataset.json").read_text())
    ident["config"]["dataset"]["seed"] = 8
    (b / "dataset.json").write_text(json.dumps(ident))
    code, out, _ = _diff(a, b, capsys)
    assert code == 1 and "config differences:" in out and "dataset.seed: 7 -> 8" in out and "~ dataset.json" in out


@pytest.mark.parametrize("what", ["missing", "not-a-dataset", "bad-identity"])
def test_bad_input_exits_2_with_one_line(pair, capsys, tmp_path, what):
    a, b = pair
    if what == "missing":
        b = tmp_path / "nowhere"
    elif what == "not-a-dataset":
        b = tmp_path / "plain"
        b.mkdir()
    else:
        (b / "dataset.json").write_text("[]")
    code, _, err = _diff(a, b, capsys)
    assert code == 2 and str(b) in one_line_error(err)


def test_field_differences_are_capped_and_typed():
    assert field_differences({"a": 1}, {"a": 1.0}) == ["a: 1 -> 1.0"]     # another type is a difference
    assert field_differences([1, 2], [1, 2, 3]) == ["(whole file): [1, 2] -> [1, 2, 3]"]
    many = field_differences({"x": list(range(100))}, {"x": list(range(1, 101))})
    assert len(many) == MAX_FIELDS + 1
