"""The label format's JSON Schema (core.label_schema, `dockfactory schema labels`): every label the
factory writes validates (the painted smoke dataset: every condition, repeat captures), and a
label that lost a key a consumer needs, or holds a value of the wrong type or range, does not."""
from __future__ import annotations

import copy
import json

import pytest

from cli_run import run_cli
from dockfactory.core.label_schema import LABEL_SCHEMA

jsonschema = pytest.importorskip("jsonschema")


@pytest.fixture(scope="module")
def labels(painted_source):
    return [json.loads(p.read_text()) for p in sorted((painted_source / "labels").glob("*.json"))]


def test_the_schema_is_a_valid_draft_2020_12_schema():
    jsonschema.Draft202012Validator.check_schema(LABEL_SCHEMA)


def test_every_label_of_a_dataset_validates(labels):
    validator = jsonschema.Draft202012Validator(LABEL_SCHEMA)
    assert len(labels) == 10
    for lab in labels:
        errors = [e.message for e in validator.iter_errors(lab)]
        assert not errors, (lab["frame_id"], errors[:3])


@pytest.mark.parametrize("edit, where", [
    (lambda d: d.pop("pose_b_in_d"), "pose_b_in_d"),
    (lambda d: d["pose_b_in_d"].pop("alpha_deg"), "alpha_deg"),
    (lambda d: d["markers"][0].update(section="C"), "'C'"),
    (lambda d: d["markers"][0].update(visibility=3), "3"),
    (lambda d: d["markers"][0].update(center_px=[1.0]), "center_px"),
    (lambda d: d["camera"].update(cam_from_d=[[1, 0, 0, 0]] * 3), "cam_from_d"),
    (lambda d: d["image"].update(width="1280"), "'1280'"),
    (lambda d: d.update(format="dockfactory.label/2"), "format"),
])
def test_a_damaged_label_does_not(labels, edit, where):
    lab = copy.deepcopy(labels[0])
    edit(lab)
    errors = list(jsonschema.Draft202012Validator(LABEL_SCHEMA).iter_errors(lab))
    assert errors and any(where in (e.message + " " + "/".join(map(str, e.path))) for e in errors), \
        [e.message for e in errors]


def test_the_command_prints_and_writes_it(tmp_path, capsys):
    code, out, _ = run_cli(["schema", "labels"], capsys)
    assert code == 0 and json.loads(out) == LABEL_SCHEMA
    code, _, _ = run_cli(["schema", "labels", "--out", tmp_path / "labels.schema.json"], capsys)
    assert code == 0 and json.loads((tmp_path / "labels.schema.json").read_text()) == LABEL_SCHEMA
