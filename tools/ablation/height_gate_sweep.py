#!/usr/bin/env python
"""Would a geometric gate after the model remove its halo? Mean IoU per held-out set per gate.

The gate: object pixels less than G cm above the dominant plane (the height cue,
`edge.cues.height_cue`) become background, before the speck rule. On the real capture the
model's false objects hug outlines at table height, so a robotics engineer would try this
first. Held-out simulated sets only (`heldout.HELD_OUT`, the README results table's); never
BlenSor or real frames. One inference per frame; every gate is scored on the same logits. Kept
as the record of a negative result (BENCHMARKS.md, v10).

    .venv/bin/python tools/ablation/height_gate_sweep.py [MODEL.onnx] [--gates-cm 0.1 0.2 0.3 0.4 0.6]
"""

from __future__ import annotations

import argparse

from heldout import sweep

from edge.cues import height_cue
from edge.infer import Segmenter
from edge.metrics import object_mask
from edge.postprocess import remove_specks


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", nargs="?", default=None, help="ONNX model (default: the shipped one)")
    ap.add_argument("--gates-cm", type=float, nargs="+", default=[0.1, 0.2, 0.3, 0.4, 0.6])
    args = ap.parse_args()
    seg = Segmenter(args.model, threads=2)
    print(f"model {seg.name}, threshold {seg.threshold:g}, speck rule {seg.min_object_px} px; mean IoU over frames (%)")

    def gate(g: float | None):
        def mask(logits, valid, depth):
            objects = object_mask(logits, valid, seg.threshold, 0)
            if g is not None:
                objects = objects & (height_cue(depth, valid) >= g)
            return remove_specks(objects, seg.min_object_px)
        return mask

    gates = [None, *args.gates_cm]
    return sweep(seg, ["no gate"] + [f"G={g:g} cm" for g in args.gates_cm], [gate(g) for g in gates])


if __name__ == "__main__":
    raise SystemExit(main())
