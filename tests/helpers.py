"""Small builders shared by the tests."""

from __future__ import annotations

from pathlib import Path

from ntncontact.engine.builder import build_model
from ntncontact.engine.model import Model
from ntncontact.io.scenario import load_scenario, parse_scenario

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def model_from_dict(data: dict, base: Path = Path(".")) -> Model:
    return build_model(parse_scenario(data, Path("test.toml")), base)


def model_from_example(name: str, overrides: list[str] | None = None) -> Model:
    path = EXAMPLES / name
    return build_model(load_scenario(path, overrides), path.parent)


class Recorder:
    """Observer keeping every step record in memory."""

    def __init__(self) -> None:
        self.records = []
        self.status = None

    def on_step(self, model, record) -> None:
        self.records.append(record)

    def on_finish(self, status, error) -> None:
        self.status = (status, error)


def recorded_ring_impact(*overrides: str) -> Recorder:
    """The ring impact example's first 0.2 s (27 contact steps), every step recorded."""
    from ntncontact.engine.simulation import Simulation

    recorder = Recorder()
    model = model_from_example("ring_impact.toml", ["analysis.t_end=0.2", *overrides])
    Simulation(model, [recorder]).run()
    return recorder
