#!/usr/bin/env python
"""Score the ablation rows (tools/ablation/run_ablation.sh) on held-out simulated sets only.

Model choice is made on simulated frames never used in training (seed 2 and 4 test sets, the
seed 3 validation mix), never on the shared BlenSor or real frames. Prints a markdown table.

    .venv/bin/python tools/ablation/eval_ablation.py [MODEL.onnx ...]
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SETS = [("own sim", "data/test_default"), ("crisp edges", "data/test_crisp"), ("blurred edges", "data/test_blurred"),
        ("v3 mix (val, seed 3)", "data/val4")]
ROWS = [("z + height, x0.125, new edges", "runs/ablation/zh_w125/model.onnx"),
        ("z only, x0.125, new edges", "runs/ablation/z_w125/model.onnx"),
        ("z + height, x0.125, old blurred edges", "runs/ablation/zh_w125_blur/model.onnx"),
        ("z + height, x0.25, new edges", "runs/ablation/zh_w25/model.onnx")]


def score(model: str, data: str) -> dict:
    cmd = [str(ROOT / ".venv/bin/depthseg-eval"), "--model", model, "--data", data, "--json", "--limit", "300",
           "--threshold", "0.5"]
    out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=True).stdout
    return json.loads(out)


def main() -> int:
    rows = [(m, m) for m in sys.argv[1:]] or ROWS
    print("| input, width, training edges | " + " | ".join(f"{n} IoU" for n, _ in SETS) + " | FP near (own sim) |")
    print("|---|" + "---:|" * (len(SETS) + 1))
    for name, model in rows:
        if not (ROOT / model).exists():
            print(f"| {name} | " + " | ".join("-" for _ in SETS) + " | - |  (missing: {model})")
            continue
        res = [score(model, d) for _, d in SETS]
        print(f"| {name} | " + " | ".join(f"{100 * r['iou']:.2f}" for r in res)
              + f" | {100 * res[0]['breakdown']['fp_boundary']:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
