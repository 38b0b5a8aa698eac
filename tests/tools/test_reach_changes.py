"""tools/reach_changes.py: lists exactly the frames whose support plane the reach term changes."""

from __future__ import annotations

import numpy as np
from toolmod import load_tool

from edge.io.writer import FrameWriter


def _frames() -> list[tuple[np.ndarray, np.ndarray]]:
    h, w = 64, 80
    table = np.full((h, w), 0.35, np.float32)
    label = np.zeros((h, w), np.uint8)
    table[40:60, 5:40], label[40:60, 5:40] = 0.29, 1  # a 6 cm box on the table
    edge = table.copy()
    edge[:, 48:] = 0.80  # past a table edge, the floor 45 cm lower: 40 % of the view
    edge_label = label.copy()
    return [(table, label), (edge, edge_label)]


def test_only_the_table_edge_frame_changes_and_its_score_is_given(tmp_path, capsys, linear_onnx):
    path = tmp_path / "two.mcap"
    with FrameWriter(path) as fw:
        for i, (d, lab) in enumerate(_frames()):
            fw.write(i, d, lab)
    tool = load_tool("reach_changes.py")
    assert tool.main([str(path)]) == 0
    out = capsys.readouterr().out
    assert "the plane changed on 1 of 2 frames" in out
    assert "frame 1: plane depth at the centre 0.800 -> 0.350 m" in out
    assert "frame 0" not in out
    assert tool.main([str(path), "--model", str(linear_onnx)]) == 0
    assert "; IoU " in capsys.readouterr().out
