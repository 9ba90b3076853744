"""ntncontact: 2D finite-deformation contact and impact with the node-to-node ALE method.

The public Python API (docs/api.md): :func:`load_scenario`, :func:`scenario_from_dict`,
:func:`run`, :func:`read_results`, :func:`sweep` and the :class:`Scenario` and
:class:`Results` they pass around, and the :class:`PhysicsWarning` a run issues. Everything
else is internal.
"""

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


def _use_kernel_cache_dir() -> None:
    """Set ``NUMBA_CACHE_DIR`` before the kernel modules are decorated. Numba reads it when it
    is imported; if something imported numba before this package, its configuration is read
    again (the caching decorators look at it when applied)."""
    os.environ.setdefault("NUMBA_CACHE_DIR", str(kernel_cache_dir()))
    config = sys.modules.get("numba.core.config")
    if config is not None:
        config.reload_config()


_use_kernel_cache_dir()

# the public API, after the kernel cache is set up (the kernel modules are imported by it)
from .api import (  # noqa: E402
    PhysicsWarning,
    Results,
    Scenario,
    load_scenario,
    read_results,
    run,
    scenario_from_dict,
)
from .studies.sweep import sweep  # noqa: E402

__all__ = ["PhysicsWarning", "Results", "Scenario", "load_scenario", "read_results", "run",
           "scenario_from_dict", "sweep", "__version__"]
