"""The acceptance report as a PDF, through a real layout engine: WeasyPrint when it imports (a
PyPI package; it needs the Pango library of the system), else a headless Chromium on the PATH
(Debian's ``chromium``). The HTML's print stylesheet (``eval.report.document``) keeps each heading with its
plot or table and each figure on one page.

``pdf_engine()`` says which engine this machine has (None: neither); ``write_pdf`` writes the PDF
atomically. Neither downloads anything.
"""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

from dockfactory.core.errors import DockfactoryError
from dockfactory.core.io import atomic_path

CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome")
NO_ENGINE = ("no PDF engine: install WeasyPrint (pip install 'dockfactory[pdf]'; it needs the system's Pango "
             "library) or Debian's chromium, or print report.html from a browser")


def _weasyprint():
    """The weasyprint module, or None when it is absent or its system libraries are."""
    try:
        import weasyprint
    except (ImportError, OSError):
        return None
    return weasyprint


def pdf_engine() -> str | None:
    """The PDF engine this machine has.

    Parameters
    ----------
    None

    Returns
    -------
    str or None
        "weasyprint", the path of a Chromium executable, or None (neither is there).
    """
    if _weasyprint() is not None:
        return "weasyprint"
    return next((p for p in map(shutil.which, CHROMIUM_NAMES) if p), None)


def write_pdf(html_path, pdf_path) -> str:
    """Render a report's HTML to PDF, atomically (the old file or the new one, never a partial one).

    Parameters
    ----------
    html_path : path
        The report's HTML file (:func:`build_report`).
    pdf_path : path
        The PDF file to write.

    Returns
    -------
    str
        The engine used (:func:`pdf_engine`).

    Raises
    ------
    DockfactoryError
        When no engine is there or the engine fails (its message, one line).
    """
    engine = pdf_engine()
    if engine is None:
        raise DockfactoryError(NO_ENGINE)
    html_path, pdf_path = Path(html_path).resolve(), Path(pdf_path)
    with atomic_path(pdf_path) as tmp:
        if engine == "weasyprint":
            _weasyprint().HTML(filename=str(html_path)).write_pdf(str(tmp))
        else:
            _chromium(engine, html_path, Path(tmp))
    return engine


def _chromium(exe: str, html_path: Path, out: Path) -> None:
    cmd = [exe, "--headless", "--no-sandbox", "--disable-gpu", "--no-pdf-header-footer",
           f"--print-to-pdf={out}", html_path.as_uri()]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    if proc.returncode != 0 or not out.is_file():
        last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        raise DockfactoryError(f"{exe}: could not print {html_path} to PDF: {last}")
