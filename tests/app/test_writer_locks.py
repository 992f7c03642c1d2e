"""Every writer takes the lock the renderer takes on its output folder (core.io.folder_lock): a
second writer into the same folder is refused in one line (exit 2) and writes nothing; an output
that cannot be a folder (a file, under a file, read-only, /proc) is one line, exit 2, nothing
half written; ``show`` writes the format its --out suffix names.

The painted smoke dataset (tests/pipeline_data.py) stands in for a render. A read-only folder is
simulated (root writes into any folder): mkdir, open for writing and access(W_OK) under it fail
with EROFS, as on a read-only mount.
"""
import builtins
import errno
import json
import os

import cv2
import pytest

from dockfactory.core.io import folder_lock
from dockfactory import cli_judge as cli_mod
from cli_run import one_line_error, run_cli

from dockfactory.cli import main


@pytest.fixture(scope="module")
def poses(painted_source, tmp_path_factory):
    path = tmp_path_factory.mktemp("poses") / "poses.json"
    assert main(["solve", str(painted_source), "--oracle-noise", "0.05", "--out", str(path)]) == 0
    return path


@pytest.fixture(scope="module")
def eval_dir(painted_source, poses, tmp_path_factory):
    out = tmp_path_factory.mktemp("eval")
    assert main(["evaluate", str(painted_source), "--poses", str(poses), "--out", str(out)]) in (0, 1, 3)
    return out


@pytest.fixture
def read_only(tmp_path, monkeypatch):
    """A folder that behaves as on a read-only mount, even for root."""
    ro = tmp_path / "ro"
    ro.mkdir()
    real_mkdir, real_open, real_os_open, real_access = os.mkdir, builtins.open, os.open, os.access

    def inside(p) -> bool:
        p = os.path.abspath(os.fspath(p))
        return p == str(ro) or p.startswith(str(ro) + os.sep)

    def erofs(p):
        return OSError(errno.EROFS, "Read-only file system", os.fspath(p))

    def mkdir(p, *a, **k):
        if inside(p):
            raise erofs(p)
        return real_mkdir(p, *a, **k)

    def os_open(p, flags, *a, **k):
        if inside(p) and flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT):
            raise erofs(p)
        return real_os_open(p, flags, *a, **k)

    def open_(p, mode="r", *a, **k):
        if isinstance(p, (str, os.PathLike)) and inside(p) and any(c in mode for c in "wax+"):
            raise erofs(p)
        return real_open(p, mode, *a, **k)

    def access(p, mode, *a, **k):
        return False if inside(p) and mode & os.W_OK else real_access(p, mode, *a, **k)
    monkeypatch.setattr(os, "mkdir", mkdir)
    monkeypatch.setattr(os, "open", os_open)
    monkeypatch.setattr(builtins, "open", open_)
    monkeypatch.setattr(os, "access", access)
    return ro


# ----------------------------------------------------------------------------- evaluate, report

def test_a_second_evaluate_into_the_same_folder_is_refused(painted_source, poses, tmp_path, capsys):
    out = tmp_path / "eval"
    with folder_lock(out, "evaluate"):   # the first run, still writing
        code, _, err = run_cli(["evaluate", painted_source, "--poses", poses, "--out", out], capsys)
    assert code == 2 and "in use by another dockfactory process" in one_line_error(err) and str(out) in err
    assert not (out / "metrics.json").exists() and not (out / "frames.csv").exists()


def test_evaluate_holds_its_lock_until_the_verdict_is_printed(painted_source, poses, tmp_path, capsys, monkeypatch):
    """The printed verdict is the one in metrics.json: no other writer can get in between."""
    out, seen = tmp_path / "eval", []
    real = cli_mod.write_outputs

    def write_then_try_the_lock(*a, **k):
        real(*a, **k)
        try:
            with folder_lock(out, "intruder"):
                seen.append("got in")
        except ValueError as exc:
            seen.append(str(exc))
    monkeypatch.setattr(cli_mod, "write_outputs", write_then_try_the_lock)
    code, stdout, _ = run_cli(["evaluate", painted_source, "--poses", poses, "--out", out], capsys)
    assert len(seen) == 1 and "in use by another dockfactory process" in seen[0] and "evaluate" in seen[0]
    accepted = json.loads((out / "metrics.json").read_text())["acceptance"]["accepted"]
    assert code == (0 if accepted else 1) and f"verdict: {'ACCEPTED' if accepted else 'REJECTED'}" in stdout


def test_report_refuses_a_folder_another_writer_holds(eval_dir, tmp_path, capsys):
    folder = tmp_path / "report"
    with folder_lock(folder, "report"):
        code, _, err = run_cli(["report", eval_dir, "--out", folder / "r.html"], capsys)
    assert code == 2 and "in use" in one_line_error(err)
    assert sorted(p.name for p in folder.iterdir()) == [".dockfactory.lock"]


