"""Every scenario shown in the user guide builds and runs, and says what the text claims."""

import re
from pathlib import Path

import numpy as np
import pytest
from helpers import Recorder

from ntncontact.engine.builder import build_model
from ntncontact.engine.simulation import Simulation
from ntncontact.io.scenario import parse_scenario

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover
    import tomli as tomllib

DOCS = Path(__file__).resolve().parents[1] / "docs"


def tutorial_scenarios():
    text = (DOCS / "tutorial.md").read_text()
    return [tomllib.loads(block) for block in re.findall(r"```toml\n(.*?)```", text, re.S)]


def run(data):
    rec = Recorder()
    Simulation(build_model(parse_scenario(data, Path("tutorial.toml")), DOCS), [rec]).run()
    assert rec.status == ("completed", None)
    return rec.records[-1].extra["contact_rows"]


def test_tutorial_has_four_steps():
    assert len(tutorial_scenarios()) == 4


def test_tutorial_dynamic_step_is_the_disk_drop_example():
    """Step 4 is examples/disk_drop.toml word for word (tests/test_disk_drop.py runs it)."""
    example = Path(__file__).resolve().parents[1] / "examples" / "disk_drop.toml"
    assert tutorial_scenarios()[3] == tomllib.loads(example.read_text())
    text = (DOCS / "tutorial.md").read_text()
    assert example.read_text() in text


@pytest.mark.parametrize("step", [0, 2])
def test_tutorial_blocks_carry_the_applied_pressure(step):
    rows = run(tutorial_scenarios()[step])
    np.testing.assert_allclose(rows["normal_traction"], 2.0, rtol=1e-6)
    assert np.abs(rows["gap"]).max() < 1e-9


def test_tutorial_friction_step_sticks_and_slips():
    rows = run(tutorial_scenarios()[1])
    assert set(rows["status"]) == {"stick", "slip"}
