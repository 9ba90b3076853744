"""The cases of ``ntncontact validate``, read from the table ``data/validation_cases.toml``.

Each case is an example of the report: a scenario with overrides (friction, mass type, mesh),
or, for the mesh-motion example of section 4.2, the mesh operation itself. The table gives each
case's overrides, its ``--quick`` overrides, how it is measured (``kind``), and the tolerance of
the impact cases; the comments at its top say what each column means.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from importlib import resources
from pathlib import Path

from ..io.scenario import tomllib

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"
KINDS = ("impact", "mesh_motion", "block_sliding", "hertz", "delamination")
TABLE = "validation_cases.toml"


@dataclass(frozen=True)
class Case:
    name: str
    example: str  # scenario file in examples/ ("" for the mesh-motion example)
    overrides: tuple[str, ...] = ()
    quick: tuple[str, ...] = ()  # extra overrides for --quick
    tolerance: float = 0.05  # impact cases: relative difference allowed on checked quantities
    kind: str = "impact"
    section: str = ""  # of the report
    mesh_size: float = 0.0  # contact element size (Hertz meshes)
    cost: float = 1.0  # rough relative run time: the longest cases start first

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"case {self.name}: unknown kind {self.kind!r}, expected {KINDS}")

    @property
    def friction(self) -> float:
        return next((float(o.split("=")[1]) for o in self.overrides if "friction" in o), 0.0)


def parse_cases(text: str, source: str = TABLE) -> tuple[Case, ...]:
    """The ``[[case]]`` rows of a case table (TOML), each completed by its ``[defaults]``."""
    data = tomllib.loads(text)
    known = {f.name for f in fields(Case)}
    defaults = data.get("defaults", {})
    cases = []
    for i, row in enumerate(data.get("case", [])):
        unknown = sorted((set(row) | set(defaults)) - known)
        if unknown:
            raise ValueError(f"{source}: case {i + 1} ({row.get('name', '?')}): unknown "
                             f"column(s) {', '.join(unknown)}; expected {sorted(known)}")
        values = defaults | row
        for key in ("overrides", "quick"):
            values[key] = tuple(values.get(key, ()))
        cases.append(Case(**values))
    names = [c.name for c in cases]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise ValueError(f"{source}: case names repeat: {', '.join(repeated)}")
    return tuple(cases)


#: The cases shipped with the package (``ntncontact/data/validation_cases.toml``)
CASES: tuple[Case, ...] = parse_cases(
    (resources.files("ntncontact") / "data" / TABLE).read_text(), TABLE)



def impact_tolerance(example: str) -> float | None:
    """The relative tolerance of an example's impact cases (``example``: the scenario file's
    stem, e.g. ``ring_impact``); None if the table has no impact case of it."""
    tolerances = {c.tolerance for c in CASES
                  if c.kind == "impact" and Path(c.example).stem == example}
    if len(tolerances) > 1:
        raise ValueError(f"{TABLE}: the impact cases of {example} have different tolerances "
                         f"{sorted(tolerances)}; compare cannot choose")
    return tolerances.pop() if tolerances else None
