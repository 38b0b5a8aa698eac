"""tools/preprocess_once_bench.py: both preprocessing modes run the whole training command, alternating."""

from __future__ import annotations

import numpy as np
from toolmod import load_tool


def _tiny_set(d) -> None:
    from edge.io import FrameWriter

    d.mkdir()
    rng = np.random.default_rng(0)
    with FrameWriter(d / "a.mcap") as w:
        for i in range(20):
            depth = (0.3 + rng.normal(0, 0.001, (40, 56))).astype(np.float32)
            label = np.zeros((40, 56), np.uint8)
            depth[10:20, 10:20] -= 0.05
            label[10:20, 10:20] = 1
            w.write(i * 1000, depth, label)


def test_both_modes_are_run_and_reported_with_their_ratio(tmp_path, capsys):
    mod = load_tool("preprocess_once_bench.py")
    _tiny_set(tmp_path / "d")
    argv = ["--data", str(tmp_path / "d"), "--frames", "20", "--epochs", "1", "--repeats", "1", "--warmup", "0",
            "--threads", "1"]
    assert mod.main(argv) == 0
    out = capsys.readouterr().out
    rows = {line.split()[0]: line.split() for line in out.splitlines() if line.startswith(("per-batch", "once"))}
    assert set(rows) == {"per-batch", "once"}
    assert all(float(r[1]) > 0 and float(r[2]) >= 0 for r in rows.values())  # epochs: log.csv rounds to 0.1 s
    assert "ratio once / per-batch: whole run x" in out and "1 runs of each mode" in out


def test_missing_data_is_one_line_and_exit_2(tmp_path, capsys):
    mod = load_tool("preprocess_once_bench.py")
    assert mod.main(["--data", str(tmp_path / "absent")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "depthseg-sim --out" in err
