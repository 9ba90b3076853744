"""The package's compiled kernels: every kernel module decorates with :func:`njit` from here.

Compiled kernels are cached on disk in :func:`ntncontact.kernel_cache_dir` (set up when the
package is imported). Importing this module also registers a listener on Numba's compile
events: the first time a process has to compile one of this package's kernels (an empty or
outdated cache), it says so once on stderr, since a first run then spends ~40 s on it.
"""

from __future__ import annotations

import sys

import numba
from numba.core import event

from . import kernel_cache_dir

__all__ = ["njit", "COMPILE_NOTE"]

COMPILE_NOTE = "ntncontact: compiling kernels once, ~40 s (cached in {directory})"

njit = numba.njit


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
