"""The dataset's exports: a writer per format of ``[export] formats`` and ``dataset export``, each
writing ``exports/<format>/`` of an intact, complete dataset.

A module per format (``coco``, ``bop``, ``video``, ...), each declaring its formats (``FORMATS``:
:class:`~dockfactory.generator.exports.registry.ExportFormat`); helpers: ``coco_results`` (a
detections document as COCO results rows), ``files`` (placing a dataset's files in an export),
``registry``. Importing the package imports every module of its folder and collects the
declarations: ``FORMATS`` (name -> ExportFormat), ``WRITERS`` (name -> writer) and each writer under
its name ``export_<name>``; a module added to the folder registers itself.
"""
import pkgutil
from importlib import import_module

from dockfactory.core.config import Config, ConfigError
from dockfactory.generator.exports.coco import coco_from_labels
from dockfactory.generator.exports.coco_results import coco_results
from dockfactory.generator.exports.registry import collect

# every module of this folder, imported here (tests/layercheck.py sees these imports)
FORMATS = collect(import_module(f"{__name__}.{m.name}") for m in pkgutil.iter_modules(__path__))
WRITERS = {name: fmt.writer for name, fmt in FORMATS.items()}
globals().update({fmt.writer.__name__: fmt.writer for fmt in FORMATS.values()})   # export_<name>


def check_export_formats(cfg: Config, source: str = "<config>") -> None:
    """Check the names of ``[export] formats`` against the registry (what render writes when the dataset completes).

    Parameters
    ----------
    cfg : Config
        The config (its ``export.formats``, strings by the config's type check).
    source : str
        The config's file, named in the error.

    Returns
    -------
    None

    Raises
    ------
    ConfigError
        One line naming ``source``, ``[export] formats`` and the first name that is no format, or that of
        a format written on demand only (``dataset export``).
    """
    known = [name for name, fmt in FORMATS.items() if not fmt.on_demand]
    for name in cfg.export.formats:
        if name in FORMATS and FORMATS[name].on_demand:
            raise ConfigError(f"{source}: [export] formats: {name!r} is written on demand only "
                              f"(dockfactory dataset export --format {name}); known: {', '.join(known)}")
        if name not in FORMATS:
            raise ConfigError(f"{source}: [export] formats: unknown format {name!r} (known: {', '.join(known)})")


__all__ = [
    # the writers of exports/<format>/, one per declared format
    *(fmt.writer.__name__ for fmt in FORMATS.values()),
    # COCO dicts without a dataset folder
    "coco_from_labels", "coco_results",
    # the config's names checked against the registry
    "check_export_formats",
]
