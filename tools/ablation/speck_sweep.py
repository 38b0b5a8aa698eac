#!/usr/bin/env python
"""Choose the speck rule's size on held-out simulated sets: mean IoU per set for several sizes.

The speck rule (`edge.postprocess`): after the threshold, object components (8-connected) under
``min_object_px`` pixels become background. One inference per frame; every size is scored on
the same logits. Held-out simulated sets only (the README results table's); never the BlenSor
or real frames.

    .venv/bin/python tools/ablation/speck_sweep.py [MODEL.onnx] [--sizes 0 2 3 4 6 8 12 16]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from edge.infer import Segmenter, checked_logits  # noqa: E402
from edge.io import open_frames  # noqa: E402
from edge.metrics import confusion, frame_scores, object_mask  # noqa: E402
from edge.preprocess import valid_mask  # noqa: E402

SETS = ["default", "crisp", "blurred", "thin", "table_edge", "tilted", "curved", "tray", "stacked", "long"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", nargs="?", default=None, help="ONNX model (default: the shipped one)")
    ap.add_argument("--sizes", type=int, nargs="+", default=[0, 2, 3, 4, 6, 8, 12, 16])
    args = ap.parse_args()
    seg = Segmenter(args.model, threads=2)
    print(f"model {seg.name}, threshold {seg.threshold:g}; mean IoU over frames (%) with object specks "
          "under N px removed")
    print("| held-out set | " + " | ".join(f"N={k}" for k in args.sizes) + " |")
    print("|---|" + "---:|" * len(args.sizes))
    means: list[list[float]] = []
    for name in SETS:
        path = ROOT / "data" / f"test_{name}"
        if not path.exists():
            print(f"| {name} | missing: simulate it with tools/results_table.py --make-data |")
            continue
        frames, _ = open_frames(path, require_labels=True)
        per: list[list[float]] = [[] for _ in args.sizes]
        for fr in frames:
            d, lab = np.asarray(fr.depth), np.asarray(fr.label)
            valid = valid_mask(d)
            logits = checked_logits(seg, d)
            for i, k in enumerate(args.sizes):
                s = frame_scores(confusion(object_mask(logits, valid, seg.threshold, k), lab, valid))
                if s is not None:
                    per[i].append(s.iou)
        row = [100 * float(np.mean(p)) for p in per]
        means.append(row)
        print(f"| {name} | " + " | ".join(f"{v:.2f}" for v in row) + " |", flush=True)
    if means:
        col = np.mean(np.asarray(means), axis=0)
        print(f"| mean of {len(means)} sets | " + " | ".join(f"{v:.2f}" for v in col) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
