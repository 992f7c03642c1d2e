"""Atomic file writes: write to a temporary name in the same folder, fsync, rename."""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import socket
import time
from pathlib import Path

HOST = socket.gethostname().replace("-", "_")
TMP_MARK = ".tmp-"


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path``; on success it replaces ``path`` atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}{TMP_MARK}{HOST}-{os.getpid()}")
    try:
        yield tmp
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise


def write_bytes_atomic(path, data: bytes) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)


def write_text_atomic(path, text: str) -> None:
    write_bytes_atomic(path, text.encode("utf-8"))


def write_json_atomic(path, obj, indent: int | None = 1) -> None:
    write_text_atomic(path, json.dumps(obj, indent=indent, sort_keys=False, allow_nan=False) + "\n")


def sha256_file(path, chunk: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def pid_alive(pid: int) -> bool:
    """Whether a process with this pid is running on this host. A zombie (killed, not yet reaped by
    its new parent) counts as dead: it will never finish a write."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return not _is_zombie(pid)


def _is_zombie(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:  # no /proc (not Linux) or the process is gone
        return False
    return stat.rsplit(")", 1)[-1].split()[0] in ("Z", "X")


def is_temp_name(name: str) -> bool:
    return name.startswith(".") and TMP_MARK in name


def stale_temp(path: Path, max_age_s: float) -> bool:
    """A temporary file left by a killed writer: its process is gone (same host) or it is old."""
    tag = path.name.rsplit(TMP_MARK, 1)[-1]
    host, _, pid = tag.rpartition("-")
    try:
        if host == HOST and pid.isdigit() and not pid_alive(int(pid)):
            return True
        return time.time() - path.stat().st_mtime > max_age_s
    except FileNotFoundError:
        return False


def remove_stale_temps(root, max_age_s: float) -> list[Path]:
    """Delete stale temporary files under ``root``; returns what was removed."""
    removed = []
    for path in Path(root).rglob(f".*{TMP_MARK}*"):
        if path.is_file() and stale_temp(path, max_age_s):
            with contextlib.suppress(FileNotFoundError):
                path.unlink()
                removed.append(path)
    return removed


def load_labels(root, split: str | None = None) -> list[dict]:
    """Labels of a dataset (optionally one split), in frame-id order."""
    out = []
    for path in sorted((Path(root) / "labels").glob("*.json")):
        label = json.loads(path.read_text())
        if split is None or label["spec"]["split"] == split:
            out.append(label)
    return out
