import subprocess
import sys

import pytest

from dockfactory.core.config import Config, ConfigError, config_from_dict, load_config


def test_defaults_are_valid_and_match_the_brief():
    cfg = config_from_dict({})
    assert cfg.image.width == 1280 and cfg.image.height == 960
    assert cfg.sections.radius_mm == 300 and cfg.sections.length_mm == 1200
    assert cfg.markers.diameter_mm == 20
    assert cfg.pose.x_mm == (5.0, 150.0) and cfg.pose.gamma_deg == (-5.0, 5.0)
    assert cfg.camera.distance_mm == (1000.0, 1800.0)
    assert cfg.dataset.train_fraction == 0.8 and cfg.dataset.val_fraction == 0.1
    assert isinstance(cfg, Config)


def test_repo_configs_load(repo_root):
    for path in sorted((repo_root / "configs").glob("*.toml")):
        if path.name == "acceptance.toml":
            continue
        load_config(path)


@pytest.mark.parametrize("text, key", [
    ("[camera]\nfocal_pxx = [1, 2]\n", "focal_pxx"),
    ("[cameras]\nfocal_px = [1, 2]\n", "cameras"),
    ("[dataset]\nframes = -3\n", "frames"),
    ("[pose]\nx_mm = [150, 5]\n", "x_mm"),
    ("[dataset]\nframes = 'ten'\n", "frames"),
    ("[render]\ndenoise = 'magic'\n", "denoise"),
    ("[render]\nsampling_pattern = 'sobol'\n", "sampling_pattern"),
    ("[render]\npost_filter = 'median7'\n", "post_filter"),
    ("[markers]\nlayout_a = [[50, 0], [52, 1], [100, 10], [120, 20], [140, -20], [160, 30]]\n", "layout"),
    ("[markers]\nlayout_a = [[5, 0], [60, 10], [100, 10], [120, 20], [140, -20], [160, 30]]\n", "layout_a[0]"),
    ("[dataset\nframes = 3\n", "TOML"),
    ("[dataset]\nval_fraction = 1.0\n", "val_fraction"),
    ("[dataset]\nval_fraction = -0.1\n", "val_fraction"),
    ("[dataset]\ntrain_fraction = 1.5\n", "train_fraction"),
    ("[glare]\nkinds = []\n", "kinds"),
    ("[occlusion]\nkinds = ['rope']\n", "rope"),
])
def test_bad_configs_name_the_key(tmp_config, text, key):
    path = tmp_config(text)
    with pytest.raises(ConfigError) as err:
        load_config(path)
    assert key in str(err.value)
    assert str(path) in str(err.value)


def test_focal_that_cannot_fit_says_why(tmp_config):
    from dockfactory.generator.sampler import check_focal_fits
    path = tmp_config("[camera]\nfocal_px = [9000, 12000]\n")
    cfg = load_config(path)  # loading does not sample frames; the feasibility check does
    with pytest.raises(ConfigError, match=r"cfg.toml: \[camera\] focal_px: min 9000 px cannot fit"):
        check_focal_fits(cfg, str(path))


@pytest.mark.parametrize("text, key", [("[dataset]\nframes = -1\n", "frames"),
                                       ("[camera]\nfocal_px = [9000, 12000]\n", "focal_px")])
def test_bad_config_writes_nothing(tmp_path, tmp_config, text, key):
    path = tmp_config(text)
    out = tmp_path / "never"
    proc = subprocess.run([sys.executable, "-m", "dockfactory", "render", str(path), "--out", str(out)],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert key in proc.stderr and str(path) in proc.stderr
    assert not out.exists()


def test_canonical_json_is_stable():
    a = config_from_dict({"dataset": {"seed": 5}})
    b = config_from_dict({"dataset": {"seed": 5}})
    assert a.canonical_json() == b.canonical_json()
    assert a.canonical_json() != config_from_dict({"dataset": {"seed": 6}}).canonical_json()


def test_version_id_covers_config_code_and_blender():
    from dockfactory.generator.version import (
        dataset_version_id,
        generator_source_fingerprint,
        generator_version,
    )
    cfg = config_from_dict({}).canonical_json()
    base = dataset_version_id(cfg, "5.0.1", "0.1.0+aaaa")
    assert base == dataset_version_id(cfg, "5.0.1", "0.1.0+aaaa")
    assert base != dataset_version_id(cfg, "5.0.1", "0.1.0+bbbb")      # generator code changed
    assert base != dataset_version_id(cfg, "5.1.0", "0.1.0+aaaa")      # Blender changed
    assert base != dataset_version_id(config_from_dict({"dataset": {"seed": 1}}).canonical_json(), "5.0.1", "0.1.0+aaaa")
    assert generator_version().endswith("+" + generator_source_fingerprint())
    assert len(generator_source_fingerprint()) == 16


def test_validate_is_split_into_short_functions():
    import ast
    import inspect

    from dockfactory.core import config
    tree = ast.parse(inspect.getsource(config))
    long = [(f.name, f.end_lineno - f.lineno + 1) for f in ast.walk(tree)
            if isinstance(f, ast.FunctionDef) and f.end_lineno - f.lineno + 1 > 50]
    assert long == []


def test_configs_resolve_to_files_or_shipped_names(tmp_path, monkeypatch):
    from dockfactory.core.errors import DockfactoryError
    from dockfactory.core.resources import resolve_config, shipped_config, shipped_configs
    assert {"smoke", "quick", "paper", "ideal", "detector", "acceptance"} <= set(shipped_configs())
    monkeypatch.chdir(tmp_path)
    for arg in ("smoke", "smoke.toml", "configs/smoke.toml"):
        assert resolve_config(arg) == shipped_config("smoke") and resolve_config(arg).is_file()
    (tmp_path / "configs").mkdir()
    own = tmp_path / "configs" / "smoke.toml"
    own.write_text("[dataset]\nframes = 3\n")
    assert resolve_config("configs/smoke.toml").resolve() == own   # a file that exists wins
    with pytest.raises(DockfactoryError, match=r"nope.toml: no such config file \(shipped configs: .*smoke"):
        resolve_config("nope.toml")
    with pytest.raises(DockfactoryError, match="no such config file"):
        resolve_config("elsewhere/smoke.toml")                 # only ./ and configs/ fall back
