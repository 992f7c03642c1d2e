"""core.progress: one display for render, detect, measure and train: a bar redrawn in place on a
terminal, plain lines (never a carriage return) in a log."""
import io

from dockfactory.core.progress import Progress


class _Tty(io.StringIO):
    def isatty(self):
        return True


def test_a_log_gets_plain_lines_and_a_terminal_a_bar():
    log = io.StringIO()
    p = Progress(4, "detect", stream=log, every_s=0.0, per="s")
    for i in range(4):
        p.update(i + 1, extra=f"{10 * (i + 1)} ms/image")
    p.close()
    text = log.getvalue()
    assert "\r" not in text and "\x1b" not in text
    lines = text.splitlines()
    assert len(lines) == 5 and lines[-1].startswith("detect [") and "4/4" in lines[-1] and "40 ms/image" in lines[-1]
    assert "/s" in lines[-1]
    tty = _Tty()
    p = Progress(2, "measure", stream=tty, per="s")
    p.update(1)
    p.update(2)
    p.close()
    assert tty.getvalue().count("\r") == 3 and tty.getvalue().endswith("\n")


def test_disabled_progress_writes_nothing():
    log = io.StringIO()
    p = Progress(3, "train", enabled=False, stream=log)
    p.update(1)
    p.note("x")
    p.close()
    assert log.getvalue() == ""
