"""One error hierarchy: every exception class of the package that is a ValueError derives from
core.errors.DockfactoryError, so the CLI reports it in one line with exit status 2 (static: the
sources are parsed, not imported), and the image-header errors are such errors."""
import ast

PACKAGES = ("core", "solver", "eval", "detector", "generator", "blender_scenes", "dockfactory")


def _value_error_classes(repo_root):
    for pkg in PACKAGES:
        for path in sorted((repo_root / pkg).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.ClassDef) and any(
                        isinstance(b, ast.Name) and b.id == "ValueError" for b in node.bases):
                    yield f"{path.relative_to(repo_root)}:{node.lineno} {node.name}"


def test_only_the_base_class_derives_from_value_error_itself(repo_root):
    assert list(_value_error_classes(repo_root)) == ["core/errors.py:6 DockfactoryError"]


def test_an_image_header_error_is_a_dockfactory_error_and_still_a_value_error():
    from dockfactory.core.errors import DockfactoryError
    from dockfactory.measure.image_header import ImageHeaderError, ImageTooLarge
    for cls in (ImageHeaderError, ImageTooLarge):
        assert issubclass(cls, DockfactoryError) and issubclass(cls, ValueError)


def test_the_cli_reports_an_image_header_error_in_one_line_with_exit_2(tmp_path, capsys, monkeypatch):
    import argparse

    from dockfactory import cli
    from dockfactory.measure.image_header import image_size
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"\x89PNG\r\n\x1a\n")

    def parser():
        p = argparse.ArgumentParser()
        p.set_defaults(func=lambda args: image_size(bad))
        return p
    monkeypatch.setattr(cli, "build_parser", parser)
    assert cli.main([]) == 2
    err = capsys.readouterr().err
    assert err == "dockfactory: error: a PNG file without its header (IHDR): truncated or damaged\n"

