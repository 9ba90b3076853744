"""A run folder's safety: one run at a time, no silent mixing with old results, no symlinks.

- **Lock**: a run holds ``DIR/ntncontact.lock`` (an ``flock`` on it, and its text names the PID,
  host and start time). A second run into the folder fails with an error naming the first. The
  kernel releases an ``flock`` when its process dies, even by SIGKILL, so a killed run never
  blocks the folder; its lock file stays behind, naming a PID that is gone, which is how
  :func:`run_status` tells a dead run ("stale") from a running one.
- **Old results**: a folder that already holds results (:data:`RESULT_FILES`, the ``fields/``
  frames, figures) is refused unless ``overwrite``; then exactly those are removed first. Other
  files in the folder are never touched, so ``--out`` pointing at a folder with other work in it
  loses nothing but what a run writes.
- **Symlinks**: files are created with ``O_EXCL | O_NOFOLLOW`` or written to a fresh temporary
  file that is renamed over the name, so a symbolic link planted under a result's name is
  replaced or refused, never written through.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import socket
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

LOCK_FILE = "ntncontact.lock"
#: Files a run (or ``plot`` / ``compare`` on its folder) writes at the folder's top level.
RESULT_FILES = ("summary.json", "history.csv", "contact.csv", "fields.pvd", "comparison.csv",
                "fields.xdmf", "fields.h5")
#: The folder of the VTU frames, and the suffixes of the figures (their names vary by scenario).
FIELDS_DIR = "fields"
FIGURE_SUFFIXES = (".png", ".gif")


class RunFolderError(RuntimeError):
    """A results folder that a run cannot use (in use, holds results, a planted symlink)."""


def create_new_text(path: Path) -> IO[str]:
    """A new text file at ``path``, opened for writing; refused if anything (a file, or a
    symbolic link, which is not followed) has that name already."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC
    try:
        fd = os.open(path, flags, 0o666)
    except FileExistsError:
        raise RunFolderError(f"{path} exists already (a file or a symbolic link): "
                             "not writing over it") from None
    return os.fdopen(fd, "w", newline="", encoding="utf-8")


#: The process's umask, read once (reading it means setting it), for the temporary files.
_UMASK = os.umask(0o022)
os.umask(_UMASK)


def new_temporary(path: Path) -> tuple[int, Path]:
    """A new file beside ``path`` with a fresh random name (created exclusively), open for
    writing, with the permissions a plain ``open`` would give (mkstemp's are 0600)."""
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.fchmod(fd, 0o666 & ~_UMASK)
    return fd, Path(name)


def replace_atomically(path: Path, write: Callable[[Path], None], sync: bool = False) -> None:
    """Have ``write`` fill a new temporary file beside ``path``, then rename it over ``path``.

    Readers see the old file or the complete new one, never a partial one. The temporary file
    has a fresh random name (created exclusively), and the rename replaces a symbolic link at
    ``path`` rather than following it. ``sync`` flushes the file to disk before the rename
    (protection against power loss; the run's own end is covered without it)."""
    fd, tmp = new_temporary(path)
    try:
        os.close(fd)
        write(tmp)
        if sync:
            with open(tmp, "rb") as handle:
                os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException as err:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(err, OSError) and err.errno is not None and err.filename is None:
            # a failed write of the file's data names no file ("[Errno 28] No space left")
            raise OSError(err.errno, err.strerror, str(path)) from None
        raise


def make_subfolder(path: Path) -> None:
    """Create the folder ``path`` (or keep it); refuse a symbolic link in its place."""
    with contextlib.suppress(FileExistsError):
        os.mkdir(path)
    if path.is_symlink() or not path.is_dir():
        raise RunFolderError(f"{path} is a symbolic link or not a folder: not writing into it")


