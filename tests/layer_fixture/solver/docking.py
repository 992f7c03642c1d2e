"""VIOLATION (function-level, not heavy): a cycle dodged inside a function."""
from dockfactory.core.geometry import norm  # fine


def solve():
    from dockfactory.solver.identify import identify   # not heavy: violation
    return identify(norm)
