"""Property-based fuzz of the other files a user hands over: layouts (``measure --layout``),
published manifests and fingerprint files (``dataset verify --manifest``), noise cards beside
weights, and weights files. Any shape, and valid files mutated (a key deleted, a value replaced
by null, a string, a list, NaN, a boolean, a huge or negative number), give the file's own
one-line error (or, for a noise card, "no card": the covariance falls back to the residuals) or
a normal result; never another exception. Deterministic: the conftest's derandomized profile.
"""
import json
import shutil

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given
from hypothesis import settings as hsettings
from hypothesis import strategies as st
from test_json_fuzz import json_values, mutated

from dockfactory.core.layout_file import LayoutFileError, read_layout_file
from dockfactory.core.resources import shipped_weights
from dockfactory.detector.checkpoint import CheckpointError, load_model
from dockfactory.detector.noise_card import centre_noise_px, noise_card_path
from dockfactory.generator.datasets import published
from dockfactory.generator.datasets.folder import DatasetError

FUZZ = hsettings(max_examples=25, deadline=None,
                 suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def files(painted_source, tmp_path_factory):
    """A published copy of the painted smoke dataset, a three-frame re-render, and the weights."""
    base = tmp_path_factory.mktemp("fuzzfiles")
    pub = base / "pub"
    published.publish(painted_source, pub)
    sub = base / "rerender"
    shutil.copytree(painted_source, sub)
    (sub / "manifest.json").unlink()
    for fid in sorted(p.stem for p in (sub / "labels").glob("*.json"))[3:]:
        for rel in (f"labels/{fid}.json", f"images/{fid}.png", f"meta/{fid}.json"):
            (sub / rel).unlink()
    weights = base / "w.pt"
    shutil.copy(shipped_weights(), weights)
    return {"base": base, "pub": pub, "sub": sub, "layout": json.loads((painted_source / "layout.json").read_text()),
            "manifest": json.loads((pub / "manifest.json").read_text()), "weights": weights,
            "weights_doc": torch.load(weights, weights_only=True)}


def _layout(files, doc):
    path = files["base"] / "layout.json"
    path.write_text(json.dumps(doc, allow_nan=True))
    try:
        read_layout_file(path)
    except LayoutFileError as exc:
        assert str(path) in str(exc) and "\n" not in str(exc)


@FUZZ
@given(value=json_values)
def test_layouts_of_any_shape(files, value):
    _layout(files, value)


@FUZZ
@given(data=st.data())
def test_mutated_layouts(files, data):
    _layout(files, data.draw(mutated(files["layout"])))


def _verify(files, doc):
    path = files["pub"] / "manifest.json"
    path.write_text(json.dumps(doc, allow_nan=True))
    try:
        rep = published.verify_against(files["sub"], path)
    except DatasetError as exc:
        assert str(path) in str(exc) and "\n" not in str(exc)
        return
    assert isinstance(rep.ok, bool) and rep.text()


@FUZZ
@given(value=json_values)
def test_manifests_of_any_shape(files, value):
    _verify(files, value)


@FUZZ
@given(data=st.data())
def test_mutated_manifests(files, data):
    _verify(files, data.draw(mutated(files["manifest"])))


ARRAY_EDITS = {
    "drop": lambda a: None, "empty": lambda a: a[:0], "first": lambda a: a[:1], "scalar": lambda a: np.array(3),
    "strings": lambda a: np.array(["x"] * len(a)), "flat": lambda a: a.reshape(-1),
    "nan": lambda a: np.full(a.shape, np.nan) if a.dtype.kind == "f" else a, "bool": lambda a: np.zeros(a.shape, bool),
}


@pytest.mark.parametrize("name", [published.FINGERPRINTS_NAME, published.FINGERPRINTS_V2_NAME])
@pytest.mark.parametrize("edit", sorted(ARRAY_EDITS))
def test_fingerprint_files_with_each_array_edited(files, tmp_path, name, edit):
    pub = tmp_path / "pub"
    shutil.copytree(files["pub"], pub)
    (pub / "manifest.json").write_text(json.dumps(files["manifest"]))
    with np.load(pub / name, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    for key in sorted(arrays):
        changed = dict(arrays)
        new = ARRAY_EDITS[edit](arrays[key])
        if new is None:
            del changed[key]
        else:
            changed[key] = new
        with open(pub / name, "wb") as fh:
            np.savez(fh, **changed)
        try:
            rep = published.verify_against(files["sub"], pub / "manifest.json")
        except DatasetError as exc:
            assert name in str(exc) and "\n" not in str(exc)
            continue
        assert isinstance(rep.ok, bool)


@FUZZ
@given(value=json_values)
def test_noise_cards_of_any_shape_are_no_card(files, value):
    card = noise_card_path(files["weights"])
    card.write_text(json.dumps(value, allow_nan=True))
    assert centre_noise_px(files["weights"]) is None   # never a card for these weights: no sha256 of them


@FUZZ
@given(value=st.one_of(st.none(), st.booleans(), st.text(max_size=4), st.floats(allow_nan=True), st.integers(),
                       st.lists(st.integers(), max_size=2)))
def test_noise_cards_with_any_noise_value(files, value):
    from dockfactory.core.io import sha256_file
    from dockfactory.detector.noise_card import NOISE_FORMAT, refinement_sha256
    card = noise_card_path(files["weights"])
    card.write_text(json.dumps({"format": NOISE_FORMAT, "weights_sha256": sha256_file(files["weights"]),
                                "refinement_sha256": refinement_sha256(), "centre_noise_px": value}, allow_nan=True))
    got = centre_noise_px(files["weights"])
    assert got is None or (isinstance(got, float) and 0 < got <= 100.0)


WEIGHT_REPLACEMENTS = (None, "x", [], {}, float("nan"), True, -1, 0, 10 ** 9, [1, 2], torch.zeros(2))


@FUZZ
@given(data=st.data())
def test_mutated_weights(files, data):
    doc = dict(files["weights_doc"])
    for _ in range(data.draw(st.integers(1, 2))):
        top = data.draw(st.sampled_from(sorted(doc)))
        if isinstance(doc[top], dict) and doc[top] and data.draw(st.booleans()):
            inner = dict(doc[top])
            key = data.draw(st.sampled_from(sorted(inner)))
            inner[key] = data.draw(st.sampled_from(WEIGHT_REPLACEMENTS))
            doc[top] = inner
        elif data.draw(st.booleans()):
            del doc[top]
        else:
            doc[top] = data.draw(st.sampled_from(WEIGHT_REPLACEMENTS))
    path = files["base"] / "fuzz.pt"
    torch.save(doc, path)
    try:
        load_model(path)
    except CheckpointError as exc:
        assert str(path) in str(exc) and "\n" not in str(exc) and "weights_only" not in str(exc)
