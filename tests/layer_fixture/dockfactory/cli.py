"""VIOLATION: importing the entry point; VIOLATION: a cheap project module inside a function."""
import dockfactory.__main__  # noqa: F401


def main():
    from dockfactory.eval.report import build_report   # not heavy: violation
    return build_report
