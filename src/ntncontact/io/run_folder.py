"""Writing into a run folder without leaving partial files or following planted symlinks.

Files are written to a fresh temporary file that is renamed over the name, so readers see the
old file or the complete new one, and a symbolic link planted under the name is replaced,
never written through.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Callable
from pathlib import Path


class RunFolderError(RuntimeError):
    """A results folder that a run cannot use (a planted symlink)."""


def replace_atomically(path: Path, write: Callable[[Path], None], sync: bool = False) -> None:
    """Have ``write`` fill a new temporary file beside ``path``, then rename it over ``path``.

    Readers see the old file or the complete new one, never a partial one. The temporary file
    has a fresh random name (created exclusively), and the rename replaces a symbolic link at
    ``path`` rather than following it. ``sync`` flushes the file to disk before the rename
    (protection against power loss; the run's own end is covered without it)."""
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    tmp = Path(name)
    try:
        os.close(fd)
        write(tmp)
        if sync:
            with open(tmp, "rb") as handle:
                os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def make_subfolder(path: Path) -> None:
    """Create the folder ``path`` (or keep it); refuse a symbolic link in its place."""
    with contextlib.suppress(FileExistsError):
        os.mkdir(path)
    if path.is_symlink() or not path.is_dir():
        raise RunFolderError(f"{path} is a symbolic link or not a folder: not writing into it")
