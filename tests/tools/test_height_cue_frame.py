"""tools/height_cue_frame.py: the scan flags the frames whose plane fit took a plane below the support."""

from __future__ import annotations

import numpy as np
from toolmod import load_tool

from edge.io.writer import FrameWriter


def test_a_frame_where_the_floor_outweighs_the_table_is_flagged(tmp_path, capsys):
    h, w = 64, 80
    table = np.full((h, w), 0.30, np.float32)
    label = np.zeros((h, w), np.uint8)
    table[20:30, 30:45], label[20:30, 30:45] = 0.26, 1  # a 4 cm box on the table
    edge = table.copy()
    edge[:, 24:] = 0.60  # past a table edge: the floor, 30 cm lower, covers 70 % of the view
    edge_label = label.copy()
    edge_label[:, 24:] = 0
    path = tmp_path / "two.mcap"
    with FrameWriter(path) as fw:
        fw.write(0, table, label)
        fw.write(1, edge, edge_label)
    tool = load_tool("height_cue_frame.py")
    assert tool.main([str(path)]) == 0
    out = capsys.readouterr().out
    assert "1 of 2 frames" in out and ": 1 (" in out
    assert tool.main([str(path), "1"]) == 0
    assert "frame 1: plane fit ok=True" in capsys.readouterr().out
