"""The export formats have one owner: each format module of generator/exports declares its formats
(``FORMATS``, generator.exports.registry), and everything else reads the registry the facade collects
from them: the writers (generator.exports.WRITERS, datasets.tools.EXPORT_WRITERS, the facade's
``export_<name>``), the names ``[export] formats`` accepts (check-config, render and run), the names
``dataset export --format`` accepts and its help. A module that declares a format one of them does not
take, or a format module that declares nothing, fails here."""
import importlib
import pkgutil
import types

import pytest

from cli_run import one_line_error, run_cli
from dockfactory.cli import build_parser
from dockfactory.cli_factory import format_names
from dockfactory.core.config import ConfigError
from dockfactory.core.config_text import load_config_text
from dockfactory.generator import exports
from dockfactory.generator.datasets import tools as dt
from dockfactory.generator.exports.registry import ExportFormat, collect
from dockfactory.generator.render_job import JobOptions, run_render

HELPERS = {"files", "coco_results", "registry"}   # modules of generator/exports that declare no format
SMALL = "[dataset]\nframes = 2\n\n[repeatability]\nposes = 0\n"


def _export_help() -> str:
    export = build_parser().subcommands.choices["dataset"].subcommands.choices["export"]
    return next(a.help for a in export.arguments if "--format" in a.option_strings)


def _config(tmp_path, formats) -> str:
    path = tmp_path / "c.toml"
    path.write_text(SMALL + "\n[export]\nformats = [" + ", ".join(f'"{f}"' for f in formats) + "]\n")
    return str(path)


def _render_formats() -> list[str]:
    return [name for name, fmt in exports.FORMATS.items() if not fmt.on_demand]


def test_every_module_is_a_format_module_or_a_named_helper():
    declared = {}
    for info in pkgutil.iter_modules(exports.__path__):
        module = importlib.import_module(f"{exports.__name__}.{info.name}")
        if info.name not in HELPERS:
            assert getattr(module, "FORMATS", ()), f"{module.__name__}: declares no FORMATS (or name it a helper here)"
        declared.update({fmt.name: fmt for fmt in getattr(module, "FORMATS", ())})
    assert declared == exports.FORMATS


def test_names_writers_and_help_agree():
    assert list(exports.WRITERS) == list(exports.FORMATS) and dt.EXPORT_WRITERS is exports.WRITERS
    assert {"coco", "yolo", "yolo-pose", "bop", "cameras", "video", "video_lossless"} <= set(exports.FORMATS)
    help_text = " ".join(_export_help().split())
    for name, fmt in exports.FORMATS.items():
        writer = getattr(exports, "export_" + name.replace("-", "_"))
        assert writer is fmt.writer is exports.WRITERS[name] and writer.__name__ in exports.__all__
        assert f"{name}: {' '.join(fmt.summary.split())}" in help_text, (name, help_text)
    assert exports.FORMATS["video_lossless"].on_demand and not exports.FORMATS["coco"].on_demand


def test_every_format_is_a_name_the_command_line_takes():
    names = list(exports.FORMATS)
    assert format_names(",".join(names)) == names and format_names(" , ".join(names)) == names
    for name in names:
        assert format_names(name) == [name]


def test_every_render_format_is_a_name_the_config_takes(tmp_path, capsys):
    path = _config(tmp_path, _render_formats())
    cfg, _ = load_config_text(path)
    assert list(cfg.export.formats) == _render_formats()
    exports.check_export_formats(cfg, path)
    code, out, _ = run_cli(["check-config", path], capsys)
    assert code == 0 and "valid" in out


@pytest.mark.parametrize("bad, why", [("nope", "unknown format 'nope'"), ("video", "'video' is written on demand only")])
def test_a_name_the_config_cannot_take_is_one_line(tmp_path, capsys, bad, why):
    path = _config(tmp_path, ["coco", bad])
    # (a frame outside the plan: were the names not checked first, render would stop there, not render)
    for argv in (["check-config", path], ["render", path, "--out", tmp_path / "ds", "--frames", "none"]):
        code, _, err = run_cli(argv, capsys)
        line = one_line_error(err)
        assert code == 2 and f"{path}: [export] formats: {why}" in line, line
        assert ", ".join(_render_formats()) in line
    assert not (tmp_path / "ds").exists()
    cfg, text = load_config_text(path)   # core checks the type only: the names are the generator's
    with pytest.raises(ConfigError, match=r"\[export\] formats"):
        run_render(cfg, tmp_path / "ds", text, JobOptions(progress=False, frame_ids=("none",)))
    assert not (tmp_path / "ds").exists()


def test_an_unknown_format_on_the_command_line_is_one_line(capsys, tmp_path):
    code, _, err = run_cli(["dataset", "export", tmp_path, "--format", "coco,nope"], capsys)
    assert code == 2 and "--format: unknown export format 'nope'" in one_line_error(err)


def _writer(name):
    def writer(ds, out):
        return out
    writer.__name__ = name
    return writer


def _module(name, formats):
    module = types.ModuleType(name)
    module.FORMATS = formats
    return module


def test_a_declaration_breaking_the_rules_fails_at_import():
    """The rules the registry relies on, each shown to fail."""
    with pytest.raises(ValueError, match="lower-case"):
        ExportFormat("Foo,bar", _writer("export_Foo,bar"), "two names in one")
    with pytest.raises(ValueError, match="export_foo_bar"):
        ExportFormat("foo-bar", _writer("write_foo"), "a writer the facade cannot name")
    with pytest.raises(ValueError, match="one line"):
        ExportFormat("foo", _writer("export_foo"), "")
    foo = ExportFormat("foo", _writer("export_foo"), "a format")
    with pytest.raises(ValueError, match="declared by a and by b"):
        collect([_module("a", (foo,)), _module("b", (foo,))])
    with pytest.raises(ValueError, match="not a tuple of ExportFormat"):
        collect([_module("a", foo)])
    late = ExportFormat("bar", _writer("export_bar"), "on demand", on_demand=True)
    assert list(collect([_module("a", (late, foo)), types.ModuleType("helper")])) == ["foo", "bar"]
