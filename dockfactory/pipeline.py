"""``dockfactory run``: render -> detect -> solve -> evaluate -> report, resumable.

Each stage records a key (a hash of its inputs) and the sha256 of its outputs in WORKDIR/stages.json
and is skipped when its key is unchanged and its outputs still hold those bytes, so an interrupted
run resumes where it stopped. After the render stage (run or skipped) the dataset is opened with
every byte verified (``Dataset.open``): a damaged dataset stops the run, named.
"""
from __future__ import annotations

import functools
import hashlib
import json
import os
import sys
import time
from pathlib import Path

from dockfactory.core.config_text import load_config_text
from dockfactory.core.io import folder_lock, sha256_file, write_json_atomic
from dockfactory.core.resources import shipped_weights
from dockfactory.eval.acceptance import load_acceptance, verdict_exit_status
from dockfactory.eval.evaluate import evaluate, portable_path, write_outputs
from dockfactory.eval.noise_calibration import calibrate_noise_card
from dockfactory.eval.report import build_report
from dockfactory.eval.section_shift import split_section_shift
from dockfactory.eval.simulated_cameras import dataset_camera
from dockfactory.eval.solve_frames import solve_dataset, write_poses
from dockfactory.generator.datasets.folder import identity
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.exports import check_export_formats
from dockfactory.generator.render_job import JobOptions, print_summary, run_render
from dockfactory.generator.sampler import check_focal_fits


class Stages:
    """WORKDIR/stages.json: per stage, the key of its inputs and the sha256 of its outputs. A stage
    is current (skipped) only when its key is unchanged and every output still has the bytes it
    was written with: an output edited or truncated since is made again, never trusted."""

    def __init__(self, workdir: Path):
        self.path = workdir / "stages.json"
        self.data = json.loads(self.path.read_text()) if self.path.exists() else {}

    @staticmethod
    def _hashes(outputs) -> dict[str, str]:
        return {Path(o).name: sha256_file(o) for o in outputs}

    def current(self, name: str, key: str, outputs) -> bool:
        rec = self.data.get(name, {})
        if rec.get("key") != key or not all(Path(o).is_file() for o in outputs):
            return False
        return rec.get("sha256") == self._hashes(outputs)

    def done(self, name: str, key: str, seconds: float, outputs) -> None:
        self.data[name] = {"key": key, "seconds": seconds, "sha256": self._hashes(outputs)}
        write_json_atomic(self.path, self.data)


def code_fingerprint(*packages: str) -> str:
    """Hash of the Python sources of ``packages``: a code change makes their stages stale."""
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for pkg in packages:
        for path in sorted((root / pkg).glob("*.py")):
            h.update(path.name.encode())
            h.update(path.read_bytes())
    return h.hexdigest()[:16]


def _key(*parts) -> str:
    return hashlib.sha256("\n".join(str(p) for p in parts).encode()).hexdigest()[:16]


def say(msg: str) -> None:
    print(f"[run] {msg}", file=sys.stderr, flush=True)


