"""tools/ablation/frame_diff.py: splits a mean-IoU difference into empty frames and the rest."""

from __future__ import annotations

import numpy as np
from onnxgen import raw_model
from toolmod import load_tool

from edge.io.writer import FrameWriter

H, W = 171, 224


def _write(path) -> None:
    """Frame 0: a 6 cm box on a table at 0.35 m; frame 1: the same table, empty."""
    table = np.full((H, W), 0.35, np.float32)
    box, box_label = table.copy(), np.zeros((H, W), np.uint8)
    box[60:110, 80:150], box_label[60:110, 80:150] = 0.29, 1
    with FrameWriter(path) as fw:
        fw.write(0, box, box_label)
        fw.write(1, table, np.zeros((H, W), np.uint8))


def test_an_empty_frame_turned_wrong_carries_its_share_of_the_difference(tmp_path, capsys):
    data = tmp_path / "two.mcap"
    _write(data)
    right = raw_model(tmp_path / "right.onnx", cut=0.32)  # object below 0.32 m: the box only
    wrong = raw_model(tmp_path / "wrong.onnx", cut=0.36)  # below 0.36 m: the whole table too
    tool = load_tool("ablation/frame_diff.py")
    assert tool.main([str(data), str(right), str(wrong)]) == 0
    out = capsys.readouterr().out
    box_iou = 100 * 50 * 70 / (H * W)  # the wrong model's union is the whole frame
    assert f"2 frames; mean IoU 100.00 -> {box_iou / 2:.2f} ({box_iou / 2 - 100:+.2f})" in out
    assert "frames without object pixels: 1, right (100) 1 -> 0; their share of the difference -50.00" in out
    assert f"the other frames: 1, share {(box_iou - 100) / 2:+.2f}" in out
    assert "frame 1: 100.0 -> 0.0 (no object pixel)" in out


def test_an_unreadable_recording_is_one_line_and_exit_2(tmp_path, capsys, linear_onnx):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file")
    tool = load_tool("ablation/frame_diff.py")
    assert tool.main([str(bad), str(linear_onnx), str(linear_onnx)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("frame_diff: ") and "\n" not in err
