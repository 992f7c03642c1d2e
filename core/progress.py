"""The one progress display of every long command (render, detect, measure, train): on a
terminal a bar redrawn in place; in a log (stderr not a terminal) a plain line every ``every_s``
seconds and at the end, never a carriage return."""
from __future__ import annotations

import sys
import time


def _hms(seconds: float) -> str:
    seconds = int(max(0, seconds))
    return f"{seconds // 3600}:{seconds // 60 % 60:02d}:{seconds % 60:02d}"


class Progress:
    def __init__(self, total: int, label: str, enabled: bool = True, stream=None, every_s: float = 10.0,
                 per: str = "h"):
        """``total`` items, ``label`` first on the line, ``per``: the rate's unit ("h" or "s")."""
        self.total, self.label, self.enabled, self.per = total, label, enabled, per
        self.extra = ""
        self.stream = stream or sys.stderr
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.start = time.monotonic()
        self.done = 0
        self.failed = 0
        self.every_s = every_s
        self._last_print = 0.0

    def line(self) -> str:
        elapsed = time.monotonic() - self.start
        rate = self.done / elapsed if elapsed > 0 else 0.0
        eta = (self.total - self.done) / rate if rate > 0 else float("nan")
        width = 24
        fill = int(width * self.done / self.total) if self.total else width
        bar = "#" * fill + "-" * (width - fill)
        eta_s = _hms(eta) if eta == eta else "?"
        failed = f"  failed {self.failed}" if self.failed else ""
        rate_text = f"{rate * 3600:.0f}/h" if self.per == "h" else f"{rate:.1f}/s"
        extra = f"  {self.extra}" if self.extra else ""
        return (f"{self.label} [{bar}] {self.done}/{self.total}  {rate_text}  "
                f"elapsed {_hms(elapsed)}  ETA {eta_s}{failed}{extra}")

    def update(self, done: int, failed: int = 0, extra: str | None = None) -> None:
        """``done`` of ``total`` (``failed`` of them failed); ``extra``: text after the figures."""
        self.done, self.failed = done, failed
        if extra is not None:
            self.extra = extra
        self.refresh()

    def refresh(self, force: bool = False) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if self.tty:
            self.stream.write("\r" + self.line() + "\x1b[K")
            self.stream.flush()
        elif force or now - self._last_print >= self.every_s:
            self._last_print = now
            print(self.line(), file=self.stream, flush=True)

    def note(self, text: str) -> None:
        if self.enabled:
            if self.tty:
                self.stream.write("\r\x1b[K")
            print(text, file=self.stream, flush=True)

    def close(self) -> None:
        if self.enabled:
            if self.tty:
                self.stream.write("\r" + self.line() + "\x1b[K\n")
            else:
                print(self.line(), file=self.stream, flush=True)
