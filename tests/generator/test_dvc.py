"""A dataset tracked with the real DVC (the ``dvc`` test extra): ``dvc init``, ``dvc add`` with the
symlink cache, ``dvc checkout``, then every consumer reads it and ``dvc status`` stays clean.

The dataset is the painted smoke dataset finished by the real render job (its render replaced,
nothing to render): exports and card written as a completed render leaves them. ``run`` solves
with the oracle (no detector, as tests/app/test_stages.py)."""
import importlib.util
import os
import shutil
import subprocess
import sys

import pytest
from cli_run import run_cli

from dockfactory.core.config import load_config
from dockfactory.core.resources import shipped_config
from dockfactory.generator import render_job
from dockfactory.generator.datasets.check import verify
from dockfactory.generator.render_job import JobOptions, run_render

pytestmark = [pytest.mark.skipif(importlib.util.find_spec("dvc") is None,
                                 reason="dvc is not installed (pip install '.[dvc]')"),
              pytest.mark.slow]   # about 40 s on 2 cores: DVC's start-up, a run


def dvc(project, *args) -> str:
    env = {**os.environ, "DVC_NO_ANALYTICS": "1", "DVC_SITE_CACHE_DIR": str(project / ".dvc-site")}
    proc = subprocess.run([sys.executable, "-m", "dvc", *args], cwd=project, env=env, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


def _no_render(*args, **kwargs):
    raise AssertionError("rendered although the dataset is complete")


@pytest.fixture
def finished(painted, monkeypatch):
    """The painted dataset completed by ``run_render``: exports (coco, yolo) and card written."""
    monkeypatch.setattr(render_job, "_render", _no_render)
    config = shipped_config("smoke")
    summary = run_render(load_config(config), painted, config.read_text(), JobOptions(progress=False))
    assert summary.complete and summary.ok and (painted / "README.md").is_file()
    return painted


def _tracked(finished, tmp_path, dvcignore: str):
    """``proj/run/dataset`` added to a new DVC project with the symlink cache, checked out again."""
    proj = tmp_path / "proj"
    shutil.move(finished, proj / "run" / "dataset")
    dvc(proj, "init", "--no-scm", "-q")
    dvc(proj, "config", "cache.type", "symlink")
    if dvcignore:
        (proj / ".dvcignore").write_text(dvcignore)
    dvc(proj, "add", "run/dataset")
    dvc(proj, "checkout", "--force")
    ds = proj / "run" / "dataset"
    assert (ds / "images" / "000000.png").is_symlink() and (ds / "manifest.json").is_symlink()
    assert "up to date" in dvc(proj, "status")
    return proj, ds


def _status_clean(proj):
    out = dvc(proj, "status")
    assert "up to date" in out, out


def test_symlink_cache_every_consumer(finished, tmp_path, capsys, monkeypatch):
    """Without a .dvcignore DVC links logs/ and exports/ too: verify, run, card and every export
    (beside the dataset by default, or --out) work, and ``dvc status`` stays clean."""
    import dockfactory.eval.report.document as report
    monkeypatch.setattr(report, "plots", lambda rows, metrics, detections_pr=None: {})
    proj, ds = _tracked(finished, tmp_path, dvcignore="")
    assert (ds / "logs" / ".dockfactory.lock").is_symlink() and (ds / "hf" / "train" / "metadata.jsonl").is_symlink()
    code, out, _ = run_cli(["dataset", "verify", ds], capsys)
    assert code == 0 and "OK: complete and intact" in out
    code, out, err = run_cli(["run", shipped_config("smoke"), "--out", proj / "run", "--oracle-noise", "0"], capsys)
    assert code in (0, 1) and "verdict:" in out and "damaged" not in err, err
    assert (proj / "run" / "report.md").is_file()
    code, out, err = run_cli(["dataset", "export", ds, "--format", "coco,yolo,bop"], capsys)
    beside = proj / "run" / "dataset.exports"      # the default for a tracked dataset: beside it
    assert code == 0 and "tracked by DVC" in err and out.split() == [str(beside / f) for f in ("coco", "yolo", "bop")]
    code, out, _ = run_cli(["dataset", "export", ds, "--format", "coco,yolo,bop", "--out", tmp_path / "ex"], capsys)
    for folder in (beside, tmp_path / "ex"):
        assert all((folder / f / ".dockfactory-export.json").is_file() for f in ("coco", "yolo", "bop"))
    code, _, _ = run_cli(["dataset", "card", ds], capsys)
    assert code == 0
    _status_clean(proj)


def test_project_dvcignore_keeps_exports_inside(finished, tmp_path, capsys):
    """With ``logs/`` and ``exports/`` in the project's .dvcignore, exports go inside as usual."""
    proj, ds = _tracked(finished, tmp_path, dvcignore="logs/\nexports/\n")
    assert not (ds / "logs" / ".dockfactory.lock").is_symlink() and not (ds / "exports").is_symlink()
    code, out, _ = run_cli(["dataset", "export", ds, "--format", "coco,yolo,bop"], capsys)
    assert code == 0 and (ds / "exports" / "bop" / ".dockfactory-export.json").is_file()
    assert verify(ds).ok
    _status_clean(proj)