def detect_stage(ds, workdir: Path, dets_path: Path, weights, train: bool, epochs, stages: Stages):
    """Detections for every frame (shipped weights, given weights, or a detector trained here)."""
    import torch  # only this stage needs torch

    from dockfactory.detector.infer import detect_dataset
    torch.set_num_threads(os.cpu_count() or 1)
    if train:
        from dockfactory.detector.train import TrainConfig
        from dockfactory.detector.train import train as train_detector
        run_dir = workdir / "train"
        cfg = TrainConfig(epochs=epochs or TrainConfig().epochs)
        key = _key("train", ds.version_id, cfg, code_fingerprint("detector"))
        if stages.current("train", key, [run_dir / "weights.pt"]):
            say("train: weights current, skipped")
        else:
            say(f"train: {cfg.epochs} epochs on the train split -> {run_dir}")
            t = time.monotonic()
            train_detector(ds, run_dir, cfg, resume=(run_dir / "last.pt").exists())
            _write_noise_card(ds, run_dir / "weights.pt")
            stages.done("train", key, time.monotonic() - t, [run_dir / "weights.pt"])
        weights = run_dir / "weights.pt"
    weights = Path(weights) if weights else shipped_weights()
    if not weights.exists():
        raise FileNotFoundError(f"{weights}: detector weights not found (use --weights, --train or --oracle-noise)")
    model_sha = sha256_file(weights)
    key = _key("detect", ds.version_id, model_sha, code_fingerprint("detector"))
    if stages.current("detect", key, [dets_path]):
        say("detect: detections current, skipped")
    else:
        say(f"detect: {weights.name} on every frame")
        t = time.monotonic()
        detect_dataset(ds, weights, dets_path, split=None, camera=dataset_camera(ds))
        stages.done("detect", key, time.monotonic() - t, [dets_path])
    return weights, model_sha


def _write_noise_card(ds, weights: Path) -> None:
    """The trained weights' noise card from the val split (the covariance's floor), if it has frames."""
    if not ds.frames(("val",)):
        say("train: no val frames, so no noise card: the solver's covariance has no floor")
        return
    card = calibrate_noise_card(ds, weights, "val")
    say(f"train: centre noise {card['centre_noise_px']:.3f} px on {card['n']} val centres -> {card['card']}")


def _render_stage(cfg, config_path, config_text: str, data_dir: Path, workers: int, stages: Stages) -> str | None:
    """Render the dataset (itself resumable: only missing frames are rendered); its version id,
    or None when the render is incomplete."""
    version = identity(cfg)["version_id"]
    key = _key("render", version)
    if stages.current("render", key, [data_dir / "manifest.json"]):
        say(f"render: dataset {version} complete, skipped")
        return version
    say(f"render: dataset {version} -> {data_dir}")
    t = time.monotonic()
    check_export_formats(cfg, str(config_path))
    check_focal_fits(cfg, str(config_path))
    summary = run_render(cfg, data_dir, config_text, JobOptions(workers=workers))
    print_summary(summary)
    if not summary.complete:
        say("render incomplete: run the same command again")
        return None
    if not summary.ok:   # complete but damaged: never recorded as done; Dataset.open names it
        return version
    stages.done("render", key, time.monotonic() - t, [data_dir / "manifest.json"])
    return version


def _solve_stage(ds, version: str, dets_path: Path | None, oracle_noise_px, poses_path: Path, stages: Stages) -> str:
    """Poses of every frame from the detections (or from oracle centres when ``dets_path`` is None);
    returns the key part naming the detections."""
    src = sha256_file(dets_path) if dets_path else f"oracle:{oracle_noise_px}"
    key = _key("solve", version, src, code_fingerprint("solver", "eval"))
    if stages.current("solve", key, [poses_path]):
        say("solve: poses current, skipped")
        return src
    t = time.monotonic()
    if dets_path:
        dets = json.loads(dets_path.read_text())
        shift = split_section_shift(ds, dets, "val")
        poses = solve_dataset(ds, detections=dets, section_shift_px=shift and shift["shift_axis_px"])
        poses["section_shift"] = {"source": "the val split", **shift} if shift else {"source": "the weights' noise card"}
        if shift:
            say(f"solve: section offset {shift['shift_axis_px'][0]:.3f} / {shift['shift_axis_px'][1]:.3f} px "
                f"measured on {shift['groups']} sections of the val split")
    else:
        poses = solve_dataset(ds, oracle_sigma_px=oracle_noise_px)
    write_poses(poses_path, poses, dets_path)
    n_ok = sum(r["ok"] for r in poses["frames"].values())
    say(f"solve: {n_ok} of {len(poses['frames'])} frames solved")
    stages.done("solve", key, time.monotonic() - t, [poses_path])
    return src


