"""A render worker dies with the process that started it (issue 46, item 7): that process held
the dataset folder's lock, so an orphaned worker must neither render on nor write a frame."""
import os
import subprocess
import sys
import time

import pytest

from dockfactory.generator import render_worker


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as fh:            # a zombie is gone too
        return fh.read().split(")")[-1].split()[0] != "Z"


@pytest.mark.slow   # seconds of work: the full suite runs it (make test), the fast lane does not
def test_a_worker_whose_starter_is_killed_exits():
    """A starter process starts a worker the way the pool does and is killed (SIGKILL); the
    worker, idle on its stdin (which the starter's death does not close: the test holds it),
    exits within a few poll periods (before: it lived on until its stdin closed)."""
    starter = subprocess.Popen([sys.executable, "-c", (
        "import os, subprocess, sys, time\n"
        "env = dict(os.environ, DOCKFACTORY_WORKER_PARENT=str(os.getpid()))\n"
        "w = subprocess.Popen([sys.executable, '-m', 'dockfactory.generator.render_worker'], env=env,\n"
        "                     stdin=sys.stdin, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)\n"
        "print(w.pid, flush=True)\n"
        "time.sleep(60)\n")], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    worker = int(starter.stdout.readline())
    time.sleep(2.0)                                  # the worker is up, idle on its stdin
    assert _alive(worker)
    starter.kill()
    starter.wait()
    deadline = time.monotonic() + 10 * render_worker.PARENT_POLL_S + 5.0
    while _alive(worker) and time.monotonic() < deadline:
        time.sleep(0.1)
    alive = _alive(worker)
    starter.stdin.close()
    assert not alive


def test_an_orphan_check_passes_under_its_starter():
    """Under its starter the check returns (the worker goes on)."""
    render_worker._exit_if_orphaned(os.getppid())
