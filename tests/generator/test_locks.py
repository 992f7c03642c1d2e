"""Issue 10, finding 6: writes that are crash- and concurrency-safe.

- an export is built aside and swapped in by rename: interrupted, it leaves the old export or the
  new one, never a partial folder, and ``render`` does not take a partial export for done;
- temporary export folders of dead processes are removed;
- one exclusive lock per dataset (render, export) and per ``run`` work folder: a second writer
  fails at once with a one-line error (exit 2) naming the holder (pid, host, command), renders
  nothing, and the lock dies with its holder (kill -9);
- a temporary file of a dead worker never makes ``verify`` fail, and ``render`` removes it before
  it declares the dataset complete.

No rendering: the painted smoke dataset of tests/pipeline_data.py (``_render`` is replaced by a
function that fails the test) and the export dataset of tests/generator/test_exports.py.
"""
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from test_exports import write_dataset

from dockfactory.core.config import load_config
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.io import HOST, remove_stale_temps
from dockfactory.core.resources import default_acceptance, shipped_config
from dockfactory.generator.datasets import tools as dt
from dockfactory.generator.render_job import JobOptions, run_render

DOCKFACTORY = str(Path(sys.executable).parent / "dockfactory")


@pytest.fixture(scope="module")
def export_source(tmp_path_factory):
    return write_dataset(tmp_path_factory.mktemp("locks-exports") / "ds")


@pytest.fixture
def export_ds(export_source, tmp_path):
    root = tmp_path / "eds"
    shutil.copytree(export_source, root)
    return root


@pytest.fixture
def no_render(monkeypatch):
    from dockfactory.generator import render_job

    def fail(*args, **kwargs):
        raise AssertionError("rendered although another process holds the dataset")
    monkeypatch.setattr(render_job, "_render", fail)


def _smoke():
    path = shipped_config("smoke")
    return load_config(path), Path(path).read_text()


def _dead_pid() -> int:
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True,
                          check=True)
    return int(proc.stdout)


HOLDER = """
import sys
from dockfactory.core.io import folder_lock
from dockfactory.generator.datasets.folder import dataset_lock
kind, folder = sys.argv[1], sys.argv[2]
with (dataset_lock(folder, "render") if kind == "dataset" else folder_lock(folder, "run")):
    print("held", flush=True)
    sys.stdin.read()
"""


