"""Atomic file writes (a temporary name in the same folder, fsync, rename), the cleanup of the
temporaries a killed writer leaves, and exclusive folder locks."""
from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import shlex
import shutil
import socket
import sys
import time
from pathlib import Path

from dockfactory.core.errors import DockfactoryError

HOST = socket.gethostname().replace("-", "_")
TMP_MARK = ".tmp-"
LOCK_NAME = ".dockfactory.lock"


def temp_name(name: str) -> str:
    """The temporary name of ``name`` for this process: ``.<name>.tmp-<host>-<pid>``."""
    return f".{name}{TMP_MARK}{HOST}-{os.getpid()}"


class WriteError(DockfactoryError, OSError):
    """An output that cannot be written (a folder, read-only, a full disk): one line naming the
    path. Still an ``OSError`` with the original ``errno``, so callers that handle OSError work."""

    def __str__(self) -> str:
        return str(self.args[0])


def write_error(path, exc: OSError) -> WriteError:
    """The one-line :class:`WriteError` for ``exc``, raised while writing ``path``."""
    path = Path(path)
    why = exc.strerror or str(exc)
    if isinstance(exc, IsADirectoryError) or path.is_dir():
        why = "it is a folder"
    elif isinstance(exc, (FileExistsError, NotADirectoryError)):
        why = f"a parent of it is not a folder ({why})"
    err = WriteError(f"{path}: cannot write: {why}")
    err.errno, err.strerror, err.filename = exc.errno, exc.strerror, str(path)
    return err


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path``; on success it replaces ``path`` atomically.

    An OSError on the way (making the folder, the body, fsync, the rename) becomes one
    :class:`WriteError` naming ``path``; the temporary is removed, ``path`` keeps its old bytes.
    """
    path = Path(path)
    tmp = path.with_name(temp_name(path.name))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        yield tmp
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(exc, OSError) and not isinstance(exc, WriteError):
            raise write_error(path, exc) from exc
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


def temp_writer(path: Path) -> tuple[str, int | None]:
    """(host, pid) of the process that made temporary ``path`` (pid None when the name has none)."""
    tag = Path(path).name.rsplit(TMP_MARK, 1)[-1]
    host, _, pid = tag.rpartition("-")
    return host, (int(pid) if pid.isdigit() else None)


def dead_writer(path: Path) -> bool:
    """True when temporary ``path`` was made by a process of this host that is gone (or a zombie)."""
    host, pid = temp_writer(path)
    return host == HOST and pid is not None and not pid_alive(pid)


def stale_temp(path: Path, max_age_s: float, own: bool = False) -> bool:
    """A temporary file or folder left by a killed writer: its process is gone (same host), or it
    is older than ``max_age_s``; with ``own``, also one of this very process (a caller that holds
    the folder's lock and is not writing it any more)."""
    try:
        if dead_writer(path):
            return True
        if own and temp_writer(path) == (HOST, os.getpid()):
            return True
        return time.time() - path.lstat().st_mtime > max_age_s
    except FileNotFoundError:
        return False


def remove_stale_temps(root, max_age_s: float, own: bool = False) -> list[Path]:
    """Delete stale temporary files and folders (an export built aside) under ``root``; returns
    what was removed. Symlinks are removed, never followed."""
    removed: list[Path] = []
    for path in sorted(Path(root).rglob(f".*{TMP_MARK}*")):
        if any(parent in removed for parent in path.parents) or not stale_temp(path, max_age_s, own):
            continue
        with contextlib.suppress(FileNotFoundError):
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            else:
                path.unlink()
            removed.append(path)
    return removed


# ----------------------------------------------------------------------------- locks

class FolderBusy(DockfactoryError):
    """Another process holds the folder's lock; the message names it."""


def _command_line() -> str:
    argv = list(sys.argv) or ["?"]
    if Path(argv[0]).name in ("dockfactory", "__main__.py"):
        argv[0] = "dockfactory"
    return shlex.join(argv)


def _holder_text(raw: bytes) -> str:
    try:
        h = json.loads(raw.decode("utf-8"))
        text = (f"{h['what']} by pid {h['pid']} on host {h['host']} since {h['since']}: "
                f"{h['command']}")
        return " ".join(text.split())[:500]   # one line, whatever the holder's arguments
    except (ValueError, KeyError, TypeError, UnicodeDecodeError):
        return "holder unknown: it has not written its name yet"


@contextlib.contextmanager
def folder_lock(folder, what: str, lock_path=None):
    """Hold the exclusive lock of ``folder`` (``fcntl.flock`` on ``lock_path``, by default
    ``folder/.dockfactory.lock``) for the duration of the block. Non-blocking: when another process
    holds it, raise :class:`FolderBusy` naming the holder (what, pid, host, command). The lock dies
    with its process (kill -9 included); the lock file stays (removing it would race). A lock file
    that is a symlink is never opened: the folder holding it is locked instead (unnamed holder)."""
    folder = Path(folder)
    path = Path(lock_path) if lock_path is not None else folder / LOCK_NAME
    if path.is_symlink():   # never opened: writing the holder's name would write where the link points
        with _directory_lock(path.parent, folder):
            yield path
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
    except OSError as exc:
        raise DockfactoryError(f"{path}: cannot create the lock file of {folder} ({exc.strerror})") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise FolderBusy(f"{folder}: in use by another dockfactory process ({_holder_text(os.pread(fd, 4096, 0))}); "
                             f"wait for it to finish (or stop it) and run this command again") from None
        me = {"what": what, "pid": os.getpid(), "host": HOST, "command": _command_line(),
              "since": time.strftime("%Y-%m-%d %H:%M:%S")}
        os.ftruncate(fd, 0)
        os.pwrite(fd, (json.dumps(me) + "\n").encode("utf-8"), 0)
        try:
            yield path
        finally:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, 0)
    finally:
        os.close(fd)   # releases the lock


