"""tools/ablation/window_errors.py: error shares by rows and for a middle window fed alone."""

from __future__ import annotations

import numpy as np
from tinymodel import TINY_H, TINY_W
from toolmod import load_tool

from edge.io.writer import FrameWriter


def _write(path, n: int = 3) -> None:
    """Tables at 0.35 m with a 5 cm box, as the tiny model's frames."""
    with FrameWriter(path) as fw:
        for k in range(n):
            d = np.full((TINY_H, TINY_W), 0.35, np.float32)
            lab = np.zeros((TINY_H, TINY_W), np.uint8)
            d[10 + k : 30 + k, 20:40], lab[10 + k : 30 + k, 20:40] = 0.30, 1
            fw.write(k, d, lab)


def test_shares_are_reported_per_checkpoint_and_repeat(tmp_path, capsys, tiny_pt):
    data = tmp_path / "t.mcap"
    _write(data)
    tool = load_tool("ablation/window_errors.py")
    res = tool.window_errors(str(data), str(tiny_pt), 3, (32, 32))
    assert list(res) == ["whole frame", "first 16 rows", "rows 12-35", "last 16 rows",
                         "middle window, in the whole frame", "middle window, fed alone"]
    assert all(0.0 <= v <= 100.0 for v in res.values())
    assert res == tool.window_errors(str(data), str(tiny_pt), 3, (32, 32))  # deterministic
    assert tool.main([str(data), str(tiny_pt), "--frames", "3", "--window", "32x32"]) == 0
    out = capsys.readouterr().out
    assert f"  {'whole frame':<36} {res['whole frame']:6.2f}" in out


def test_a_window_that_does_not_fit_is_one_line_and_exit_2(tmp_path, capsys, tiny_pt):
    data = tmp_path / "t.mcap"
    _write(data, 1)
    tool = load_tool("ablation/window_errors.py")
    assert tool.main([str(data), str(tiny_pt), "--window", "64x64"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "larger than the frames" in err and "Traceback" not in err
