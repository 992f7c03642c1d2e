"""Bad command-line input is one line and exit 2, never a traceback (issue 10, finding 8: flags,
``show``, multi-path ``dataset`` commands, damaged dataset.json / manifest, unwritable outputs).

No rendering: datasets come from tests/pipeline_data.py (the smoke config, painted); commands
that would render or train are replaced by stubs that must not be reached.
"""
import errno
import json
import os
import shutil

import pytest

from dockfactory.core import io as io_mod
from cli_run import run_cli

from dockfactory.core.errors import DockfactoryError
from dockfactory.core.io import write_bytes_atomic, write_json_atomic
from dockfactory.cli import main


def _one_line_error(err: str) -> str:
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert lines and "Traceback" not in err, err
    assert "error:" in lines[-1], err
    return lines[-1]


@pytest.fixture
def painted(painted_source):
    return painted_source   # read only here: tests that damage a dataset take copy_of(...)


@pytest.fixture
def copy_of(painted, tmp_path):
    def make(name: str):
        dst = tmp_path / name
        shutil.copytree(painted, dst)
        return dst
    return make


def _a_frame(root) -> str:
    return min(p.stem for p in (root / "labels").glob("*.json"))


# ----------------------------------------------------------------------------- show

@pytest.mark.parametrize("frame_id", ["999999", "nope", "../labels/000000", ""])
def test_show_unknown_frame_names_dataset_and_id(painted, tmp_path, capsys, frame_id):
    code, _, err = run_cli(["show", painted, frame_id, "--out", tmp_path / "o.png"], capsys)
    line = _one_line_error(err)
    assert code == 2 and str(painted) in line and repr(frame_id) in line
    assert not (tmp_path / "o.png").exists()


def test_show_refuses_a_stray_frame_and_a_symlinked_image(copy_of, tmp_path, capsys):
    """show reads a frame of the plan, inside the dataset: a stray label+image pair is not a frame,
    and an image that is a symlink to outside is never read."""
    painted = copy_of("s")
    fid = _a_frame(painted)
    shutil.copy(painted / "labels" / f"{fid}.json", painted / "labels" / "999999.json")
    shutil.copy(painted / "images" / f"{fid}.png", painted / "images" / "999999.png")
    code, _, err = run_cli(["show", painted, "999999", "--out", tmp_path / "o.png"], capsys)
    assert code == 2 and "plan" in _one_line_error(err)
    secret = tmp_path / "secret.png"
    shutil.move(painted / "images" / f"{fid}.png", secret)
    (painted / "images" / f"{fid}.png").symlink_to(secret)
    code, _, err = run_cli(["show", painted, fid, "--out", tmp_path / "o.png"], capsys)
    assert code == 2 and "symlink" in _one_line_error(err) and not (tmp_path / "o.png").exists()


def test_show_not_a_dataset(tmp_path, capsys):
    code, _, err = run_cli(["show", tmp_path, "000000", "--out", tmp_path / "o.png"], capsys)
    assert code == 2 and str(tmp_path) in _one_line_error(err)


def test_show_draws_a_known_frame(painted, tmp_path, capsys):
    out = tmp_path / "o.png"
    code, _, _ = run_cli(["show", painted, _a_frame(painted), "--out", out], capsys)
    assert code == 0 and out.stat().st_size > 0


