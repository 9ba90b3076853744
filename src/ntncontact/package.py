"""What every layer may read of the package itself: its version and the folder its compiled
kernels are cached in. It imports nothing of the package, so that the package's ``__init__``
(which re-exports the public API, the top layer) is imported by no module below it."""

import os
import sys
from pathlib import Path

import platformdirs

__version__ = "0.1.0"


def kernel_cache_dir() -> Path:
    """Where the compiled (Numba) kernels are cached: ``NUMBA_CACHE_DIR`` if the user set it,
    else the user's cache folder (``~/.cache/ntncontact/numba`` on Linux). One place for every
    entry point (make, the ``ntncontact`` command, Python, pytest), so that kernels compiled
    once are found by all of them; never inside the source tree."""
    chosen = os.environ.get("NUMBA_CACHE_DIR")
    return Path(chosen) if chosen else platformdirs.user_cache_path("ntncontact") / "numba"


def use_kernel_cache_dir() -> None:
    """Set ``NUMBA_CACHE_DIR`` before the kernel modules are decorated. Numba reads it when it
    is imported; if something imported numba before this package, its configuration is read
    again (the caching decorators look at it when applied)."""
    os.environ.setdefault("NUMBA_CACHE_DIR", str(kernel_cache_dir()))
    config = sys.modules.get("numba.core.config")
    if config is not None:
        config.reload_config()
