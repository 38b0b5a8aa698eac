"""tools/false_object_heights.py: false-object pixels near and away from outlines, split by height above the table."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from toolmod import load_tool

from edge.errors import ConfigError
from edge.io.writer import FrameWriter


class _FixedMask:
    """A stand-in for `Segmenter`: the mask it is given, whatever the depth."""

    def __init__(self, mask: np.ndarray) -> None:
        self.mask = mask

    def predict(self, depth: np.ndarray) -> SimpleNamespace:
        return SimpleNamespace(mask=self.mask)


def test_a_raised_rim_and_a_table_level_rim_are_told_apart(tmp_path):
    h, w = 60, 80
    depth = np.full((h, w), 0.30, np.float32)  # a flat table 30 cm below the camera
    label = np.zeros((h, w), np.uint8)
    depth[20:40, 30:50], label[20:40, 30:50] = 0.25, 1  # a 5 cm box
    depth[20:40, 29] = 0.295  # left of it a 1 px rim 5 mm up (an object's base, under a 10 mm rule)
    mask = label.copy()
    mask[20:40, 29] = 1  # the model calls both rims object
    mask[20:40, 50] = 1  # right of the box: at table level (a blur halo)
    mask[5, 5] = 1  # and one speck far from any outline
    mask[20, 30:50] = 0  # the box's top row missed: 50 mm up, not at table level
    path = tmp_path / "f.mcap"
    with FrameWriter(path) as fw:
        fw.write(0, depth, label, (60.0, 60.0, 40.0, 30.0))
    tool = load_tool("false_object_heights.py")
    r = tool.height_split(path, _FixedMask(mask))
    union = 400 + 20 + 20 + 1  # the missed row stays in the union (label 1)
    assert r["frames"] == 1 and r["union"] == union
    # the labeller's 3 x 3 median puts the rim's two end pixels (5 table pixels around each) at table level
    assert r["fp_near_raised_under_rule"] == pytest.approx(100 * 18 / union)
    assert r["fp_near_table_level"] == pytest.approx(100 * 22 / union)
    assert r["fp_near_over_rule"] == 0.0 and r["fp_far"] == pytest.approx(100 / union)
    assert r["fp_near"] == pytest.approx(r["fp_near_table_level"] + r["fp_near_raised_under_rule"])
    # the far speck lies on the flat table, so all of the far share is at table level
    assert r["fp_far_table_level"] == r["fp_far"] and r["fp_far_raised_under_rule"] == r["fp_far_over_rule"] == 0.0
    # of the missed row only the corner beside the table-level rim reads table level through the median
    assert r["fn_near"] == pytest.approx(100 * 20 / union) and r["fn_near_table_level"] == pytest.approx(100 / union)


def test_the_split_needs_the_table_level_below_the_rule(tmp_path):
    with pytest.raises(ConfigError, match="below the rule's line"):
        load_tool("false_object_heights.py").height_split(tmp_path / "none.mcap", None, low_m=0.01, rule_m=0.01)


def test_the_ceiling_makes_the_labels_table_level_object_pixels_table(tmp_path):
    h, w = 60, 80
    depth = np.full((h, w), 0.30, np.float32)
    label = np.zeros((h, w), np.uint8)
    depth[20:40, 30:50], label[20:40, 30:50] = 0.25, 1  # a 5 cm box
    label[20:40, 50] = 1  # its right outline: labelled object, but the range reads the table (a mixed pixel)
    path = tmp_path / "f.mcap"
    with FrameWriter(path) as fw:
        fw.write(0, depth, label, (60.0, 60.0, 40.0, 30.0))
    r = load_tool("false_object_heights.py").height_split(path, _FixedMask(label))
    # the 20 table-level outline pixels go, and the box's 4 corners, which the labeller's 3 x 3
    # median puts at table level (5 of their 9 neighbours are table); nothing else
    assert r["ceiling_iou"] == pytest.approx(100 * (420 - 24) / 420)
    assert r["ceiling_pooled_iou"] == pytest.approx(r["ceiling_iou"])
    assert r["fp_near"] == r["fn_near"] == 0.0  # the model here is the labels: the ceiling is not its score
