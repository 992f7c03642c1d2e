"""What an export format is: an :class:`ExportFormat` that its module declares, and how the
declarations of the package's modules become one registry (:func:`collect`).

A format module of ``generator/exports/`` ends with ``FORMATS = (ExportFormat(...), ...)`` (one
entry per format it writes); a module without ``FORMATS`` is a helper (``files``,
``coco_results``, this one). The package's facade imports every module of the package and hands
them to :func:`collect`: adding a format is its module (and its test), nothing else.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Callable

FORMAT_NAME = re.compile(r"[a-z][a-z0-9_-]*")   # a folder name, a TOML string, one item of --format a,b


@dataclass(frozen=True)
class ExportFormat:
    """One export format, as its module declares it.

    ``name``: what ``[export] formats`` and ``dataset export --format`` take, and the folder
    ``exports/<name>/``: lower-case letters, digits, ``_`` and ``-``, starting with a letter.
    ``writer(ds, out)``: writes the export of the opened dataset ``ds`` into the folder ``out`` it
    is given and returns it; named ``export_<name>`` (``-`` as ``_``), the name the facade gives it.
    ``summary``: one line for the command line's help. ``on_demand``: written by ``dataset export``
    only, never when a render completes (``[export] formats`` refuses it).
    A declaration breaking one of these rules raises ValueError when its module is imported.
    """

    name: str
    writer: Callable
    summary: str
    on_demand: bool = False

    def __post_init__(self):
        if not isinstance(self.name, str) or not FORMAT_NAME.fullmatch(self.name):
            raise ValueError(f"export format {self.name!r}: a name is lower-case letters, digits, '_' and '-', "
                             f"starting with a letter")
        wanted = "export_" + self.name.replace("-", "_")
        if not callable(self.writer) or getattr(self.writer, "__name__", None) != wanted:
            raise ValueError(f"export format {self.name!r}: its writer must be a function named {wanted}")
        if not isinstance(self.summary, str) or not self.summary.strip() or "\n" in self.summary:
            raise ValueError(f"export format {self.name!r}: its summary must be one line of help text")


def collect(modules) -> dict[str, ExportFormat]:
    """The registry of the formats that ``modules`` declare.

    Parameters
    ----------
    modules : iterable of module
        The package's modules; each one's ``FORMATS`` (a tuple of ExportFormat) is read, a module
        without it is a helper and adds nothing.

    Returns
    -------
    dict of str to ExportFormat
        Name -> format: those written when a render completes first, then the on-demand ones, each
        group by name.

    Raises
    ------
    ValueError
        ``FORMATS`` is not a tuple of ExportFormat, or two declarations share a name.
    """
    found: dict[str, tuple[ExportFormat, str]] = {}
    for module in modules:
        declared = getattr(module, "FORMATS", ())
        if not isinstance(declared, tuple) or not all(isinstance(f, ExportFormat) for f in declared):
            raise ValueError(f"{module.__name__}.FORMATS: not a tuple of ExportFormat")
        for fmt in declared:
            if fmt.name in found:
                raise ValueError(f"export format {fmt.name!r}: declared by {found[fmt.name][1]} "
                                 f"and by {module.__name__}")
            found[fmt.name] = (fmt, module.__name__)
    order = sorted(found, key=lambda name: (found[name][0].on_demand, name))
    return {name: found[name][0] for name in order}