def _evaluate_stage(ds, eval_dir: Path, poses_path: Path, spec, acceptance_path, src: str,
                    dets_path: Path | None, oracle_noise_px, stages: Stages) -> dict:
    """Metrics against the acceptance spec, written to ``eval_dir`` (read back when current)."""
    key = _key("evaluate", sha256_file(poses_path), sha256_file(acceptance_path), src,
               code_fingerprint("solver", "eval"))
    if stages.current("evaluate", key, [eval_dir / "metrics.json", eval_dir / "frames.csv"]):
        say("evaluate: metrics current, skipped")
        return json.loads((eval_dir / "metrics.json").read_text())
    t = time.monotonic()
    metrics, rows = evaluate(ds, poses_path, spec, dets_path, oracle_sigma_px=oracle_noise_px)
    write_outputs(eval_dir, metrics, rows)
    stages.done("evaluate", key, time.monotonic() - t, [eval_dir / "metrics.json", eval_dir / "frames.csv"])
    return metrics


def _holds_workdir_lock(fn):
    """Run ``fn(config_path, workdir, ...)`` holding the work folder's exclusive lock
    (WORKDIR/.dockfactory.lock): a second ``run`` into it fails at once, naming the first."""
    @functools.wraps(fn)
    def locked(config_path, workdir, *args, **kwargs):
        with folder_lock(Path(workdir), "run"):
            return fn(config_path, workdir, *args, **kwargs)
    return locked


@_holds_workdir_lock
def run_pipeline(config_path, workdir, acceptance_path, weights=None, train: bool = False,
                 oracle_noise_px: float | None = None, workers: int = 1, train_epochs: int | None = None) -> int:

    t_all = time.monotonic()
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    cfg, config_text = load_config_text(config_path)
    spec = load_acceptance(acceptance_path)
    stages = Stages(workdir)
    data_dir = workdir / "dataset"
    commands = [f"dockfactory run {config_path} --out {workdir}"]

    version = _render_stage(cfg, config_path, config_text, data_dir, workers, stages)   # 1. render
    if version is None:
        return 1
    # every byte checked before anything downstream is trusted, skipped stages included
    ds = Dataset.open(data_dir)

    dets_path = workdir / "detections.json"   # 2. detect
    model_sha = None
    if oracle_noise_px is not None:
        say(f"detect: skipped, oracle mode (exact centres + {oracle_noise_px} px noise)")
        dets_path = None
    else:
        weights, model_sha = detect_stage(ds, workdir, dets_path, weights, train, train_epochs, stages)
        commands.append(f"dockfactory detect {data_dir} --weights {weights} --split all --out {dets_path}")

    poses_path = workdir / "poses.json"   # 3. solve
    src = _solve_stage(ds, version, dets_path, oracle_noise_px, poses_path, stages)
    commands.append(f"dockfactory solve {data_dir} " + (f"--detections {dets_path}" if dets_path else f"--oracle-noise {oracle_noise_px}")
                    + f" --out {poses_path}")

    eval_dir = workdir / "eval"   # 4. evaluate
    _evaluate_stage(ds, eval_dir, poses_path, spec, acceptance_path, src, dets_path, oracle_noise_px, stages)
    commands.append(f"dockfactory evaluate {data_dir} --poses {poses_path}"
                    + (f" --detections {dets_path}" if dets_path else "") + f" --acceptance {acceptance_path} --out {eval_dir}")
    write_json_atomic(eval_dir / "provenance.json", {"detections": portable_path(dets_path, eval_dir) if dets_path else None,
                                                     "model_sha256": model_sha, "commands": commands})

    # 5. report (always rebuilt: cheap, and it carries the date)
    report = workdir / "report.html"
    commands.append(f"dockfactory report {eval_dir} --out {report}")
    summary = build_report(eval_dir, report, commands)
    say(f"done in {time.monotonic() - t_all:.0f} s")
    print(f"verdict: {summary['verdict']}  report: {report}")
    return verdict_exit_status(summary["verdict"])
