"""Argument types and helpers shared by the command groups (one place): counts, ranges, paths,
shards, tolerances, config overrides, torch threads; the parser class (CommandParser). Each type
raises argparse's error, so a bad flag is one line and exit 2 before any work."""
from __future__ import annotations

import argparse
import math
import os
from dataclasses import replace

from dockfactory.core.errors import DockfactoryError
from dockfactory.solver.errors import InvalidSolverInput
from dockfactory.solver.options import LensPrior


class CommandParser(argparse.ArgumentParser):
    """The ArgumentParser of dockfactory and of each of its sub-commands: it also keeps what it is
    given in public attributes, so a walk over every command and flag (tests, bench/cli) reads none
    of argparse's private ones. ``arguments``: the actions of ``add_argument``, in order (--help
    first; argument groups are not used); ``subcommands``: the action of ``add_subparsers`` (its
    ``choices``: name -> parser). Parsing and help are argparse's own."""

    subcommands = None

    def __init__(self, *args, **kwargs):
        self.arguments = []
        super().__init__(*args, **kwargs)

    def add_argument(self, *args, **kwargs):
        action = super().add_argument(*args, **kwargs)
        self.arguments.append(action)
        return action

    def add_subparsers(self, **kwargs):
        self.subcommands = super().add_subparsers(**kwargs)   # parser_class: this class, by default
        return self.subcommands

    def command_parsers(self) -> list[CommandParser]:
        """The parser of every sub-command below this one, nested ones after their parent's."""
        out = []
        for parser in (self.subcommands.choices.values() if self.subcommands is not None else ()):
            out += [parser, *parser.command_parsers()]
        return out


def int_at_least(low: int):
    """argparse type: an integer >= ``low`` (a negative count used to be accepted silently)."""
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer >= {low}, got {text!r}") from None
        if v < low:
            raise argparse.ArgumentTypeError(f"expected an integer >= {low}, got {text!r}")
        return v
    parse.__name__ = f"integer >= {low}"
    return parse


def shard_spec(text: str) -> tuple[int, int]:
    try:
        k, n = (int(v) for v in text.split("/"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected K/N (e.g. 2/4), got {text!r}") from None
    if not (n >= 1 and 1 <= k <= n):
        raise argparse.ArgumentTypeError(f"expected K/N with 1 <= K <= N, got {text!r}")
    return k, n


def output_path(text: str) -> str:
    """argparse type of every ``--out``: a non-empty path (an empty one named the current folder's
    parent deep inside a writer)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("expected a path, got an empty one")
    if "\0" in text:
        raise argparse.ArgumentTypeError("a path cannot hold a NUL character")
    return text


def tolerance_levels(text: str) -> float:
    """argparse type of ``--tolerance``: a finite number of 8-bit levels > 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of levels > 0, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a finite number of levels > 0, got {text!r}")
    return v


def add_set_flag(parser) -> None:
    """``--set TABLE.KEY=VALUE`` (repeatable) on a command that reads a config."""
    parser.add_argument("--set", action="append", default=[], metavar="TABLE.KEY=VALUE", dest="sets",
                        help="override a config key (repeatable), e.g. --set dataset.frames=10; validated like "
                             "the file and part of the dataset's version id")


MAX_THREADS = 64   # torch threads: far more than the cores of any machine this runs on (100000 segfaulted)


def int_in(low: int, high: int):
    """argparse type: an integer in [low, high]."""
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            v = low - 1
        if not low <= v <= high:
            raise argparse.ArgumentTypeError(f"expected an integer in [{low}, {high}], got {text!r}")
        return v
    parse.__name__ = f"integer in [{low}, {high}]"
    return parse


thread_count = int_in(1, MAX_THREADS)


def torch_threads(threads: int | None):
    """Import torch and set its threads (``threads`` in [1, MAX_THREADS]; None: one per core, at
    most MAX_THREADS); the command's entry point chose the OpenMP wait policy."""
    if threads is not None and not 1 <= threads <= MAX_THREADS:
        raise DockfactoryError(f"--threads: expected an integer in [1, {MAX_THREADS}], got {threads}")
    import torch
    torch.set_num_threads(threads or min(MAX_THREADS, os.cpu_count() or 1))
    return torch


positive_int = int_at_least(1)
non_negative_int = int_at_least(0)


def float_in(low: float, high: float, low_open: bool = False):
    """argparse type: a finite number in [low, high] (``(low, high]`` with ``low_open``)."""
    span = f"{'(' if low_open else '['}{low:g}, {high:g}]"

    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            v = math.nan
        if not (math.isfinite(v) and (v > low if low_open else v >= low) and v <= high):
            raise argparse.ArgumentTypeError(f"expected a number in {span}, got {text!r}")
        return v
    parse.__name__ = f"number in {span}"
    return parse


unit_float = float_in(0.0, 1.0)                 # scores and IoU thresholds
input_scale = float_in(0.0, 8.0, low_open=True)  # network px per image px
learning_rate = float_in(0.0, 1.0, low_open=True)  # SGD's initial learning rate


LENS_PRIOR_KEYS = {"pp": "pp_fraction", "k1": "k1", "k2": "k2", "p": "p"}


def lens_prior(text: str):
    """argparse type of ``--lens-prior``: what is plausible for the intrinsics the camera model does
    not estimate (solver.options.LensPrior, marginalised into every pose's uncertainty).
    ``default``: an uncalibrated camera's generic ranges; ``known``: a calibrated lens (nothing
    marginalised); or ``pp=F,k1=A,k2=B,p=C``: half-ranges (the principal point's as a fraction of the
    image width; keys not given keep the default's)."""
    base = LensPrior(marginalise=True)
    if text == "default":
        return base
    if text == "known":
        return replace(base, marginalise=False)
    values = {}
    for item in text.split(","):
        key, sep, value = item.partition("=")
        if not sep or key.strip() not in LENS_PRIOR_KEYS:
            raise argparse.ArgumentTypeError(f"expected default, known or pp=F,k1=A,k2=B,p=C "
                                             f"(keys {', '.join(LENS_PRIOR_KEYS)}), got {item!r}")
        try:
            values[LENS_PRIOR_KEYS[key.strip()]] = float(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{key.strip()}: expected a number, got {value!r}") from None
    try:
        return replace(base, **values)
    except InvalidSolverInput as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
