"""The documentation cannot drift from the code: the config key reference is regenerated from the
schema and compared; every relative link of the README and docs/ resolves; the README stays a
front page; its example config is valid; bench/README.md names every bench script."""
import re
import tomllib
from pathlib import Path

import pytest

from dockfactory.core.config import Config, config_from_dict, load_config
from dockfactory.core.config_text import apply_overrides, defaults_toml, reference_markdown, to_toml
from dockfactory.core.resources import shipped_config, shipped_configs
from dockfactory.cli import main


def test_the_key_reference_is_the_schema(repo_root):
    assert (repo_root / "docs" / "config_reference.md").read_text() == reference_markdown(), \
        "docs/config_reference.md is stale: regenerate it (python -c 'from dockfactory.core.config_text import " \
        "reference_markdown; print(reference_markdown(), end=\"\")' > docs/config_reference.md)"


def test_every_key_has_a_meaning():
    from dockfactory.core.config_text import tables
    missing = [f"[{t}] {k}" for t, _, rows in tables() for k, _, _, m in rows if not m]
    assert not missing, missing


def test_defaults_print_a_config_that_is_the_defaults(capsys):
    assert main(["check-config", "--defaults"]) == 0
    text = capsys.readouterr().out
    assert text == defaults_toml()
    assert config_from_dict(tomllib.loads(text)) == Config()


@pytest.mark.parametrize("name", shipped_configs())
def test_the_resolved_toml_of_each_shipped_config_reads_back_as_it(name, capsys):
    if name == "acceptance":
        pytest.skip("an acceptance spec, not a dataset config")
    cfg = load_config(shipped_config(name))   # a calibration file resolved beside it
    assert config_from_dict(tomllib.loads(to_toml(cfg.resolved_dict()))) == cfg
    assert main(["check-config", name, "--resolved"]) == 0
    assert config_from_dict(tomllib.loads(capsys.readouterr().out)) == cfg


def test_set_overrides_are_validated_like_the_file_and_change_the_version(capsys):
    from dockfactory.generator.datasets.folder import identity
    base = tomllib.loads(shipped_config("smoke").read_text())
    merged = apply_overrides(base, ["dataset.frames=10", "camera.focal_px=[1300, 2900]", "dataset.name=other"], "x")
    cfg = config_from_dict(merged)
    assert (cfg.dataset.frames, cfg.camera.focal_px, cfg.dataset.name) == (10, (1300.0, 2900.0), "other")
    assert identity(cfg)["version_id"] != identity(config_from_dict(base))["version_id"]
    assert main(["check-config", "smoke", "--set", "dataset.frames=10"]) == 0
    assert identity(cfg)["version_id"] not in capsys.readouterr().out   # name and focal differ too
    for bad, words in (("dataset.frames=abc", "[dataset] frames: expected an integer"),
                       ("dataset.frames=-1", "frames"), ("nope.x=1", "unknown table 'nope'"),
                       ("frames=1", "expected TABLE.KEY=VALUE"), ("dataset.frames", "expected TABLE.KEY=VALUE")):
        assert main(["check-config", "smoke", "--set", bad]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and words in err[0], (bad, err)


def test_render_with_set_records_the_resolved_config(tmp_path, monkeypatch):
    """The dataset's config.toml is the resolved config, so it reproduces the dataset alone."""
    import dockfactory.cli_factory as gcli
    seen = {}

    def fake_render(cfg, out, text, opts):
        seen.update(cfg=cfg, text=text)
        raise SystemExit(0)
    monkeypatch.setattr(gcli, "run_render", fake_render)
    with pytest.raises(SystemExit):
        main(["render", "smoke", "--out", str(tmp_path / "d"), "--set", "dataset.frames=9"])
    assert seen["cfg"].dataset.frames == 9
    assert config_from_dict(tomllib.loads(seen["text"])) == seen["cfg"]


def _links(path: Path):
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", path.read_text()):
        if not re.match(r"[a-z]+://", target):
            yield target


def test_every_relative_link_resolves(repo_root):
    pages = [repo_root / "README.md", repo_root / "results" / "README.md", repo_root / "bench" / "README.md",
             *sorted((repo_root / "docs").glob("*.md"))]
    broken = [f"{p.relative_to(repo_root)}: {t}" for p in pages for t in _links(p) if not (p.parent / t).exists()]
    assert not broken, broken


def test_the_readme_is_a_front_page_with_a_valid_example(repo_root, tmp_path):
    text = (repo_root / "README.md").read_text()
    assert len(text.splitlines()) <= 250
    example = re.search(r"```toml\n(.*?)```", text, re.S).group(1)
    (tmp_path / "my_scene.toml").write_text(example)
    assert main(["check-config", str(tmp_path / "my_scene.toml")]) == 0


def test_bench_readme_names_every_script(repo_root):
    index = (repo_root / "bench" / "README.md").read_text()
    scripts = sorted(p.name for p in (repo_root / "bench").rglob("*") if p.suffix in (".py", ".sh")
                     and p.name != "__init__.py" and not {"results", "configs", "torchvision"} & set(p.parts))
    missing = [s for s in scripts if f"`{s}`" not in index]
    assert not missing, f"bench/README.md does not describe {missing}"


@pytest.mark.parametrize("command", ["render", "run"])
def test_the_help_names_every_shipped_config(command, capsys):
    """render --help and run --help list every shipped dataset config by name (they once listed 5)."""
    from dockfactory.core.resources import shipped_dataset_configs
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert len(shipped_dataset_configs()) >= 8
    for name in shipped_dataset_configs():
        assert name in text, name


def test_the_readme_frame_counts_are_the_configs_plans(repo_root):
    """Each shipped config the README's table counts ("N frames") plans exactly N frames (smoke's
    was given as 6 while it renders 10)."""
    from dockfactory.generator.sampler import frame_plan
    rows = re.findall(r"^\| `(\w+)` \| ([\d,]+) frames", (repo_root / "README.md").read_text(), re.M)
    assert {"smoke", "quick"} <= {name for name, _ in rows}
    for name, count in rows:
        cfg = load_config(shipped_config(name))
        assert len(frame_plan(cfg)) == int(count.replace(",", "")), name


def test_the_documented_plan_frames_example_runs(repo_root, capsys):
    """docs/acceptance.md's plan-frames example, run as written: exit 0 with a plan for every gated
    component (it once left y out and exited 2)."""
    import shlex
    text = (repo_root / "docs" / "acceptance.md").read_text()
    example = re.search(r"`(dockfactory plan-frames [^`]+)`", text).group(1)
    assert main(shlex.split(example)[1:]) == 0
    out = capsys.readouterr().out
    assert all(f"localization: {c}: expected" in out for c in ("x", "y", "alpha"))
