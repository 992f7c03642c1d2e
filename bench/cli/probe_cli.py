"""Probe every command-line flag with odd values, the way a new user's typos and scripts would:
no attempt may end in a traceback, a signal or a hang.

    python -m bench.cli.probe_cli [--out RESULTS.txt] [--timeout S] [--commands NAME,NAME]

Builds a small world without Blender (the painted smoke dataset of tests/pipeline_data.py, its
poses, an evaluation folder, a layout, a folder of its images, a fifo, a junk file, an empty file,
a read-only folder), then for every sub-command of ``dockfactory`` (discovered from the parser) and
every option it takes, runs the command with otherwise valid arguments and that option set to
each odd value of its kind: numbers (nan, inf, -1, 0, 1e308, 1e9, "abc", ""), paths (missing, a
folder, a file where a folder is expected, the fifo, /dev/null, the junk file, a read-only
folder), choices (an unknown one); and every positional argument replaced the same way. Each
attempt is its own process with a timeout. An attempt passes when it exits 0, 1, 2 or 3 (not proven) without
"Traceback" on stderr; a timeout is a pass only for commands that start real work (render, run,
train, ablate, detect, noise-card, measure, export-onnx, design), where a valid odd value may well start
it. Prints one line per failing attempt and a summary; writes them to ``--out``.
"""
from __future__ import annotations

import argparse
import json
import os
import stat
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

NUMBERS = ("nan", "inf", "-1", "0", "1e308", "1000000000", "abc", "")
WORKING = {"render", "run", "train", "ablate", "detect", "noise-card", "measure", "export-onnx", "design"}


def build_world(base: Path) -> dict:
    """The files the probes use (valid ones, then odd ones)."""
    from tests.pipeline_data import write_painted_dataset

    from dockfactory.core.resources import shipped_config
    from dockfactory.eval.acceptance import AcceptanceSpec
    from dockfactory.eval.evaluate import evaluate, write_outputs
    from dockfactory.eval.solve_frames import solve_dataset
    from dockfactory.generator.datasets.reader import Dataset
    ds_root = base / "dataset"
    write_painted_dataset(ds_root, shipped_config("smoke"))
    ds = Dataset.open(ds_root)
    (base / "poses.json").write_text(json.dumps(solve_dataset(ds, oracle_sigma_px=0.1)))
    metrics, rows = evaluate(ds, base / "poses.json", AcceptanceSpec(), oracle=False, oracle_sigma_px=0.1)
    write_outputs(base / "eval", metrics, rows)
    images = base / "images"
    images.mkdir()
    for p in sorted((ds_root / "images").glob("*.png"))[:2]:
        (images / p.name).write_bytes(p.read_bytes())
    os.mkfifo(base / "fifo")
    (base / "junk").write_bytes(os.urandom(256))
    (base / "empty").write_bytes(b"")
    (base / "readonly").mkdir()
    os.chmod(base / "readonly", stat.S_IRUSR | stat.S_IXUSR)
    return {"dataset": str(ds_root), "poses": str(base / "poses.json"), "eval": str(base / "eval"),
            "layout": str(ds_root / "layout.json"), "images": str(images), "config": str(shipped_config("smoke")),
            "base": base}


def base_args(command: str, w: dict) -> list[str]:
    """Valid arguments of ``command`` (positional and required), outputs under the world."""
    out = str(w["base"] / f"out_{command}")
    return {"render": [w["config"], "--out", out], "dataset": ["verify", w["dataset"]],
            "check-config": [w["config"]], "show": [w["dataset"], "000000", "--out", out + ".png"],
            "solve": [w["dataset"], "--oracle-noise", "0.1", "--out", out + ".json"],
            "evaluate": [w["dataset"], "--poses", w["poses"], "--out", out],
            "report": [w["eval"], "--out", out + ".html"], "run": [w["config"], "--out", out],
            "train": [w["dataset"], "--out", out, "--epochs", "1"], "detect": [w["dataset"], "--out", out + ".json"],
            "ablate": [w["dataset"], "--out", out, "--epochs", "1", "--seeds", "1"],
            "export-onnx": ["--out", out + ".onnx"], "noise-card": [w["dataset"]],
            "measure": [w["images"], "--layout", w["layout"], "--out", out],
            "plan-frames": ["--config", w["config"]], "design": ["docking_cell", "--out", out],
            "layout": ["from-config", w["config"], "--out", out + ".json"], "schema": ["labels", "--out", out + ".json"]
            }[command]


