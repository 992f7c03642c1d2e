"""Command-line conventions a user expects: ``--version``; each ``dataset`` action its own parser,
help and flags (a flag of another action is an error, not silently ignored)."""
import pytest

from dockfactory import __version__
from dockfactory.cli import main


def _exit(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main([str(a) for a in argv])
    return exc.value.code, capsys.readouterr()


def test_version(capsys):
    code, out = _exit(["--version"], capsys)
    assert code == 0 and out.out.strip() == f"dockfactory {__version__}"


@pytest.mark.parametrize("argv, words", [
    (["dataset", "info", "D", "--manifest", "m.json"], "unrecognized arguments: --manifest"),
    (["dataset", "export", "D", "--json"], "unrecognized arguments: --json"),
    (["dataset", "verify", "D", "--format", "coco"], "unrecognized arguments: --format"),
    (["dataset", "diff", "A"], "required: DIR_B"),
    (["dataset", "diff", "A", "B", "C"], "unrecognized arguments: C"),
    (["dataset", "publish", "D"], "required: --out"),
    (["dataset", "nope", "D"], "invalid choice: 'nope'"),
])
def test_each_dataset_action_takes_only_its_own_flags(capsys, argv, words):
    code, out = _exit(argv, capsys)
    assert code == 2 and words in out.err, out.err


@pytest.mark.parametrize("action, flag", [("verify", "--manifest"), ("info", "--json"), ("diff", "DIR_B"),
                                          ("export", "--format"), ("publish", "--out"), ("card", "--license")])
def test_each_dataset_action_has_its_own_help(capsys, action, flag):
    code, out = _exit(["dataset", action, "--help"], capsys)
    assert code == 0 and f"dockfactory dataset {action}" in out.out and flag in out.out
    others = {"verify": "--manifest", "info": "--json", "export": "--format", "publish": "--out", "card": "--license"}
    others = {a: f for a, f in others.items() if not (action == "diff" and f == "--json")   # diff has --json too
              and not (action == "export" and f == "--out")}                              # export has --out too
    assert all(f not in out.out for a, f in others.items() if a != action and f != flag)


def _out_commands():
    from dockfactory.cli import build_parser
    return sorted(p.prog.replace("dockfactory ", "") for p in build_parser().command_parsers()
                  if any(a.dest == "out" for a in p.arguments))


def test_the_walk_finds_every_command_with_an_out_flag():
    assert len(_out_commands()) == 17 and {"render", "dataset export", "layout from-csv", "schema"} <= set(_out_commands())


@pytest.mark.parametrize("command", _out_commands())
def test_an_empty_out_path_is_refused_by_every_command(capsys, command):
    """`solve --out ""` and `show --out ""` ended in a traceback deep in the atomic writer."""
    argv = command.split() + ["--out", ""]
    code, out = _exit(argv, capsys)
    assert code == 2 and "argument --out: expected a path, got an empty one" in out.err, out.err


@pytest.mark.parametrize("argv", [
    ["train", "D", "--out", "O", "--crops-per-frame", "1000000000"],   # asked numpy for a 30 GB index array
    ["train", "D", "--out", "O", "--batch", "1000000000"],
    ["train", "D", "--out", "O", "--epochs", "0"],
    ["ablate", "D", "--seeds", "100000"],
    ["export-onnx", "--out", "m.onnx", "--height", "100000"],
])
def test_training_and_export_sizes_have_named_limits(capsys, argv):
    code, out = _exit(argv, capsys)
    assert code == 2 and "expected an integer in [" in out.err, out.err


@pytest.mark.parametrize("record", ["/dev/null", "/proc/self/x"])
def test_ablate_checks_its_folders_before_training(painted_source, tmp_path, capsys, record):
    """`ablate --record FILE` trained a whole run, then ended in a FileExistsError traceback."""
    from cli_run import one_line_error, run_cli
    code, _, err = run_cli(["ablate", painted_source, "--out", tmp_path / "abl", "--epochs", "1",
                            "--record", record], capsys)
    assert code == 2 and "--record" in one_line_error(err) and not list((tmp_path / "abl").glob("*/"))


def test_output_cut_short_by_its_reader_is_no_traceback():
    """`dockfactory check-config smoke | head -1`: the reader closes the pipe early; the command
    stops quietly with the shell's SIGPIPE status (141), no traceback on standard error. (The
    pipe's read end is closed before the command writes, so every write fails.)"""
    import os
    import subprocess
    import sys
    read_end, write_end = os.pipe()
    os.close(read_end)
    proc = subprocess.run([sys.executable, "-m", "dockfactory", "check-config", "smoke", "--resolved"],
                          stdout=write_end, stderr=subprocess.PIPE, timeout=60)
    os.close(write_end)
    err = proc.stderr.decode()
    assert proc.returncode == 141, err
    assert "Traceback" not in err and "BrokenPipeError" not in err, err
