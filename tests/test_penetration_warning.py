"""A pair that goes deep into its partner surface is named (an independent user's check,
session 35): the disk drop with a disk four times finer than the ALE block under it (n_circ 64
against the example's 32): node-to-node pairs hold the block's nodes, the disk's pairs went
0.014 deep, 29 % of the disk's surface spacing, where the example's own run goes 0.2 %; the
run completed without a word. summary.json now says where (``max_penetration_at``) and
``ntncontact run`` warns above PENETRATION_WARNING of the spacing."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import run_example

from ntncontact.report.run_warnings import PENETRATION_WARNING


def _run(tmp_path: Path, capsys, *sets: str) -> tuple[dict, str]:
    return run_example("disk_drop.toml", tmp_path / "out", capsys, "analysis.t_end=0.1", *sets)


def test_a_deep_pair_is_located_and_warned(tmp_path, capsys):
    summary, err = _run(tmp_path, capsys, "bodies.0.mesh.n_circ=64", "bodies.0.mesh.n_radial=5")
    at = summary["max_penetration_at"]
    assert at["depth"] == pytest.approx(summary["max_penetration"], rel=0, abs=0)
    assert at["interface"] == "disk_block"
    assert at["depth"] > PENETRATION_WARNING * at["element_size"]
    # the smaller spacing is the disk's: 2 pi 0.5 / 64
    assert at["element_size"] == pytest.approx(2 * 3.141592653589793 * 0.5 / 64, rel=0.01)
    assert f"node {at['node']} of interface 'disk_block'" in err and "max_penetration_at" in err


def test_the_example_stays_shallow_and_nothing_is_said(tmp_path, capsys):
    summary, err = _run(tmp_path, capsys)
    at = summary["max_penetration_at"]
    assert 0.0 < at["depth"] < 0.01 * at["element_size"]
    assert "warning" not in err