def odd_paths(w: dict) -> tuple[str, ...]:
    b = w["base"]
    return ("/nonexistent/x", str(b), str(b / "junk"), str(b / "fifo"), "/dev/null", str(b / "empty"),
            str(b / "readonly" / "x"), "/proc/self/x")


def attempts(parser, w: dict):
    """(command, argv) pairs: every option and positional of every sub-command of ``parser``
    (dockfactory's: a cli_args.CommandParser), each odd value."""
    for name, sp in parser.subcommands.choices.items():
        base = base_args(name, w)
        for action in sp.arguments:
            if action.option_strings and action.option_strings[0] in ("-h", "--help"):
                continue
            yield from _values_for(name, base, action, w)


def _values_for(name: str, base: list[str], action, w: dict):
    if not action.option_strings:          # a positional: replace the first valid one of its place
        position = [a for a in base if not a.startswith("--")]
        if action.dest in ("action",) or not position:
            return
        idx = base.index(position[0]) if action.dest != "frame_id" else 1
        for v in odd_paths(w) + ("", "-"):
            argv = list(base)
            argv[idx] = v
            yield name, argv
        return
    flag = action.option_strings[-1]
    if action.nargs == 0:
        yield name, base + [flag]
        return
    if action.choices:
        values = ("unknown", "")
    elif action.type in (int, float) or (action.type is not None and action.type not in (str, Path)):
        values = NUMBERS
    else:
        values = odd_paths(w) + ("",)
    for v in values:
        argv = [a for a in base]
        if flag in argv:
            argv[argv.index(flag) + 1] = v
        else:
            argv += [flag, v]
        yield name, argv


def run_one(name: str, argv: list[str], timeout: float) -> str | None:
    """None when the attempt passes, else why not (a command that starts real work gets a
    quarter of ``timeout``: its odd values are refused in a second, or the work starts)."""
    timeout = timeout / 4 if name in WORKING else timeout
    try:
        proc = subprocess.run([sys.executable, "-m", "dockfactory", name, *argv], capture_output=True, text=True,
                              timeout=timeout, stdin=subprocess.DEVNULL, cwd=tempfile.gettempdir())
    except subprocess.TimeoutExpired:
        return None if name in WORKING else f"hang (> {timeout:g} s)"
    if "Traceback" in proc.stderr:
        return "traceback: " + proc.stderr.strip().splitlines()[-1][:160]
    if proc.returncode not in (0, 1, 2, 3):   # 3: evaluate / run not proven
        return f"exit {proc.returncode}: " + (proc.stderr.strip().splitlines() or [""])[-1][:160]
    return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--timeout", type=float, default=45.0)
    ap.add_argument("--commands", default=None, help="comma-separated sub-commands (default: all)")
    args = ap.parse_args()
    from dockfactory.cli import build_parser
    keep = set(args.commands.split(",")) if args.commands else None
    with tempfile.TemporaryDirectory() as tmp:
        w = build_world(Path(tmp))
        tried, failed = 0, []
        for name, argv in attempts(build_parser(), w):
            if keep is not None and name not in keep:
                continue
            tried += 1
            why = run_one(name, argv, args.timeout)
            if why:
                failed.append(f"dockfactory {name} {' '.join(argv)}: {why}")
                print(failed[-1], flush=True)
        os.chmod(w["base"] / "readonly", stat.S_IRWXU)
    summary = f"{tried} attempts, {len(failed)} failed"
    print(summary)
    if args.out:
        args.out.write_text("\n".join(failed + [summary]) + "\n")


if __name__ == "__main__":
    main()
