"""The ALE mismatch warning's first advice is ale.max_stretch (tester O finding 4): a block
sliding 1.1 on a 3-long ALE base left pairs 11 spacings apart from 0.43 of slide on, because
the base's nodes could not leave its fixed trailing end further behind; max_stretch = 4
removed it. The advice began with "an ALE surface longer than the slide", which it was."""

from ntncontact.report.run_warnings import result_warnings


def test_the_mismatch_advice_names_max_stretch_first():
    summary = {"max_ale_mismatch": 0.543,
               "max_ale_mismatch_at": {"time": 0.24, "element_size": 0.05}}
    [line] = [w for w in result_warnings(summary, static=False) if "ALE contact node" in w]
    advice = line.split("no longer node to node. ", 1)[1]
    assert advice.startswith("A larger ale.max_stretch")
    assert "slide away from an end" in advice and "surface longer than the slide" in advice
