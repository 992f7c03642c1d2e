"""Symlinks a DVC cache puts in place (``generator.datasets.dvc_links``), without DVC: the painted smoke
dataset's files are moved into a cache laid out like DVC's (``.dvc/cache/files/md5/xx/...``)
and replaced by symlinks, as ``dvc add`` with ``cache.type symlink`` does. tests/generator/test_dvc.py
does the same with the real DVC."""
import hashlib
import json
import os
import shutil
from pathlib import Path

import pytest
from cli_run import one_line_error, run_cli

from dockfactory.core.io import FolderBusy
from dockfactory.generator.datasets.folder import DatasetError, dataset_lock, frame_done
from dockfactory.generator.datasets.check import verify
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.datasets.tools import export
from dockfactory.generator.datasets.dvc_links import CACHE_ENV, dvc_caches, outside_exports, outside_note, tracking_file


def link_into_cache(root: Path, cache: Path) -> int:
    """Move every file of ``root`` into ``cache`` (content-addressed by md5, read-only) and put an
    absolute symlink in its place; returns how many."""
    n = 0
    for path in sorted(p for p in root.rglob("*") if p.is_file() and not p.is_symlink()):
        digest = hashlib.md5(path.read_bytes()).hexdigest()
        target = cache / "files" / "md5" / digest[:2] / digest[2:]
        target.parent.mkdir(parents=True, exist_ok=True)
        if not target.exists():
            shutil.copyfile(path, target)
            target.chmod(0o444)
        path.unlink()
        os.symlink(target, path)
        n += 1
    return n


@pytest.fixture
def project(painted, tmp_path):
    """A DVC-like project holding the dataset at ``proj/ds``, every file a link into ``.dvc/cache``."""
    proj = tmp_path / "proj"
    (proj / ".dvc").mkdir(parents=True)
    ds = proj / "ds"
    shutil.move(painted, ds)
    (ds / "logs").mkdir(exist_ok=True)
    (ds / "logs" / ".dockfactory.lock").write_bytes(b"")
    assert link_into_cache(ds, proj / ".dvc" / "cache") > 40
    return ds


def test_cache_links_are_accepted_by_every_consumer(project, capsys, tmp_path):
    assert (project / "images" / "000000.png").is_symlink()
    assert verify(project).ok, verify(project).text()
    ds = Dataset.open(project)
    assert len(ds.labels_of()) == 10
    assert all(frame_done(project, fid, True) for fid in ds.splits)   # render finds nothing to do
    code, out, _ = run_cli(["dataset", "export", project, "--format", "coco,yolo,bop", "--out", tmp_path / "ex"],
                           capsys)
    assert code == 0 and (tmp_path / "ex" / "coco" / "images" / "train" / "000000.png").is_file()
    assert not (tmp_path / "ex" / "coco" / "images" / "train" / "000000.png").is_symlink()
    code, _, _ = run_cli(["show", project, "000000", "--out", tmp_path / "o.png"], capsys)
    assert code == 0 and (tmp_path / "o.png").stat().st_size > 0


def test_a_link_to_another_cached_file_is_corrupt(project):
    """Inside the cache but with other bytes: the manifest's sha256 decides."""
    image = project / "images" / "000001.png"
    other = os.readlink(project / "images" / "000002.png")
    image.unlink()
    os.symlink(other, image)
    report = verify(project)
    assert not report.ok and [p for p, _ in report.corrupt] == ["images/000001.png"] and not report.unsafe


def test_a_link_outside_every_cache_stays_refused(project, tmp_path, monkeypatch):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    image = project / "images" / "000001.png"
    copy = elsewhere / "copy.png"
    shutil.copyfile(image, copy)   # the right bytes, in no cache
    image.unlink()
    os.symlink(copy, image)
    report = verify(project)
    assert not report.ok and report.unsafe[0][0] == "images/000001.png"
    assert "not into a DVC cache" in report.unsafe[0][1] and CACHE_ENV in report.unsafe[0][1]
    with pytest.raises(DatasetError, match="unsafe: images/000001.png"):
        Dataset.open(project)
    monkeypatch.setenv(CACHE_ENV, str(elsewhere))   # the user names that cache
    assert verify(project).ok


