"""The export formats have one list of names the config knows (core.names.EXPORT_FORMATS, what
[export] formats and render write), one registry of writers (generator.datasets.tools.EXPORT_WRITERS:
those plus the on-demand videos) and the command line's help: a format added to one and not the
others fails here."""
from dockfactory.cli import build_parser
from dockfactory.core.names import EXPORT_FORMATS
from dockfactory.generator.datasets import tools as dt

ON_DEMAND = ("video", "video_lossless")   # written by `dataset export` only (datasets with [runs])


def _export_help() -> str:
    export = build_parser().subcommands.choices["dataset"].subcommands.choices["export"]
    return next(a.help for a in export.arguments if "--format" in a.option_strings)


def test_names_writers_and_help_agree():
    assert tuple(dt.EXPORT_WRITERS) == EXPORT_FORMATS + ON_DEMAND
    assert all(callable(w) for w in dt.EXPORT_WRITERS.values())
    text = _export_help()
    assert all(name in text for name in dt.EXPORT_WRITERS), text
