#!/usr/bin/env python
"""Choose the speck rule's size on held-out simulated sets: mean IoU per set for several sizes.

The speck rule (`edge.postprocess`): after the threshold, object components (8-connected) under
``min_object_px`` pixels become background. One inference per frame; every size is scored on
the same logits. Held-out simulated sets only (`heldout.HELD_OUT`, the README results table's);
never the BlenSor or real frames.

    .venv/bin/python tools/ablation/speck_sweep.py [MODEL.onnx] [--sizes 0 2 3 4 6 8 12 16]
"""

from __future__ import annotations

import argparse

from heldout import sweep

from edge.infer import Segmenter
from edge.metrics import object_mask


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", nargs="?", default=None, help="ONNX model (default: the shipped one)")
    ap.add_argument("--sizes", type=int, nargs="+", default=[0, 2, 3, 4, 6, 8, 12, 16])
    args = ap.parse_args()
    seg = Segmenter(args.model, threads=2)
    print(f"model {seg.name}, threshold {seg.threshold:g}; mean IoU over frames (%) with object specks "
          "under N px removed")

    def size(k: int):
        return lambda logits, valid, _depth: object_mask(logits, valid, seg.threshold, k)

    return sweep(seg, [f"N={k}" for k in args.sizes], [size(k) for k in args.sizes])


if __name__ == "__main__":
    raise SystemExit(main())
