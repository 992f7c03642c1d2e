"""The acceptance report (``dockfactory report``): one self-contained HTML file, report.json and a
Markdown summary of an evaluation folder, and its PDF.

Modules: :mod:`~dockfactory.eval.report.document` (reads and checks the evaluation, writes the
HTML, JSON and Markdown), :mod:`~dockfactory.eval.report.budget` (the uncertainty budget table),
:mod:`~dockfactory.eval.report.calibration` (centre noise, bounds, covariance calibration),
:mod:`~dockfactory.eval.report.cameras` (the tolerance envelope and the camera models),
:mod:`~dockfactory.eval.report.pdf` (the PDF through WeasyPrint or a headless Chromium). Importing
the package loads neither matplotlib nor a PDF engine: each is imported when first used.
"""
from dockfactory.eval.report.document import build_report, check_schema, read_rows
from dockfactory.eval.report.pdf import NO_ENGINE, pdf_engine, write_pdf

__all__ = [
    # the report of an evaluation folder and its inputs
    "build_report", "read_rows", "check_schema",
    # the PDF
    "pdf_engine", "write_pdf", "NO_ENGINE",
]
