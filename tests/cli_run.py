"""Running ``dockfactory`` in-process for the command-line tests (tests only)."""
from dockfactory.cli import main


def run_cli(argv, capsys):
    """(exit status, stdout, stderr) of ``dockfactory ARGV``; argparse's exits count too."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def one_line_error(err: str) -> str:
    """The single line of a refusal: no traceback, one non-empty line starting "dockfactory"."""
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err and lines[0].startswith("dockfactory"), err
    return lines[0]