@contextlib.contextmanager
def _directory_lock(directory: Path, folder: Path):
    """``flock`` on ``directory`` itself (nothing written), the lock of ``folder`` when its lock
    file is a symlink (a dataset tracked with DVC's symlink cache links its ``logs/`` files);
    FolderBusy when another process holds it. A symlinked directory is refused."""
    if directory.is_symlink():
        raise DockfactoryError(f"{directory}: is a symlink; the lock of {folder} lives in a real folder")
    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise FolderBusy(f"{folder}: in use by another dockfactory process (its lock file is a symlink, so the "
                             "holder is not named); wait for it to finish (or stop it) and run this command again") from None
        yield
    finally:
        os.close(fd)   # releases the lock


def check_output_folder(folder, option: str = "--out") -> Path:
    """``folder`` as a Path when it can be an output folder as far as can be told without making it
    (not an empty path, not an existing file), else one :class:`DockfactoryError` line naming
    ``option``: a command checks its ``--out`` so before work whose results it would lose."""
    if not str(folder).strip():   # Path("") is the current folder: never written by accident
        raise DockfactoryError(f"{option}: an empty path; give the output folder")
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise DockfactoryError(f"{option} {folder}: is a file, not a folder")
    return folder


def make_output_folder(folder, option: str = "--out") -> Path:
    """Create the output folder ``folder`` (and its parents) and return it, or raise one
    :class:`DockfactoryError` line naming ``option`` and the folder: an existing file, a folder
    under a file, a place where no folder can be made (read-only, /proc), a folder not writable."""
    folder = check_output_folder(folder, option)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        why = ("a parent of it is not a folder" if isinstance(exc, (NotADirectoryError, FileExistsError))
               else exc.strerror or str(exc))
        raise DockfactoryError(f"{option} {folder}: cannot create this folder ({why})") from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise DockfactoryError(f"{option} {folder}: this folder is not writable")
    return folder


@contextlib.contextmanager
def output_lock(folder, what: str, option: str = "--out", lock_path=None):
    """:func:`make_output_folder`, then hold its :func:`folder_lock` (``lock_path`` as there) for
    the block: a writer's whole run, so two writers never interleave their outputs."""
    folder = make_output_folder(folder, option)
    with folder_lock(folder, what, lock_path):
        yield folder
