"""Config limits (issue 10, finding 7): values that used to pass validation and then crash or hang.

NaN and inf are rejected for every float of the config (walked from the dataclasses, so a new
key is covered without a new test), counts have named upper bounds, and a config that fails
validation writes nothing. No rendering: configs are only loaded and checked.
"""
import copy
import dataclasses
import math
import resource
import subprocess
import sys
import time
import typing

import pytest

from dockfactory.core import config as config_mod
from dockfactory.core.config import Config, ConfigError, Overrides, config_from_dict, load_config
from dockfactory.cli import main


def _float_slots():
    """(table, key, example TOML value with a NaN in it) for every float in the config."""
    out = []
    tables = typing.get_type_hints(Config)
    for table in dataclasses.fields(Config):
        cls = tables[table.name]
        hints = typing.get_type_hints(cls)
        default = cls()
        for f in dataclasses.fields(cls):
            hint, value = hints[f.name], getattr(default, f.name)
            if hint is float:
                out.append((table.name, f.name, None))
            elif hint == Overrides:                                 # a table of name = number
                out.append((table.name, f.name, [{"dark_noise_e": 1.0}, "dark_noise_e"]))
            elif typing.get_origin(hint) is tuple:
                args = typing.get_args(hint)
                if float in args:                                   # a [min, max] range
                    out.append((table.name, f.name, [list(value), 0]))
                elif args and typing.get_origin(args[0]) is tuple and float in typing.get_args(args[0]):
                    # a list of float pairs or triples (a part's vertices: empty by default)
                    rows = [list(p) for p in value] or [[0.0] * len(typing.get_args(args[0]))]
                    out.append((table.name, f.name, [rows, 0, 1]))
    return out


def _with(template, bad):
    """``bad`` placed into the template (None: a scalar; else the element at the given index)."""
    if template is None:
        return bad
    value, *index = template
    value = copy.deepcopy(value)
    target = value
    for i in index[:-1]:
        target = target[i]
    target[index[-1]] = bad
    return value


SLOTS = _float_slots()


def test_every_float_slot_is_walked():
    keys = {(t, k) for t, k, _ in SLOTS}
    # the findings' keys, and a few of every kind (scalar, range, layout pair, condition weight)
    assert {("camera", "margin_px"), ("render", "frame_timeout_s"), ("camera", "distance_mm"),
            ("pose", "x_mm"), ("sensor", "full_well_e"), ("markers", "layout_a"),
            ("conditions", "normal"), ("dataset", "train_fraction")} <= keys
    assert len(SLOTS) >= 35


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf], ids=["nan", "inf", "-inf"])
@pytest.mark.parametrize("table, key, template", SLOTS, ids=[f"{t}.{k}" for t, k, _ in SLOTS])
def test_nan_and_inf_are_rejected_everywhere(table, key, template, bad):
    data = {table: {key: _with(template, bad)}}
    with pytest.raises(ConfigError) as err:
        config_from_dict(data, "cfg.toml")
    msg = str(err.value)
    assert f"[{table}] {key}" in msg and "cfg.toml" in msg and "finite" in msg
    assert "\n" not in msg


