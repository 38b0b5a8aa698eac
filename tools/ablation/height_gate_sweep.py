#!/usr/bin/env python
"""Would a geometric gate after the model remove its halo? Mean IoU per held-out set per gate.

The gate: object pixels less than G cm above the dominant plane (the height cue,
`edge.cues.height_cue`) become background, before the speck rule. On the real capture the
model's false objects hug outlines at table height, so a robotics engineer would try this
first. Held-out simulated sets only (the README results table's); never BlenSor or real frames.
One inference per frame; every gate is scored on the same logits. Kept as the record of a
negative result (BENCHMARKS.md, v10).

    .venv/bin/python tools/ablation/height_gate_sweep.py [MODEL.onnx] [--gates-cm 0.1 0.2 0.3 0.4 0.6]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from edge.cues import height_cue  # noqa: E402
from edge.infer import Segmenter, checked_logits  # noqa: E402
from edge.io import open_frames  # noqa: E402
from edge.metrics import confusion, frame_scores, object_mask  # noqa: E402
from edge.postprocess import remove_specks  # noqa: E402
from edge.preprocess import valid_mask  # noqa: E402

SETS = ["default", "crisp", "blurred", "thin", "table_edge", "tilted", "curved", "tray", "stacked", "long"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", nargs="?", default=None, help="ONNX model (default: the shipped one)")
    ap.add_argument("--gates-cm", type=float, nargs="+", default=[0.1, 0.2, 0.3, 0.4, 0.6])
    args = ap.parse_args()
    seg = Segmenter(args.model, threads=2)
    gates = [None, *args.gates_cm]
    heads = ["no gate"] + [f"G={g:g} cm" for g in args.gates_cm]
    print(f"model {seg.name}, threshold {seg.threshold:g}, speck rule {seg.min_object_px} px; mean IoU over frames (%)")
    print("| held-out set | " + " | ".join(heads) + " |")
    print("|---|" + "---:|" * len(heads))
    means: list[list[float]] = []
    for name in SETS:
        path = ROOT / "data" / f"test_{name}"
        if not path.exists():
            print(f"| {name} | missing: simulate it with tools/results_table.py --make-data |")
            continue
        frames, _ = open_frames(path, require_labels=True)
        per: list[list[float]] = [[] for _ in gates]
        for fr in frames:
            d, lab = np.asarray(fr.depth), np.asarray(fr.label)
            valid = valid_mask(d)
            objects = object_mask(checked_logits(seg, d), valid, seg.threshold, 0)
            height = height_cue(d, valid)
            for i, g in enumerate(gates):
                m = objects if g is None else objects & (height >= g)
                s = frame_scores(confusion(remove_specks(m, seg.min_object_px), lab, valid))
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