# ------------------------------------------------------------------------------------------------
# The lock
# ------------------------------------------------------------------------------------------------
class RunLock:
    """The exclusive lock of a run folder, held from :meth:`acquire` to :meth:`release`."""

    def __init__(self, path: Path, fd: int) -> None:
        self.path = path
        self._fd: int | None = fd
        self._info: dict[str, Any] = {}

    @classmethod
    def acquire(cls, directory: Path, phase: str | None = None) -> RunLock:
        """Lock ``directory`` for this process, or raise :class:`RunFolderError` naming the run
        that holds it. ``phase`` ("building": the command locks the folder before its model's
        build, up to 35 s for long interfaces) is written in the lock file for :func:`run_status`
        until :meth:`set_phase` clears it."""
        path = directory / LOCK_FILE
        while True:
            try:
                fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o666)
            except OSError as err:
                if err.errno == errno.ELOOP:
                    raise RunFolderError(f"{path} is a symbolic link: not using it") from None
                raise
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                info = read_lock(directory)
                holder = ("its PID is not written yet" if info is None else f"PID "
                          f"{info.get('pid')} on {info.get('host')}, started {info.get('started')}")
                raise RunFolderError(f"{directory} is in use by another run: {holder} (lock "
                                     f"file {path})") from None
            # The holder before us may have removed the file between our open and our lock:
            # then we hold a lock on a file nobody else will see, so try again.
            if _same_file(path, fd):
                break
            os.close(fd)
        info = {"pid": os.getpid(), "host": socket.gethostname(),
                "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
        os.ftruncate(fd, 0)
        lock = cls(path, fd)
        lock._info = info
        lock.set_phase(phase)
        return lock

    def set_phase(self, phase: str | None) -> None:
        """Write (or, None, drop) the ``phase`` the lock file names. One ``pwrite`` padded
        with spaces, as summary.json's (never truncated): a reader sees the old text or the
        new one, both valid JSON."""
        if self._fd is None:
            return
        info = {k: v for k, v in self._info.items() if k != "phase"}
        if phase is not None:
            info["phase"] = phase
        self._info = info
        data = (json.dumps(info) + "\n").encode()
        os.pwrite(self._fd, data.ljust(os.fstat(self._fd).st_size), 0)

    def release(self) -> None:
        """Remove the lock file and unlock (harmless when released already)."""
        if self._fd is None:
            return
        fd, self._fd = self._fd, None
        try:
            if _same_file(self.path, fd):
                self.path.unlink()
        finally:
            os.close(fd)


def _same_file(path: Path, fd: int) -> bool:
    try:
        named = os.lstat(path)
    except FileNotFoundError:
        return False
    held = os.fstat(fd)
    return (named.st_dev, named.st_ino) == (held.st_dev, held.st_ino)


def read_lock(directory: Path) -> dict[str, Any] | None:
    """What the lock file of ``directory`` says (pid, host, started), or None if there is none
    or it cannot be read yet."""
    try:
        fd = os.open(directory / LOCK_FILE, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except OSError:
        return None
    with os.fdopen(fd, encoding="utf-8") as handle:
        try:
            info = json.loads(handle.read())
        except ValueError:  # being written
            return None
    return info if isinstance(info, dict) else None


def lock_holder_alive(directory: Path, info: dict[str, Any]) -> bool:
    """Whether the run a lock file names still runs: on this host, whether its PID exists;
    on another host, whether the lock is still held (which is as good as the file system's
    locks across hosts)."""
    if info.get("host") == socket.gethostname():
        try:
            os.kill(int(info["pid"]), 0)
        except ProcessLookupError:
            return False
        except PermissionError:  # another user's process
            return True
        except (KeyError, TypeError, ValueError):
            return False
        return True
    try:
        fd = os.open(directory / LOCK_FILE, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)
    return False


# ------------------------------------------------------------------------------------------------
# Old results
# ------------------------------------------------------------------------------------------------
def existing_results(directory: Path) -> list[str]:
    """Names of the results a run writes that ``directory`` holds (a symbolic link with such a
    name counts), in a stable order."""
    if not directory.is_dir():
        return []
    found = [name for name in (*RESULT_FILES, FIELDS_DIR) if os.path.lexists(directory / name)]
    found += sorted(p.name for p in directory.iterdir()
                    if p.suffix.lower() in FIGURE_SUFFIXES and not p.is_dir())
    return found


def remove_results(directory: Path) -> None:
    """Remove what :func:`existing_results` lists, and the temporary files of a killed run.
    Symbolic links are removed, never followed; ``fields/`` loses its VTU frames only (the
    folder itself goes when nothing else is in it)."""
    for name in existing_results(directory):
        path = directory / name
        if name == FIELDS_DIR and path.is_dir() and not path.is_symlink():
            for frame in path.iterdir():
                if frame.suffix in (".vtu", ".tmp") and not frame.is_dir():
                    frame.unlink()
            with contextlib.suppress(OSError):  # other files in it: keep them, and it
                path.rmdir()
        else:
            path.unlink()
    remove_leftovers(directory)


def remove_leftovers(directory: Path) -> None:
    """Remove the temporary files of the results a killed run was writing (see
    :func:`replace_atomically`)."""
    for leftover in directory.glob(".*.tmp"):
        if any(leftover.name.startswith(f".{name}.") for name in RESULT_FILES) \
                and not leftover.is_dir():
            leftover.unlink()


def prepare(directory: Path, overwrite: bool, lock: RunLock | None = None) -> RunLock:
    """Create ``directory`` if needed and lock it (``lock``: this process holds it already,
    since before the model's build); refuse it if it holds results, unless ``overwrite``,
    which removes them. Returns the held lock."""
    directory.mkdir(parents=True, exist_ok=True)
    lock = lock or RunLock.acquire(directory)
    lock.set_phase(None)  # built: from here on summary.json tells the run's state
    try:
        found = existing_results(directory)
        if found and not overwrite:
            shown = ", ".join(found[:5]) + (", ..." if len(found) > 5 else "")
            raise RunFolderError(f"{directory} already holds results ({shown}): choose "
                                 "another folder, or replace them (--overwrite; "
                                 "overwrite=True in ntncontact.run)")
        if found:
            remove_results(directory)
    except BaseException:
        lock.release()
        raise
    return lock


# ------------------------------------------------------------------------------------------------
# Status
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RunStatus:
    """A results folder's run as a reader sees it. ``state`` is the summary's status, except
    "running" when no live process holds the folder, which is "stale" (the run was killed),
    and "starting" while a live run holds the folder before its summary.json exists or while
    it builds its model (``phase`` "building"; an older run's summary may still be there)."""

    state: str
    steps: int | None
    time: float | None
    error: str | None
    lock: dict[str, Any] | None
    phase: str | None = None


def read_summary(directory: Path, tries: int = 5) -> dict[str, Any]:
    """``directory``/summary.json, read again (up to ``tries`` times, 10 ms apart) when caught
    mid-write: while a run goes on it is rewritten in place (see ``SummaryWriter``)."""
    path = directory / "summary.json"
    for _ in range(tries - 1):
        with contextlib.suppress(ValueError):
            return _read_json(path)
        time.sleep(0.01)
    try:
        return _read_json(path)
    except ValueError as err:
        raise RunFolderError(f"{path} is not valid JSON: {err}") from None


def _read_json(path: Path) -> dict[str, Any]:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        if not path.parent.is_dir():  # a mistyped folder is not "a folder without a run"
            raise RunFolderError(f"{path.parent} does not exist") from None
        raise RunFolderError(f"{path.parent} holds no run (no summary.json)") from None


def run_status(directory: Path) -> RunStatus:
    """The status of the run in ``directory`` (see :class:`RunStatus`)."""
    lock = read_lock(directory)
    alive = lock is not None and lock_holder_alive(directory, lock)
    phase = lock.get("phase") if alive and lock is not None else None
    try:
        summary = read_summary(directory)
    except RunFolderError:
        if lock is None or (directory / "summary.json").exists():  # no run, or unreadable
            raise
        # locked before anything was written: starting, or killed then (stale)
        return RunStatus("starting" if alive else "stale", None, None, None, lock, phase)
    state = summary.get("status")
    if phase is not None:  # an older run's summary, about to be replaced
        return RunStatus("starting", None, None, None, lock, phase)
    if alive:
        state = "running"
    elif state == "running":
        state = "stale"
    return RunStatus(str(state), summary.get("steps"), summary.get("time"), summary.get("error"),
                     lock)
