"""The export formats have one list of names the config knows (core.names.EXPORT_FORMATS, what
[export] formats and render write), one registry of writers built from it (generator.exports.WRITERS,
each name's ``export_<name>`` of the facade, plus the on-demand videos; datasets.tools reads it)
and the command line's help: a format added to one and not the others fails here."""
from dockfactory.cli import build_parser
from dockfactory.core.names import EXPORT_FORMATS
from dockfactory.generator.datasets import tools as dt
from dockfactory.generator.exports import ON_DEMAND, WRITERS, export_video_lossless, export_yolo_pose


def _export_help() -> str:
    export = build_parser().subcommands.choices["dataset"].subcommands.choices["export"]
    return next(a.help for a in export.arguments if "--format" in a.option_strings)


def test_names_writers_and_help_agree():
    assert tuple(dt.EXPORT_WRITERS) == EXPORT_FORMATS + ON_DEMAND and dt.EXPORT_WRITERS is WRITERS
    assert WRITERS["yolo-pose"] is export_yolo_pose and WRITERS["video_lossless"] is export_video_lossless
    assert all(callable(w) for w in dt.EXPORT_WRITERS.values())
    text = _export_help()
    assert all(name in text for name in dt.EXPORT_WRITERS), text
