"""Fixtures of the generator's tests."""
import shutil

import pytest

from dockfactory.generator.datasets import published


@pytest.fixture
def release(painted_source, tmp_path):
    """(published folder with manifest.json and its fingerprints, a re-render of three of its frames:
    a copy without the manifest, as ``dockfactory render --frames`` leaves it)."""
    pub = tmp_path / "pub"
    published.publish(painted_source, pub)
    sub = tmp_path / "rerender"
    shutil.copytree(painted_source, sub)
    (sub / "manifest.json").unlink()
    ids = sorted(p.stem for p in (sub / "labels").glob("*.json"))
    for fid in ids[3:]:
        for rel in (f"labels/{fid}.json", f"images/{fid}.png", f"meta/{fid}.json"):
            (sub / rel).unlink()
    return pub, sub, ids[:3]