@pytest.mark.parametrize("text, key", [
    ("[camera]\nmargin_px = nan\n", "margin_px"),
    ("[render]\nframe_timeout_s = nan\n", "frame_timeout_s"),
    ("[camera]\ndistance_mm = [nan, 1800]\n", "distance_mm"),
    ("[pose]\nx_mm = [5, nan]\n", "x_mm"),
    ("[sensor]\nfull_well_e = [8000, inf]\n", "full_well_e"),
])
def test_finding_7_nan_inf_from_toml_exit_2(tmp_config, capsys, text, key):
    path = tmp_config(text)
    assert main(["check-config", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("dockfactory: error:") and key in err and str(path) in err and "\n" not in err


def test_limits_are_named():
    assert 3_200 <= config_mod.MAX_FRAMES <= 1_000_000       # above the paper config, ids stay six digits
    assert config_mod.MAX_REPEAT_POSES <= 1_000 and config_mod.MAX_REPEAT_CAPTURES <= 100   # repPPP_CC
    assert config_mod.MIN_IMAGE_PX <= 16 and config_mod.MAX_IMAGE_PX <= 16384
    assert config_mod.MAX_MAGNITUDE <= 1e12
    cfg = config_from_dict({"dataset": {"frames": config_mod.MAX_FRAMES}})   # the bound itself is fine
    assert cfg.dataset.frames == config_mod.MAX_FRAMES


@pytest.mark.parametrize("data, key", [
    ({"dataset": {"frames": 10**12}}, "frames"),
    # just above the named bounds (read when the test runs)
    (lambda m: {"dataset": {"frames": m.MAX_FRAMES + 1}}, "frames"),
    (lambda m: {"dataset": {"frames": m.MAX_FRAMES}, "repeatability": {"poses": 1, "captures": 2}}, "poses"),
    (lambda m: {"repeatability": {"poses": m.MAX_REPEAT_POSES + 1, "captures": 1}}, "poses"),
    (lambda m: {"repeatability": {"poses": 1, "captures": m.MAX_REPEAT_CAPTURES + 1}}, "captures"),
    ({"repeatability": {"poses": 100_000_000}}, "poses"),
    ({"repeatability": {"poses": 1, "captures": 10**9}}, "captures"),
    ({"render": {"samples": 10**12}}, "samples"),
    ({"render": {"max_bounces": 10**9}}, "max_bounces"),
    ({"render": {"adaptive_min_samples": 10**12}}, "adaptive_min_samples"),
    ({"pose": {"x_mm": [-1e308, 1e308]}}, "x_mm"),            # finite, but max - min overflows
    ({"conditions": {"normal": 1e308, "glare": 1e308}}, "normal"),  # the weights' sum overflows
    ({"camera": {"lateral_jitter_mm": 1e300}}, "lateral_jitter_mm"),
])
def test_upper_bounds_one_line_and_fast(data, key):
    if callable(data):
        data = data(config_mod)
    t0 = time.monotonic()
    with pytest.raises(ConfigError) as err:
        config_from_dict(data, "cfg.toml")
    assert time.monotonic() - t0 < 1.0
    assert key in str(err.value) and "cfg.toml" in str(err.value) and "\n" not in str(err.value)


def _limit_memory():
    resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))   # today's code: MemoryError, not swap


@pytest.mark.parametrize("text, key", [("[dataset]\nframes = 1000000000000\n", "frames"),
                                       ("[repeatability]\nposes = 100000000\n", "poses")])
def test_finding_7_huge_counts_check_config_exit_2(tmp_config, text, key):
    """In a child process with 2 GB of address space and a 60 s timeout: before the bounds, the
    first was a MemoryError traceback and the second a hang."""
    path = tmp_config(text)
    try:
        proc = subprocess.run([sys.executable, "-m", "dockfactory", "check-config", str(path)],
                              check=False, capture_output=True, text=True, timeout=60,
                              preexec_fn=_limit_memory)
    except subprocess.TimeoutExpired:
        pytest.fail("check-config hangs")
    assert proc.returncode == 2, proc.stderr[-500:]
    err = proc.stderr.strip()
    assert err.startswith("dockfactory: error:") and key in err and "\n" not in err


@pytest.mark.parametrize("text", ["[dataset]\nframes = 2\n[camera]\nmargin_px = nan\n",
                                  "[dataset]\nframes = 2\n[sensor]\nfull_well_e = [8000, inf]\n"])
def test_finding_7_invalid_config_writes_nothing(tmp_path, tmp_config, capsys, text):
    """A NaN config used to leave config.toml and layout.json behind, blocking the next render."""
    path = tmp_config(text)
    out = tmp_path / "out"
    assert main(["render", str(path), "--out", str(out), "--quiet"]) == 2
    assert not out.exists()
    assert "dockfactory: error:" in capsys.readouterr().err


def test_shipped_configs_are_inside_the_limits(repo_root):
    for path in sorted((repo_root / "configs").glob("*.toml")):
        if path.name != "acceptance.toml":
            load_config(path)
