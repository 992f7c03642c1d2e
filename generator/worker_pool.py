"""Render worker processes seen from the job: start, request with a time limit, kill, restart.

Each worker is ``python -m dockfactory.generator.render_worker`` (bpy is imported only there). A worker that
dies (segfault, kill) or exceeds its time limit is killed and reported, so the job can restart it
and retry the frame.
"""
from __future__ import annotations

import json
import os
import selectors
import subprocess
import sys
import time
from pathlib import Path

from dockfactory.core.blas import pin_label_blas


class WorkerDied(RuntimeError):
    """The worker process exited or stopped answering in time."""


class WorkerProcess:
    def __init__(self, init_request: dict, log_path: Path, env: dict | None = None):
        self.init_request = init_request
        self.log_path = Path(log_path)
        self.env = env
        self.proc: subprocess.Popen | None = None
        self.frames_done = 0
        self._buf = b""
        self.info: dict = {}

    def start(self, timeout_s: float) -> dict:
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        log = open(self.log_path, "ab")
        env = dict(os.environ if self.env is None else self.env)
        env.setdefault("PYTHONUNBUFFERED", "1")
        env["DOCKFACTORY_WORKER_PARENT"] = str(os.getpid())   # the worker dies with this process
        pin_label_blas(env)   # the same label bytes on every x86-64 CPU (core.blas)
        # the installed package (no sys.path edits); the worker's cwd is the log folder, so no
        # folder of the caller's can shadow an import
        self.proc = subprocess.Popen([sys.executable, "-m", "dockfactory.generator.render_worker"],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log,
                                     env=env, cwd=str(self.log_path.parent))
        log.close()
        self._buf = b""
        self.frames_done = 0
        self.info = self.request(self.init_request, timeout_s)
        if not self.info.get("ok"):
            self.kill()
            raise RuntimeError(f"render worker failed to start: {self.info.get('error')}")
        return self.info

    @property
    def pid(self) -> int | None:
        return self.proc.pid if self.proc else None

    def send(self, msg: dict) -> None:
        if self.proc is None or self.proc.poll() is not None:
            raise WorkerDied("worker is not running")
        try:
            self.proc.stdin.write((json.dumps(msg) + "\n").encode())
            self.proc.stdin.flush()
        except (BrokenPipeError, OSError) as exc:
            raise WorkerDied(f"worker pipe closed ({exc})") from exc

    def recv(self, timeout_s: float) -> dict:
        """The next reply (replies come in request order)."""
        return json.loads(self._read_line(timeout_s))

    def request(self, msg: dict, timeout_s: float) -> dict:
        self.send(msg)
        return self.recv(timeout_s)

    def _read_line(self, timeout_s: float) -> bytes:
        deadline = time.monotonic() + timeout_s
        fd = self.proc.stdout.fileno()
        with selectors.DefaultSelector() as sel:
            sel.register(fd, selectors.EVENT_READ)
            while b"\n" not in self._buf:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise WorkerDied(f"no answer within {timeout_s:.0f} s (hung)")
                if not sel.select(timeout=min(left, 1.0)):
                    continue
                chunk = os.read(fd, 1 << 16)
                if not chunk:
                    code = self.proc.wait(timeout=5)
                    raise WorkerDied(f"worker exited with status {code}")
                self._buf += chunk
        line, self._buf = self._buf.split(b"\n", 1)
        return line

    def kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self.proc = None

    def close(self, timeout_s: float = 10.0) -> None:
        if self.proc is None:
            return
        if self.proc.poll() is None:
            try:
                self.proc.stdin.write(b'{"op": "quit"}\n')
                self.proc.stdin.flush()
                self.proc.wait(timeout=timeout_s)
            except (OSError, subprocess.TimeoutExpired):
                pass
        self.kill()
