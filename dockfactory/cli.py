"""The ``dockfactory`` command line: the root parser and ``main``. The command groups live in one
module each (``cli_factory``: render, dataset, check-config, show; ``cli_judge``: solve,
evaluate, report, run; ``cli_detector``: train, detect, ablate, export-onnx, noise-card;
``cli_measure``: measure; ``cli_plan``: plan-frames; ``cli_design``: design; ``cli_layout``: layout, schema) and share their
argument types (``cli_args``). Bad input (DockfactoryError) is one line and exit 2; argparse's
own errors too."""
from __future__ import annotations

import os
import sys

from dockfactory import __version__
from dockfactory.cli_args import CommandParser
from dockfactory.cli_design import add_subcommand as add_design_command
from dockfactory.cli_detector import add_subcommands as add_detector_commands
from dockfactory.cli_factory import add_subcommands as add_factory_commands
from dockfactory.cli_judge import add_eval_commands
from dockfactory.cli_layout import add_schema_subcommand
from dockfactory.cli_layout import add_subcommand as add_layout_command
from dockfactory.cli_measure import add_subcommand as add_measure_command
from dockfactory.cli_plan import add_subcommand as add_plan_command
from dockfactory.core.errors import DockfactoryError

EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_BROKEN_PIPE = 2, 130, 141   # 141: 128 + SIGPIPE, as a shell reports it


def build_parser() -> CommandParser:
    p = CommandParser(prog="dockfactory", description="Synthetic data factory and judge "
                      "for uncalibrated monocular docking of cylindrical sections.")
    p.add_argument("--version", action="version", version=f"dockfactory {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    add_factory_commands(sub)
    add_eval_commands(sub)
    add_detector_commands(sub)
    add_measure_command(sub)
    add_plan_command(sub)
    add_design_command(sub)
    add_layout_command(sub)
    add_schema_subcommand(sub)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except KeyboardInterrupt:
        print("interrupted: run the same command again to resume", file=sys.stderr)
        return EXIT_INTERRUPTED
    except DockfactoryError as exc:  # bad input: ConfigError, DatasetError, SolverError, ...
        print(f"dockfactory: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:   # the reader of standard output stopped early (`| head`): no traceback
        _silence_stdout()
        return EXIT_BROKEN_PIPE


def _silence_stdout() -> None:
    """Point standard output at the null device, so the flush at exit writes nowhere."""
    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    except OSError:
        pass   # no null device to point at: the interpreter's own message at exit is all that is left


if __name__ == "__main__":
    sys.exit(main())
