"""An ALE node that ends far from its partner's place is named (summary.json
``max_ale_mismatch``, ``ntncontact run``'s warning): the pair is then no longer node to node,
which nothing said before (an independent tester, session 36: a block sliding off the end of
an ALE base, whose end nodes stay fixed, left its pairs 1.85 from their ALE nodes, and a
slide over a locally respaced base 0.265, 2.1 spacings, both runs "completed" in silence;
pairs beyond the surface's end are now released, and a pair reaches 0.66 of a spacing at
the fixed end before its release).
Where the motion follows its pairs, the mismatch is round-off: the examples' largest are
2e-15 (ring impact) and 9e-10 (disk drop)."""

from __future__ import annotations

import json

import pytest
from helpers import LEDGE, run_example

from ntncontact.cli import MISMATCH_WARNING, main


def test_a_slide_past_the_ale_surfaces_end_is_named(tmp_path, capsys):
    path = tmp_path / "ledge.toml"
    path.write_text(LEDGE.format(motion="ale", t_end=0.5))
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    at = summary["max_ale_mismatch_at"]
    assert at["element_size"] == pytest.approx(0.125)
    assert summary["max_ale_mismatch"] > MISMATCH_WARNING * at["element_size"]
    err = capsys.readouterr().err
    assert "warning: an ALE contact node ended" in err and "max_ale_mismatch" in err


def test_the_examples_ale_runs_keep_no_mismatch_worth_a_warning(tmp_path, capsys):
    summary, err = run_example("disk_drop.toml", tmp_path / "disk", capsys, "analysis.t_end=0.4")
    assert summary["max_ale_mismatch"] < 1e-6 * summary["max_ale_mismatch_at"]["element_size"]
    assert "max_ale_mismatch" not in err
