"""[render] device = "cpu" | "gpu": validated, part of a dataset's identity only when it is "gpu"
(the default leaves every existing dataset's config hash, hence its version id for the same
software, unchanged), and a GPU render on a machine without one is refused in one line before
anything is written (this machine has no GPU; the test skips where one exists)."""
import json
import subprocess
import sys

import pytest

from cli_run import one_line_error, run_cli
from dockfactory.core.config import ConfigError, config_from_dict, config_from_identity, load_config
from dockfactory.core.resources import shipped_config
from dockfactory.generator.version import dataset_version_id

# version ids of the shipped configs for fixed software strings, computed on main before the
# device key existed (dataset_version_id(cfg.canonical_json(), blender="5.0.1",
# generator="0.1.0+fixed")): the config part of every version id must not move. quick and
# realistic render with label-aware sampling since it became the default: their ids are those of
# the same config with it off (marker_samples = 0, the value that renders what they held before);
# likewise smoke, quick and realistic render the printed flat marker since it became the default:
# their ids are those of the same config with the raised puck.
BEFORE_DEVICE = {"smoke": "0f232de11a0961f8", "quick": "fb879ab49c3d1a7a", "realistic": "b4cacf658a488b5a",
                 "paper": "ed8dae519be049c0"}
SAMPLING_BY_DEFAULT = ("quick", "realistic")
FLAT_BY_DEFAULT = ("smoke", "quick", "realistic")   # the printed flat marker became the default; paper pins the puck


def _vid(cfg) -> str:
    return dataset_version_id(cfg.canonical_json(), blender="5.0.1", generator="0.1.0+fixed")


def _before_sampling(cfg):
    return config_from_identity({**cfg.to_dict(), "render": {**cfg.to_dict()["render"], "marker_samples": 0}})


def _before_flat(cfg):
    return config_from_identity({**cfg.to_dict(), "markers": {**cfg.to_dict()["markers"], "form": "puck", "raise_mm": 1.0}})


def test_the_default_device_keeps_every_config_hash():
    for name, before in BEFORE_DEVICE.items():
        cfg = load_config(shipped_config(name))
        assert cfg.markers.form == ("flat" if name in FLAT_BY_DEFAULT else "puck"), name
        if name in FLAT_BY_DEFAULT:
            assert _vid(cfg) != before, name
            cfg = _before_flat(cfg)
        if name in SAMPLING_BY_DEFAULT:
            assert cfg.render.marker_samples == 40 and _vid(cfg) != before, name
            cfg = _before_sampling(cfg)
        assert cfg.render.device == "cpu" and _vid(cfg) == before, name
        assert "device" not in cfg.to_dict()["render"] and cfg.to_dict(full=True)["render"]["device"] == "cpu"
        explicit = config_from_identity({**cfg.to_dict(), "render": {**cfg.to_dict()["render"], "device": "cpu"}})
        assert explicit.canonical_json() == cfg.canonical_json()
        gpu = config_from_identity({**cfg.to_dict(), "render": {**cfg.to_dict()["render"], "device": "gpu"}})
        assert gpu.to_dict()["render"]["device"] == "gpu" and _vid(gpu) != before   # GPU frames are other bytes


def test_an_unknown_device_is_refused():
    with pytest.raises(ConfigError, match=r"\[render\] device: 'tpu' is not one of cpu, gpu"):
        config_from_dict({"render": {"device": "tpu"}})


def test_a_stored_dataset_without_the_key_still_opens(painted):
    from dockfactory.generator.datasets.reader import Dataset
    ident = json.loads((painted / "dataset.json").read_text())
    assert "device" not in ident["config"]["render"]
    assert Dataset.open(painted).config.render.device == "cpu"
    assert "marker_samples" not in ident["config"]["render"]         # rendered off: reads back off
    assert Dataset.open(painted).config.render.marker_samples == 0


def _has_bpy() -> bool:
    import importlib.util
    return importlib.util.find_spec("bpy") is not None


@pytest.mark.slow   # seconds of work: the full suite runs it (make test), the fast lane does not
@pytest.mark.skipif(not _has_bpy(), reason="needs bpy (Blender as a Python module)")
def test_gpu_without_a_gpu_is_one_line_exit_2_and_nothing_written(tmp_path, capsys):
    from dockfactory.generator.render_device import probe_gpus
    if probe_gpus():
        pytest.skip("this machine has a GPU Cycles can use")
    out = tmp_path / "ds"
    code, _, err = run_cli(["render", "smoke", "--set", "render.device=gpu", "--out", out, "--quiet"], capsys)
    assert code == 2 and "no usable GPU" in one_line_error(err)
    assert not out.exists()
    # the worker's own check (a Ray node without a GPU): use_device refuses, "cpu" is Cycles' CPU
    code = ("import bpy\nfrom dockfactory.blender_scenes.render import use_device\n"
            "print(use_device(bpy.context.scene, 'cpu'))\n"
            "try:\n    use_device(bpy.context.scene, 'gpu')\nexcept RuntimeError as e:\n    print('refused:', e)\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "CPU" in proc.stdout.splitlines() and "refused: render device 'gpu': no usable GPU" in proc.stdout