def test_evaluate_into_a_file_is_one_line(painted_source, poses, tmp_path, capsys):
    out = tmp_path / "f"
    out.write_text("mine")
    code, _, err = run_cli(["evaluate", painted_source, "--poses", poses, "--out", out], capsys)
    assert code == 2 and f"--out {out}: is a file, not a folder" in one_line_error(err) and out.read_text() == "mine"


# ----------------------------------------------------------------------------- measure

def _measure_out(tmp_path, out, capsys):
    fifo = tmp_path / "cam.png"   # reported without loading the detector (the layout fixture made it)
    return run_cli(["measure", fifo, "--layout", tmp_path / "layout.json", "--out", out, "--quiet"], capsys)


@pytest.fixture
def layout(painted_source, tmp_path):
    (tmp_path / "layout.json").write_bytes((painted_source / "layout.json").read_bytes())
    os.mkfifo(tmp_path / "cam.png")


@pytest.mark.parametrize("where", ["a file", "under a file", "proc", "read-only", "under read-only"])
def test_measure_out_that_cannot_be_written_is_one_line(tmp_path, capsys, layout, request, where):
    (tmp_path / "file").write_text("mine")
    out = {"a file": tmp_path / "file", "under a file": tmp_path / "file" / "sub",
           "proc": "/proc/dockfactory-measure-out"}.get(where)
    if out is None:
        ro = request.getfixturevalue("read_only")
        out = ro if where == "read-only" else ro / "sub"
    before = sorted(os.listdir(tmp_path))
    code, _, err = _measure_out(tmp_path, out, capsys)
    assert code == 2 and str(out) in one_line_error(err)
    assert sorted(os.listdir(tmp_path)) == before and (tmp_path / "file").read_text() == "mine"
    if where.endswith("read-only"):
        assert os.listdir(tmp_path / "ro") == []


def test_measure_refuses_a_folder_another_writer_holds(tmp_path, capsys, layout):
    out = tmp_path / "out"
    with folder_lock(out, "measure"):
        code, _, err = _measure_out(tmp_path, out, capsys)
    assert code == 2 and "in use" in one_line_error(err) and not (out / "measurements.json").exists()


# ----------------------------------------------------------------------------- dataset publish, export-onnx

@pytest.mark.parametrize("where", ["a file", "read-only", "held"])
def test_publish_into_a_folder_it_cannot_have_is_one_line(painted_source, tmp_path, capsys, request, where):
    (tmp_path / "file").write_text("mine")
    out = tmp_path / "file" if where == "a file" else tmp_path / "pub"
    if where == "read-only":
        out = request.getfixturevalue("read_only")
    if where == "held":
        with folder_lock(out, "dataset publish"):
            code, _, err = run_cli(["dataset", "publish", painted_source, "--out", out], capsys)
    else:
        code, _, err = run_cli(["dataset", "publish", painted_source, "--out", out], capsys)
    assert code == 2 and str(out) in one_line_error(err)
    assert (tmp_path / "file").read_text() == "mine"
    assert not out.is_dir() or [p.name for p in out.iterdir() if p.name != ".dockfactory.lock"] == []


@pytest.mark.parametrize("where", ["read-only", "held", "a folder"])
def test_export_onnx_where_it_cannot_write_is_one_line(tmp_path, capsys, request, where):
    folder = request.getfixturevalue("read_only") if where == "read-only" else tmp_path / "models"
    folder.mkdir(exist_ok=True)
    out = folder if where == "a folder" else folder / "m.onnx"
    if where == "held":
        with folder_lock(folder, "export-onnx"):
            code, _, err = run_cli(["export-onnx", "--out", out, "--no-check"], capsys)
    else:
        code, _, err = run_cli(["export-onnx", "--out", out, "--no-check"], capsys)
    assert code == 2 and str(folder if where == "held" else out) in one_line_error(err)
    assert [p.name for p in folder.iterdir() if p.name != ".dockfactory.lock"] == []


# ----------------------------------------------------------------------------- show

def _a_frame(root) -> str:
    return sorted((root / "images").glob("*.png"))[0].stem


@pytest.mark.parametrize("name, magic", [("o.jpg", b"\xff\xd8\xff"), ("o.JPEG", b"\xff\xd8\xff"),
                                         ("o.png", b"\x89PNG\r\n\x1a\n")])
def test_show_writes_the_format_its_suffix_names(painted_source, tmp_path, capsys, name, magic):
    out = tmp_path / name
    code, _, _ = run_cli(["show", painted_source, _a_frame(painted_source), "--out", out], capsys)
    assert code == 0 and out.read_bytes().startswith(magic)
    frame = cv2.imread(str(painted_source / "images" / f"{_a_frame(painted_source)}.png"))
    assert cv2.imread(str(out)).shape == frame.shape


def test_show_refuses_a_suffix_it_cannot_write(painted_source, tmp_path, capsys):
    out = tmp_path / "o.gif"
    code, _, err = run_cli(["show", painted_source, _a_frame(painted_source), "--out", out], capsys)
    assert code == 2 and "'.gif'" in one_line_error(err) and str(out) in err and os.listdir(tmp_path) == []