def test_a_cache_named_in_the_dvc_config(project, tmp_path):
    """``dvc cache dir`` writes ``[cache] dir`` into .dvc/config (relative to .dvc/)."""
    proj = project.parent
    shutil.move(proj / ".dvc" / "cache", tmp_path / "shared_cache")
    for link in (p for p in project.rglob("*") if p.is_symlink()):
        target = os.readlink(link).replace(str(proj / ".dvc" / "cache"), str(tmp_path / "shared_cache"))
        link.unlink()
        os.symlink(target, link)
    assert not verify(project).ok
    (proj / ".dvc" / "config").write_text("[core]\n    no_scm = True\n[cache]\n    dir = ../../shared_cache\n"
                                          "    type = symlink\n")
    assert dvc_caches(project) == ((tmp_path / "shared_cache").resolve(),)
    assert verify(project).ok


def test_symlinked_folders_and_dangling_links_stay_refused(project, tmp_path):
    (project / "exr").rename(tmp_path / "exr")
    os.symlink(tmp_path / "exr", project / "exr")
    (project / "meta" / "000000.json").unlink()
    os.symlink(project.parent / ".dvc" / "cache" / "files" / "md5" / "00" / "gone", project / "meta" / "000000.json")
    report = verify(project)
    reasons = dict(report.unsafe)
    assert "outside the dataset" in reasons["exr"] and "dangling" in reasons["meta/000000.json"]


def test_a_symlinked_lock_file_is_never_written_through(project):
    lock = project / "logs" / ".dockfactory.lock"
    target = Path(os.readlink(lock))
    before = target.read_bytes()
    with dataset_lock(project, "test"):
        with pytest.raises(FolderBusy, match="in use by another dockfactory process"):
            with dataset_lock(project, "second"):
                pass
    assert lock.is_symlink() and target.read_bytes() == before


def test_exports_of_a_tracked_dataset_go_beside_it(project, capsys, tmp_path):
    """``dvc add ds`` writes ds.dvc beside it: an export inside would make ``dvc status`` dirty, so
    it goes to ds.exports/ unless the project's .dvcignore ignores exports/."""
    assert tracking_file(project) is None and outside_exports(project) is None and outside_note(project) == ""
    (project.parent / "ds.dvc").write_text("outs:\n- path: ds\n")
    assert tracking_file(project) == project.parent / "ds.dvc"
    code, out, err = run_cli(["dataset", "export", project, "--format", "yolo"], capsys)
    beside = project.parent / "ds.exports"
    assert code == 0 and out.strip() == str(beside / "yolo") and (beside / "yolo" / "data.yaml").is_file()
    assert err.startswith("note: ") and "tracked by DVC" in err and "exports/" in err
    assert not (project / "exports").exists()
    code, _, err = run_cli(["dataset", "export", project, "--format", "yolo", "--out", project / "x"], capsys)
    assert code == 2 and "inside the dataset" in one_line_error(err)
    (project.parent / ".dvcignore").write_text("# derived folders of every dockfactory dataset\nlogs/\nexports/\n")
    assert outside_exports(project) is None
    assert export(project, "yolo") == project / "exports" / "yolo"


def test_a_dataset_inside_a_tracked_folder(project):
    """``dvc add data`` of a folder holding datasets: their exports go beside that folder."""
    proj = project.parent
    (proj / "data").mkdir()
    project.rename(proj / "data" / "ds")
    (proj / "data.dvc").write_text("outs:\n- path: data\n")
    ds = proj / "data" / "ds"
    assert outside_exports(ds) == (proj / "data.exports" / "ds").resolve()
    (proj / ".dvcignore").write_text("data/ds/exports/\n")
    assert outside_exports(ds) is None


def test_the_manifest_is_what_is_linked_not_what_the_links_say(project):
    """A link is only a way to reach a file: the manifest's paths stay the dataset's own."""
    manifest = json.loads((project / "manifest.json").read_text())
    assert all(not rec["path"].startswith("/") for rec in manifest["files"])
    assert (project / "manifest.json").is_symlink()