def test_show_out_is_a_folder(painted, tmp_path, capsys):
    folder = tmp_path / "folder"
    folder.mkdir()
    code, _, err = run_cli(["show", painted, _a_frame(painted), "--out", folder], capsys)
    assert code == 2 and str(folder) in _one_line_error(err)
    assert os.listdir(folder) == [] and [p.name for p in tmp_path.iterdir()] == ["folder"]  # no temporary left


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_show_out_in_a_read_only_folder(painted, tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        code, _, err = run_cli(["show", painted, _a_frame(painted), "--out", ro / "o.png"], capsys)
    finally:
        ro.chmod(0o755)
    assert code == 2 and str(ro / "o.png") in _one_line_error(err)


@pytest.mark.parametrize("exc", [OSError(errno.ENOSPC, "No space left on device"),
                                 PermissionError(errno.EACCES, "Permission denied")], ids=["full", "read-only"])
def test_show_out_write_fails(painted, tmp_path, capsys, monkeypatch, exc):
    """A full disk (or a refused write) surfaces at fsync/close; simulated, since root ignores modes."""
    out = tmp_path / "o.png"
    out.write_bytes(b"old")

    def fail(fd):
        raise exc
    monkeypatch.setattr(io_mod.os, "fsync", fail)
    code, _, err = run_cli(["show", painted, _a_frame(painted), "--out", out], capsys)
    line = _one_line_error(err)
    assert code == 2 and str(out) in line and exc.strerror in line
    assert out.read_bytes() == b"old"                          # atomic: the old file is untouched
    assert [p.name for p in tmp_path.iterdir()] == ["o.png"]   # and no temporary is left


def test_write_errors_are_dockfactory_errors_and_still_oserrors(tmp_path):
    (tmp_path / "d").mkdir()
    with pytest.raises(DockfactoryError) as err:
        write_json_atomic(tmp_path / "d", {"a": 1})
    assert isinstance(err.value, OSError) and err.value.errno == errno.EISDIR
    assert str(tmp_path / "d") in str(err.value) and "\n" not in str(err.value)
    (tmp_path / "file").write_text("x")
    with pytest.raises(DockfactoryError, match="file"):     # a parent that is a file
        write_bytes_atomic(tmp_path / "file" / "sub" / "o.bin", b"x")


# ----------------------------------------------------------------------------- dataset A B

def test_verify_takes_every_path(painted, copy_of, capsys):
    b = copy_of("b")
    code, out, _ = run_cli(["dataset", "verify", painted, b], capsys)
    assert code == 0 and str(painted) in out and str(b) in out
    label = min((b / "labels").glob("*.json"))
    label.write_text(label.read_text().replace('"x_mm": ', '"x_mm": 1'))   # B damaged, A intact
    code, out, _ = run_cli(["dataset", "verify", painted, b], capsys)
    assert code == 1 and f"{b}: FAILED" in out and f"{painted}: OK" in out
    code, out, _ = run_cli(["dataset", "verify", b, painted], capsys)     # order does not matter
    assert code == 1 and f"{b}: FAILED" in out


def test_verify_second_path_not_a_dataset(painted, tmp_path, capsys):
    code, _, err = run_cli(["dataset", "verify", painted, tmp_path / "nothing"], capsys)
    assert code == 2 and str(tmp_path / "nothing") in _one_line_error(err)


def test_info_takes_every_path(painted, copy_of, capsys):
    b = copy_of("b")
    code, out, _ = run_cli(["dataset", "info", painted, b], capsys)
    assert code == 0 and str(painted) in out and str(b) in out
    code, out, _ = run_cli(["dataset", "info", painted, b, "--json"], capsys)
    assert code == 0 and [d["root"] for d in json.loads(out)] == [str(painted), str(b)]
    code, out, _ = run_cli(["dataset", "info", painted, "--json"], capsys)   # one path: one object, as before
    assert code == 0 and json.loads(out)["root"] == str(painted)


BAD_IDENTITIES = ["[]", "null", '"x"', "{}", '{"name": "x"}', '{"config": []}']


@pytest.mark.parametrize("content", BAD_IDENTITIES)
@pytest.mark.parametrize("action", ["info", "diff"])
def test_bad_dataset_json(painted, copy_of, capsys, content, action):
    b = copy_of("b")
    (b / "dataset.json").write_text(content)
    code, _, err = run_cli(["dataset", action, b] + ([painted] if action == "diff" else []), capsys)
    assert code == 2 and str(b / "dataset.json") in _one_line_error(err)


@pytest.mark.parametrize("content", BAD_IDENTITIES)
def test_verify_calls_a_damaged_identity_damage(painted, copy_of, capsys, content):
    """A dataset whose dataset.json is damaged is a FAILED dataset (exit 1, the file named), not
    bad input: the folder is a dataset, its identity is what broke."""
    b = copy_of("b")
    (b / "dataset.json").write_text(content)
    code, out, err = run_cli(["dataset", "verify", b], capsys)
    assert code == 1 and "FAILED" in out and "corrupt: dataset.json" in out and not err


@pytest.mark.parametrize("manifest", [{}, [], {"files": None}, {"files": [{"path": "x"}]},
                                      {"files": [{"path": 3, "bytes": "1", "sha256": 1}]}],
                         ids=["no-files", "list", "files-null", "record-keys", "record-types"])
@pytest.mark.parametrize("action", ["info", "verify", "diff"])
def test_bad_manifest(painted, copy_of, capsys, manifest, action):
    b = copy_of("b")
    (b / "manifest.json").write_text(json.dumps(manifest))
    code, out, err = run_cli(["dataset", action, b] + ([painted] if action == "diff" else []), capsys)
    assert "Traceback" not in err
    if action == "verify":          # verify reports a damaged manifest as a failed dataset
        assert code == 1 and f"{b}: FAILED" in out and "manifest.json" in out
    else:
        assert code == 2 and str(b / "manifest.json") in _one_line_error(err)


def test_manifest_without_counts_info(copy_of, capsys):
    b = copy_of("b")
    manifest = json.loads((b / "manifest.json").read_text())
    del manifest["counts"]
    (b / "manifest.json").write_text(json.dumps(manifest))
    code, _, err = run_cli(["dataset", "info", b], capsys)
    assert code == 2 and str(b / "manifest.json") in _one_line_error(err)


# ----------------------------------------------------------------------------- flags

@pytest.fixture
def no_render(monkeypatch):
    calls = []
    monkeypatch.setattr("dockfactory.cli_factory.run_render", lambda *a, **k: calls.append(a))
    return calls


@pytest.mark.parametrize("flags", [["--retries", "-1"], ["--recycle-after", "0"], ["--recycle-after", "-5"],
                                   ["--workers", "0"], ["--workers", "-2"]])
def test_render_flags(tmp_path, capsys, no_render, flags):
    code, _, err = run_cli(["render", "smoke", "--out", tmp_path / "o", *flags], capsys)
    assert code == 2 and flags[0] in _one_line_error(err)
    assert no_render == [] and not (tmp_path / "o").exists()


@pytest.fixture
def no_pipeline(monkeypatch):
    calls = []
    monkeypatch.setattr("dockfactory.cli_judge.run_pipeline", lambda *a, **k: calls.append((a, k)) or 0)
    return calls


@pytest.mark.parametrize("flags, named", [
    (["--train", "--weights", "w.pt"], "--weights"),
    (["--epochs", "3"], "--epochs"),                       # --epochs without --train did nothing
    (["--oracle-noise", "1", "--weights", "w.pt"], "--oracle-noise"),
    (["--oracle-noise", "1", "--train"], "--oracle-noise"),
    (["--oracle-noise", "-1"], "--oracle-noise"),
    (["--oracle-noise", "nan"], "--oracle-noise"),
    (["--workers", "0"], "--workers"),
    (["--workers", "-1"], "--workers"),
    (["--train", "--epochs", "0"], "--epochs"),
])
def test_run_flags(tmp_path, capsys, no_pipeline, flags, named):
    code, _, err = run_cli(["run", "smoke", "--out", tmp_path / "w", *flags], capsys)
    assert code == 2 and named in _one_line_error(err)
    assert no_pipeline == [] and not (tmp_path / "w").exists()


def test_run_missing_weights(tmp_path, capsys, no_pipeline):
    code, _, err = run_cli(["run", "smoke", "--out", tmp_path / "w", "--weights", tmp_path / "nope.pt"], capsys)
    assert code == 2 and "nope.pt" in _one_line_error(err)
    assert no_pipeline == [] and not (tmp_path / "w").exists()


def test_run_invalid_config_writes_nothing(tmp_config, tmp_path, capsys, no_pipeline):
    path = tmp_config("[camera]\nmargin_px = nan\n")
    code, _, err = run_cli(["run", path, "--out", tmp_path / "w"], capsys)
    assert code == 2 and "margin_px" in _one_line_error(err)
    assert no_pipeline == [] and not (tmp_path / "w").exists()


def test_run_good_flags_reach_the_pipeline(tmp_path, capsys, no_pipeline):
    code, _, _ = run_cli(["run", "smoke", "--out", tmp_path / "w", "--train", "--epochs", "2"], capsys)
    assert code == 0 and len(no_pipeline) == 1 and no_pipeline[0][1]["train_epochs"] == 2


@pytest.mark.parametrize("argv", [
    ["train", "{d}", "--out", "{t}/r", "--threads", "-1"],
    ["train", "{d}", "--out", "{t}/r", "--threads", "0"],
    ["train", "{d}", "--out", "{t}/r", "--input-scale", "nan"],
    ["train", "{d}", "--out", "{t}/r", "--input-scale", "0"],
    ["train", "{d}", "--out", "{t}/r", "--seed", "-1"],
    ["ablate", "{d}", "--out", "{t}/a", "--input-scale", "-1"],
    ["ablate", "{d}", "--out", "{t}/a", "--conf", "1.5"],
    ["detect", "{d}", "--out", "{t}/x.json", "--conf", "nan"],
    ["detect", "{d}", "--out", "{t}/x.json", "--conf", "-0.1"],
    ["detect", "{d}", "--out", "{t}/x.json", "--iou", "2"],
    ["detect", "{d}", "--out", "{t}/x.json", "--threads", "-4"],
    ["export-onnx", "--out", "{t}/m.onnx", "--height", "0"],
    ["export-onnx", "--out", "{t}/m.onnx", "--width", "-64"],
])
def test_detector_flags(tmp_path, capsys, argv):
    argv = [a.format(d=tmp_path / "no-dataset", t=tmp_path) for a in argv]
    code, _, err = run_cli(argv, capsys)
    assert code == 2 and argv[-2] in _one_line_error(err)
    assert sorted(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", [["check-config"], ["render", "--out", "ds"], ["plan-frames", "--rmse", "x=0.4"]])
def test_a_deeply_nested_toml_is_one_line(tmp_path, capsys, command):
    """A config (or spec) nested thousands deep: exit 2, one line naming the file (it was a
    RecursionError traceback); nothing written."""
    path = tmp_path / "deep.toml"
    path.write_text("[spec]\nx = " + "[" * 5000 + "]" * 5000 + "\n")
    argv = [command[0], str(path)] + [str(tmp_path / a) if a == "ds" else a for a in command[1:]]
    code, _, err = run_cli(argv, capsys)
    assert code == 2 and "deep.toml: not valid TOML: its arrays or tables nest too deeply" in err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "ds").exists()


@pytest.mark.parametrize("value", ["dataset.name=a\nb", "dataset.name=a\rb", "dataset.name=a\x01b", "dataset.name=a\tb"])
def test_a_set_value_with_a_control_character_is_one_line(capsys, value):
    code, _, err = run_cli(["check-config", "smoke", "--set", value], capsys)
    assert code == 2 and "control character" in err and len(err.strip().splitlines()) == 1


def test_a_huge_camera_index_is_refused_by_the_parser(tmp_path, capsys):
    """--camera 10^20 (OpenCV: 'Python int too large to convert to C long', a garbled error list):
    refused before anything opens, naming the range."""
    with pytest.raises(SystemExit) as exc:
        main(["measure", "--camera", "99999999999999999999", "--layout", str(tmp_path / "l.json")])
    assert exc.value.code == 2 and "expected an integer in [0, 1023]" in capsys.readouterr().err
