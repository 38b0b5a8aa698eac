"""tools/phantom_objects.py: phantom objects on the empty frames of a set, by support kind."""

from __future__ import annotations

import numpy as np
from tinymodel import TINY_H, TINY_W
from toolmod import load_tool

from edge.io.writer import FrameWriter


def _scene(kind: str) -> dict:
    sup = {"table": {}, "tray": {"tray": {"inner_m": 0.2}}, "edge": {"table_edge": {"dist_m": 0.1}}}[kind]
    return {"index": 0, "params": {"support": {"tray": None, "table_edge": None} | sup}}


def _write(path) -> None:
    """Two flat empty tables, an empty tray whose 2 cm rim the plane fit calls object, one box (skipped)."""
    with FrameWriter(path) as fw:
        flat = np.full((TINY_H, TINY_W), 0.35, np.float32)
        empty = np.zeros((TINY_H, TINY_W), np.uint8)
        fw.write(0, flat, empty, scene=_scene("table"))
        fw.write(1, flat, empty, scene=_scene("edge"))
        tray = flat.copy()
        tray[5:8, 5:60] = 0.33
        fw.write(2, tray, empty, scene=_scene("tray"))
        box, lab = flat.copy(), empty.copy()
        box[10:30, 20:40], lab[10:30, 20:40] = 0.30, 1
        fw.write(3, box, lab, scene=_scene("table"))


def test_counts_by_support_and_method(tmp_path, capsys, tiny_onnx):
    data = tmp_path / "e.mcap"
    _write(data)
    tool = load_tool("phantom_objects.py")
    res = tool.phantoms(data, [tiny_onnx])
    assert list(res) == [str(tiny_onnx), "plane fit", "plane fit + specks"]
    plane = res["plane fit"]
    assert list(plane) == ["table", "table edge", "tray", "all"]
    assert [plane[k]["frames"] for k in plane] == [1, 1, 1, 3]  # the frame with a box is not empty: skipped
    assert plane["table"]["with_phantom"] == plane["table edge"]["with_phantom"] == 0
    assert plane["tray"]["with_phantom"] == 1
    assert 3 * 55 - 8 <= plane["tray"]["median_px"] <= 3 * 55  # the rim, 2 cm up (the 3 x 3 median rounds its corners)
    model = res[str(tiny_onnx)]
    assert model["all"]["with_phantom"] == sum(model[k]["with_phantom"] for k in ("table", "table edge", "tray"))
    assert res == tool.phantoms(data, [tiny_onnx])  # deterministic
    assert tool.main([str(data), "--model", str(tiny_onnx)]) == 0
    assert "| tray | 1 |" in capsys.readouterr().out


def test_a_set_without_empty_frames_is_one_line_and_exit_2(tmp_path, capsys, tiny_onnx):
    data = tmp_path / "b.mcap"
    with FrameWriter(data) as fw:
        d, lab = np.full((TINY_H, TINY_W), 0.35, np.float32), np.zeros((TINY_H, TINY_W), np.uint8)
        d[10:30, 20:40], lab[10:30, 20:40] = 0.30, 1
        fw.write(0, d, lab)
    assert load_tool("phantom_objects.py").main([str(data), "--model", str(tiny_onnx)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "no labelled frame without objects" in err and "Traceback" not in err
