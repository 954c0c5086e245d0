"""scripts/probe_inputs.py, the corpus of malformed inputs behind the reliability figures: it
runs, and its first inputs (an alias bomb, a key written twice, a recursive alias) each stop
with one clean line."""

import re

import pytest

from .helpers import load_file_module


@pytest.mark.slow
def test_the_probe_runs_three_inputs_and_counts_them_clean(capsys):
    probe = load_file_module("scripts/probe_inputs.py")
    assert len(probe.CASES) >= 100
    assert len({(c.category, c.name) for c in probe.CASES}) == len(probe.CASES)
    assert probe.main(["--only", "3"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"^category +inputs +clean +unclear +hung +crashed +exit 0 +other$", out, re.M)
    assert re.search(r"^total +3 +3 +0 +0 +0 +0 +0$", out, re.M), out
