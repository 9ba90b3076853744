"""ntncontact: 2D finite-deformation contact and impact with the node-to-node ALE method.

The public Python API (docs/api.md): :func:`load_scenario`, :func:`scenario_from_dict`,
:func:`run`, :func:`read_results`, :func:`sweep` and the :class:`Scenario` and
:class:`Results` they pass around, and the :class:`PhysicsWarning` a run issues. Everything
else is internal.
"""

from .package import __version__, use_kernel_cache_dir
from .package import kernel_cache_dir as kernel_cache_dir  # re-exported: names the cache folder

use_kernel_cache_dir()

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