class Holder:
    """A process that holds the dataset (or work folder) lock until it is closed or killed."""

    def __init__(self, kind: str, folder: Path):
        self.proc = subprocess.Popen([sys.executable, "-c", HOLDER, kind, str(folder)], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = self.proc.stdout.readline()
        if line.strip() != "held":
            self.proc.kill()
            raise AssertionError(f"the holder did not take the lock: {self.proc.communicate()[1]}")

    def close(self):
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()


@pytest.fixture
def holder():
    made = []

    def make(kind, folder):
        made.append(Holder(kind, folder))
        return made[-1]
    yield make
    for h in made:
        h.close()


def _one_line_naming(msg: str, pid: int):
    assert "\n" not in msg.strip(), msg
    assert f"pid {pid}" in msg and HOST in msg and "render" in msg, msg


# ----------------------------------------------------------------------------- locks

def test_second_render_fails_at_once_naming_the_holder(painted, holder, no_render):
    (painted / "labels" / "000002.json").unlink()   # a frame to render: nothing may render it twice
    h = holder("dataset", painted)
    cfg, text = _smoke()
    with pytest.raises(DockfactoryError) as err:
        run_render(cfg, painted, text, JobOptions(progress=False))
    _one_line_naming(str(err.value), h.proc.pid)
    h.close()   # kill -9: the lock dies with its holder
    assert h.proc.returncode == -signal.SIGKILL


def test_lock_dies_with_a_killed_holder(painted, holder, no_render):
    h = holder("dataset", painted)
    os.kill(h.proc.pid, signal.SIGKILL)
    h.proc.wait()
    cfg, text = _smoke()
    summary = run_render(cfg, painted, text, JobOptions(progress=False))
    assert summary.complete and summary.rendered == 0


def test_render_and_export_cli_exit_2_with_one_line(painted, holder):
    h = holder("dataset", painted)
    for argv in ([DOCKFACTORY, "render", "smoke", "--out", str(painted), "--quiet"],
                 [DOCKFACTORY, "dataset", "export", str(painted), "--format", "coco"]):
        proc = subprocess.run(argv, check=False, capture_output=True, text=True, timeout=120)
        assert proc.returncode == 2, (argv, proc.stdout, proc.stderr)
        assert "Traceback" not in proc.stderr
        _one_line_naming(proc.stderr, h.proc.pid)
    assert not (painted / "exports").exists()


def test_readers_need_no_lock(painted, holder):
    holder("dataset", painted)
    assert dt.verify(painted).ok
    assert dt.info(painted)["complete"]


def test_run_work_folder_is_locked(painted, tmp_path, holder, no_render):
    from dockfactory.pipeline import run_pipeline
    work = tmp_path / "run"
    shutil.copytree(painted, work / "dataset")
    h = holder("run", work)
    with pytest.raises(DockfactoryError) as err:
        run_pipeline(shipped_config("smoke"), work, default_acceptance(), oracle_noise_px=0.0)
    msg = str(err.value)
    assert "\n" not in msg and f"pid {h.proc.pid}" in msg and HOST in msg and "run" in msg
    assert not (work / "stages.json").exists()


# ----------------------------------------------------------------------------- exports

def _tree(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_interrupted_replace_leaves_old_or_new_never_partial(export_ds, monkeypatch):
    """Killed while the old export is being removed (the issue's 56 of 132 files)."""
    dt.export(export_ds, "bop")
    final = export_ds / "exports" / "bop"
    reference = _tree(final)
    real_rmtree = shutil.rmtree

    def killed_halfway(path, *args, **kwargs):
        if not Path(path).exists():
            return real_rmtree(path, *args, **kwargs)
        files = sorted(p for p in Path(path).rglob("*") if p.is_file())
        for p in files[: len(files) // 2]:
            p.unlink()
        raise KeyboardInterrupt("killed")

    monkeypatch.setattr(shutil, "rmtree", killed_halfway)
    try:
        dt.export(export_ds, "bop")
    except KeyboardInterrupt:
        pass
    monkeypatch.setattr(shutil, "rmtree", real_rmtree)
    assert not final.exists() or _tree(final) == reference
    assert dt.export_complete(export_ds, "bop") == final.exists()
    dt.export(export_ds, "bop")   # the next export cleans up whatever the killed one left
    assert _tree(final) == reference
    assert sorted(p.name for p in (export_ds / "exports").iterdir()) == ["bop"]


def test_render_does_not_take_a_partial_export_for_done(painted, no_render):
    partial = painted / "exports" / "coco" / "images" / "test"
    partial.mkdir(parents=True)
    (partial / "000001.png").write_bytes(b"half")
    cfg, text = _smoke()
    summary = run_render(cfg, painted, text, JobOptions(progress=False))
    assert summary.complete
    coco = painted / "exports" / "coco"
    assert (coco / "annotations" / "person_keypoints_test.json").is_file()
    assert dt.export_complete(painted, "coco") and dt.export_complete(painted, "yolo")


def test_render_of_a_complete_but_edited_dataset_says_damaged(painted, no_render):
    """A label edited in place (same size: frame_done cannot tell) after the dataset completed:
    render finds every frame done but does not call the dataset fine (exit 1), names the file,
    and writes no export from it."""
    label = painted / "labels" / "000001.json"
    text = label.read_text()
    i = text.index('"x_mm": ') + len('"x_mm": ') + 1
    digit = text[i] if text[i].isdigit() else text[i + 1]
    k = text.index(digit, i)
    label.write_text(text[:k] + str((int(digit) + 1) % 10) + text[k + 1:])
    cfg, config_text = _smoke()
    summary = run_render(cfg, painted, config_text, JobOptions(progress=False))
    assert summary.complete and not summary.ok
    assert any("labels/000001.json" in p and "sha256" in p for p in summary.damaged), summary.damaged
    assert "DAMAGED" in summary.text() and not (painted / "exports").exists()


def test_stale_temporary_export_folders_are_removed(export_ds):
    exports = export_ds / "exports"
    dead = exports / f".bop.tmp-{HOST}-{_dead_pid()}"
    (dead / "models").mkdir(parents=True)
    (dead / "models" / "obj_000001.ply").write_text("partial")
    old_style = exports / f".coco.tmp-{_dead_pid()}"   # the old name (no host): removed by age
    old_style.mkdir()
    (old_style / "x.json").write_text("{}")
    os.utime(old_style, (1e9, 1e9))
    dt.export(export_ds, "yolo")
    assert sorted(p.name for p in exports.iterdir()) == ["yolo"]


def test_remove_stale_temps_takes_folders_and_spares_the_living(tmp_path):
    dead = tmp_path / "exports" / f".bop.tmp-{HOST}-{_dead_pid()}"
    (dead / "a").mkdir(parents=True)
    (dead / "a" / f".f.json.tmp-{HOST}-{os.getpid()}").write_text("x")
    alive = tmp_path / "exports" / f".coco.tmp-{HOST}-{os.getpid()}"
    alive.mkdir()
    removed = remove_stale_temps(tmp_path, max_age_s=3600)
    assert dead in removed and not dead.exists() and alive.is_dir()


def test_nested_export_of_one_dataset_does_not_crash(export_ds, monkeypatch):
    """Two exports of one dataset at once (here the second starts inside the first): the second is
    refused with a one-line error naming the first; the first completes."""
    real = dt.EXPORT_WRITERS["bop"]
    refused = []

    def writer(ds, out):   # the writers get the opened dataset
        result = real(ds, out)
        try:
            dt.export(ds.root, "bop")
        except DockfactoryError as exc:
            refused.append(str(exc))
        return result

    monkeypatch.setitem(dt.EXPORT_WRITERS, "bop", writer)
    dt.export(export_ds, "bop")
    assert len(refused) == 1 and f"pid {os.getpid()}" in refused[0] and "\n" not in refused[0]
    assert dt.export_complete(export_ds, "bop")


def test_two_concurrent_export_processes_do_not_crash(export_ds):
    argv = [DOCKFACTORY, "dataset", "export", str(export_ds), "--format", "bop"]
    procs = [subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    outs = [p.communicate(timeout=120) for p in procs]
    for p, (out, err) in zip(procs, outs):
        assert p.returncode in (0, 2) and "Traceback" not in err, err
        if p.returncode == 2:
            assert "in use by" in err and len(err.strip().splitlines()) == 1, err
    assert any(p.returncode == 0 for p in procs)
    assert dt.export_complete(export_ds, "bop")
    assert sorted(p.name for p in (export_ds / "exports").iterdir()) == ["bop"]


# ----------------------------------------------------------------------------- dead workers' temporaries

def test_verify_ignores_a_dead_workers_temporary_file(painted):
    tmp = painted / "meta" / f".000001.json.tmp-{HOST}-{_dead_pid()}"
    tmp.write_text('{"frame_id": "000001", "fi')
    report = dt.verify(painted)
    assert report.ok, report.text()
    assert tmp.name in report.text() and "ignored" in report.text()


def test_verify_reports_a_write_in_progress(painted):
    tmp = painted / "meta" / f".000001.json.tmp-{HOST}-{os.getpid()}"
    tmp.write_text("{")
    report = dt.verify(painted)
    assert not report.ok and tmp.name in report.text()


def test_render_removes_a_dead_workers_temporary_before_it_declares_complete(painted, no_render):
    tmp = painted / "meta" / f".000001.json.tmp-{HOST}-{_dead_pid()}"
    tmp.write_text("{")
    cfg, text = _smoke()
    summary = run_render(cfg, painted, text, JobOptions(progress=False))
    assert summary.complete and not tmp.exists()
    report = dt.verify(painted)
    assert report.ok and "ignored" not in report.text(), report.text()


def test_a_foreign_folder_gets_no_lock_file_and_a_leftover_lock_blocks_nothing(tmp_path, no_render):
    """The lock file is made only in a folder render may write: a foreign folder is refused
    before it; a folder that holds nothing but a lock file left by an earlier render is empty."""
    from dockfactory.generator.datasets.folder import DatasetError, dataset_lock, prepare
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    cfg, text = _smoke()
    with pytest.raises(DatasetError, match="not empty"):
        run_render(cfg, foreign, text, JobOptions(progress=False))
    assert sorted(p.name for p in foreign.iterdir()) == ["notes.txt"]
    fresh = tmp_path / "fresh"
    with dataset_lock(fresh, "render"):
        pass
    assert prepare(fresh, cfg, text)["name"] == "smoke"


def test_a_symlinked_lock_file_of_any_folder_is_never_written_through(tmp_path):
    """core.io.folder_lock itself (not only a dataset's lock): a lock file that is a symlink is never
    opened, the folder holding it is locked instead, and a second locker fails at once."""
    from dockfactory.core.io import FolderBusy, folder_lock
    target = tmp_path / "elsewhere.lock"
    target.write_bytes(b"not ours")
    out = tmp_path / "out"
    out.mkdir()
    os.symlink(target, out / ".dockfactory.lock")
    with folder_lock(out, "first"):
        with pytest.raises(FolderBusy, match="lock file is a symlink"):
            with folder_lock(out, "second"):
                pass
    assert target.read_bytes() == b"not ours" and (out / ".dockfactory.lock").is_symlink()
    with folder_lock(out, "again"):   # released with the block
        pass
