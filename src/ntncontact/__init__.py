"""ntncontact: 2D finite-deformation contact and impact with the node-to-node ALE method.

The public Python API (docs/api.md): :func:`load_scenario`, :func:`scenario_from_dict`,
:func:`run`, :func:`read_results`, :func:`sweep` and the :class:`Scenario` and
:class:`Results` they pass around. Everything else is internal.
"""

__version__ = "0.1.0"

from .api import Results, Scenario, load_scenario, read_results, run, scenario_from_dict  # noqa: E402
from .studies.sweep import sweep  # noqa: E402

__all__ = ["Results", "Scenario", "load_scenario", "read_results", "run", "scenario_from_dict",
           "sweep", "__version__"]
