"""The one base class of dockfactory's errors: bad input (a config, a dataset, a file, a
command-line value) that the CLI reports in one line with exit status 2."""
from __future__ import annotations


class DockfactoryError(ValueError):
    """Bad input: the message names the problem (file, key, value). A ``ValueError`` subclass, so
    callers that check arrays and values the plain Python way catch it too."""
