"""tools/ablation/eval_ablation.py: the rule a new default is chosen by, on made-up set scores."""

from __future__ import annotations

import pytest
from toolmod import load_tool


@pytest.fixture(scope="module")
def ea():
    return load_tool("ablation/eval_ablation.py")  # imports its neighbour heldout.py: load_tool allows it


def test_a_lead_inside_seed_noise_does_not_replace_the_default(ea):
    old = [97.0] * 10
    assert "does not replace" in ea.verdict("old", old, "new", [97.05] * 10)  # +0.05, v10's seed spread
    assert "mean +0.10" in ea.verdict("old", old, "new", [97.1] * 10)
    assert "does not replace" not in ea.verdict("old", old, "new", [97.1] * 10)


def test_one_set_falling_more_than_a_point_vetoes_any_gain(ea):
    old = [97.0] * 10
    new = [99.0] * 9 + [95.9]  # mean +1.69, one set -1.1
    v = ea.verdict("old", old, "new", new)
    assert "largest change on one set -1.10" in v and "does not replace" in v
    assert "does not replace" not in ea.verdict("old", old, "new", [99.0] * 9 + [96.0])  # exactly -1.0 passes
