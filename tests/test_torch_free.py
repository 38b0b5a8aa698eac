"""The one subprocess check of the torch-free runtime path (the import-linter contracts in
pyproject.toml check the imports statically; this checks what really runs).

In a fresh interpreter where ``import torch`` raises, every edge command runs on an ONNX model:
the Segmenter (plain and with-preprocessing graphs), depthseg-eval (with the baseline),
depthseg-tune (dry run), depthseg-bench and depthseg-replay (writing an output recording).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from onnxgen import TORCH_BLOCKER, raw_model

from edge.io import FrameWriter

REPO = Path(__file__).resolve().parents[1]


def test_edge_commands_run_where_torch_cannot_be_imported(tmp_path, linear_onnx, scene):
    rec = tmp_path / "rec.mcap"
    with FrameWriter(rec) as w:
        for i in range(6):
            d, lab = scene(i)
            w.write(1_000_000_000 + i * 50_000_000, d, lab, intrinsics=(25.0, 25.0, 15.5, 11.5))
    raw = raw_model(tmp_path / "raw.onnx", height=24, width=32)
    np.save(tmp_path / "f.npy", scene(0)[0])
    m, r, f = str(linear_onnx), str(raw), str(rec)
    code = TORCH_BLOCKER + f"""
import contextlib, io, json
import numpy as np
from edge.infer import Segmenter
from edge.eval_cli import main as eval_main
from edge.tune_cli import main as tune_main
from export.bench_cli import main as bench_main
from replay.cli import main as replay_main

d = np.load({str(tmp_path / 'f.npy')!r})
p = Segmenter({m!r}, threads=1).predict(d)
q = Segmenter({r!r}, threads=1).predict(d)
rcs = {{}}
with contextlib.redirect_stdout(io.StringIO()):
    rcs["eval"] = eval_main(["--model", {m!r}, "--data", {f!r}, "--baseline", "--json", "--threads", "1"])
    rcs["tune"] = tune_main(["--model", {m!r}, "--data", {f!r}, "--dry-run", "--json", "--threads", "1"])
    rcs["bench"] = bench_main(["--model", {m!r}, "--threads", "1", "--runs", "2", "--warmup", "1", "--json"])
    rcs["replay"] = replay_main([{f!r}, "--model", {m!r}, "--json", "--out", {str(tmp_path / 'out.mcap')!r}])
try:
    import torch  # noqa: F401
    blocked = False
except ImportError:
    blocked = True
loaded = sorted(k for k in sys.modules if k.split(".")[0] in ("torch", "torchvision"))
print(json.dumps({{"rcs": rcs, "blocked": blocked, "loaded": loaded,
                  "objects": int((p.mask == 1).sum()), "unknown": [int((p.mask == 255).sum()), int((q.mask == 255).sum())]}}))
"""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=tmp_path,
                          env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["blocked"] and out["loaded"] == []
    assert out["rcs"] == {"eval": 0, "tune": 0, "bench": 0, "replay": 0}
    invalid = int((scene(0)[0] == 0).sum())
    assert out["objects"] > 0 and out["unknown"] == [invalid, invalid]
    assert (tmp_path / "out.mcap").exists()
