"""tools/edge_path_digest.py: the same code gives the same digests; one changed value is reported."""

from __future__ import annotations

import json

import numpy as np
from toolmod import load_tool

from edge.io.writer import FrameWriter


def test_digests_match_themselves_and_a_changed_one_fails(tmp_path, capsys):
    rng = np.random.default_rng(3)
    path = tmp_path / "frames.mcap"
    with FrameWriter(path) as fw:
        for k in range(3):
            z = np.full((171, 224), 0.32, np.float32) + rng.normal(0, 0.002, (171, 224)).astype(np.float32)
            label = np.zeros((171, 224), np.uint8)
            z[40:90, 50:120], label[40:90, 50:120] = 0.28, 1
            fw.write(k, z, label)
    tool = load_tool("edge_path_digest.py")
    out = tmp_path / "d.json"
    assert tool.main(["--data", str(path), "--out", str(out)]) == 0
    got = json.loads(out.read_text())
    # 3 frames x 4 variants x (valid, plane, x, stats, 3 masks)
    assert len(got) == 3 * 4 * 7 and all(k.startswith(f"{path}:") for k in got)
    assert tool.main(["--data", str(path), "--compare", str(out)]) == 0
    assert "0 differ" in capsys.readouterr().out
    key = sorted(got)[5]
    got[key] = "0" * 16
    out.write_text(json.dumps(got))
    assert tool.main(["--data", str(path), "--compare", str(out)]) == 1
    printed = capsys.readouterr().out
    assert "1 differ" in printed and key in printed
