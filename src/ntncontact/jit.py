"""The package's compiled kernels: every kernel module decorates with :func:`njit` from here.

Compiled kernels are cached on disk in :func:`ntncontact.package.kernel_cache_dir` (set up when
the package is imported). Importing this module also registers a listener on Numba's compile
events: the first time a process has to compile one of this package's kernels (an empty or
outdated cache, or a configuration whose kernels the warm-up did not compile), it says so once
on stderr, since a first run then spends up to ~40 s on it.
"""

from __future__ import annotations

import sys

import numba
import numpy as np
from numba.core import event

from .package import kernel_cache_dir

__all__ = ["njit", "COMPILE_NOTE", "read_only"]

#: Not "once": a configuration whose kernels (a branch, an argument type) the warm-up's runs
#: do not reach compiles them at its first run, a few seconds; ~40 s is an empty cache's.
COMPILE_NOTE = ("ntncontact: compiling kernels for this configuration (up to ~40 s with an empty "
                "cache; cached in {directory} for later runs)")

njit = numba.njit


def read_only(array: np.ndarray) -> np.ndarray:
    """A read-only view of ``array`` (no copy). Numba compiles a kernel once per argument
    type, and a read-only array is another type than a writable one: a caller whose arrays
    are sometimes frozen (a mesh's) and sometimes new passes them through this, so that one
    compiled form (the one the warm-up caches) serves every run."""
    view = array.view()
    view.setflags(write=False)
    return view


class _CompileNote(event.Listener):
    """Prints :data:`COMPILE_NOTE` at the first compilation of an ``ntncontact`` kernel (not
    at a kernel loaded from the cache: Numba sends no compile event then)."""

    def __init__(self) -> None:
        self.said = False

    def on_start(self, ev: event.Event) -> None:
        if self.said:
            return
        function = getattr(ev.data.get("dispatcher"), "py_func", None)
        if getattr(function, "__module__", "").startswith("ntncontact."):
            self.said = True
            print(COMPILE_NOTE.format(directory=kernel_cache_dir()), file=sys.stderr,
                  flush=True)

    def on_end(self, ev: event.Event) -> None:
        pass


NOTE = _CompileNote()
event.register("numba:compile", NOTE)
