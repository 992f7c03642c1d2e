"""No module reads or patches argparse's private attributes (``parser._actions``,
``argparse._SubParsersAction``, ...): they change between Python versions without notice. The
walk over every command and flag goes through cli_args.CommandParser's public ``arguments`` and
``subcommands`` instead (static: the sources are parsed, never imported)."""
import argparse
import ast

FOLDERS = ("core", "solver", "eval", "detector", "generator", "blender_scenes", "dockfactory", "bench", "tests")


def _private_names() -> set[str]:
    """The single-underscore attributes and methods of argparse's parser, group and actions."""
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    objects = (parser, sub, parser.add_argument_group(), parser.add_mutually_exclusive_group(),
               parser.add_argument("--x"), sub.add_parser("y"))
    return {n for o in objects for n in (*dir(o), *vars(o)) if n.startswith("_") and not n.startswith("__")}


def _uses(repo_root, private: set[str]):
    for folder in FOLDERS:
        for path in sorted((repo_root / folder).rglob("*.py")):
            if "layer_fixture" in path.parts:
                continue
            for node in ast.walk(ast.parse(path.read_text())):
                if not isinstance(node, ast.Attribute):
                    continue
                on_argparse = isinstance(node.value, ast.Name) and node.value.id == "argparse"
                if (on_argparse and node.attr.startswith("_")) or node.attr in private:
                    yield f"{path.relative_to(repo_root)}:{node.lineno} .{node.attr}"


def test_the_private_names_are_argparse_s():
    assert {"_actions", "_option_string_actions", "_subparsers", "_group_actions", "_name_parser_map",
            "_defaults", "_get_formatter"} <= _private_names()


def test_no_module_uses_argparse_internals(repo_root):
    assert list(_uses(repo_root, _private_names())) == []
