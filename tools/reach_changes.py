#!/usr/bin/env python
"""Which frames' support plane the reach term of the height cue's rule changes, and what it does there.

Why: `edge.cues.REACH_M` (points far in front of a plane count against it, points far behind it
do not) changed the plane the height cue measures from. A model trained before it sees its old
input wherever the plane is unchanged, so this tool fits every frame under both rules (the old
one is the same code with an unlimited reach) and lists the frames whose plane differs, exactly;
with ``--model`` it also scores the model on those frames under both rules (IoU in % of frame).

    .venv/bin/python tools/reach_changes.py data/val4 data/test_table_edge data/blensor.mcap
    .venv/bin/python tools/reach_changes.py data/val4 --model edge/models/default.onnx
"""

from __future__ import annotations

import argparse
import sys
from contextlib import contextmanager
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from edge import cues  # noqa: E402
from edge.io import open_frames  # noqa: E402
from edge.meta import SensorSpec  # noqa: E402
from edge.metrics import confusion, frame_scores  # noqa: E402
from edge.preprocess import valid_mask  # noqa: E402


@contextmanager
def _unlimited_reach():
    kept = cues.REACH_M
    cues.REACH_M = float("inf")
    try:
        yield
    finally:
        cues.REACH_M = kept


def _frame_iou(seg, depth, label) -> float:
    """IoU in % of one frame, scored as depthseg-eval scores (`valid_mask`: its labels decide what counts)."""
    return 100.0 * frame_scores(confusion(seg.predict(depth).mask == 1, label, valid_mask(depth))).iou


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="+", help="recordings (MCAP files or folders)")
    ap.add_argument("--model", help="also score this model on the changed frames, before and after")
    args = ap.parse_args(argv)
    seg = None
    if args.model:
        from edge.infer import Segmenter

        seg = Segmenter(args.model)
    for src in args.data:
        frames, _ = open_frames(src)
        n, changed = 0, []
        for i, f in enumerate(frames):
            n += 1
            d = f.depth
            v = valid_mask(d, SensorSpec().max_range_m)  # what a pico flexx model reads as returns
            new = cues.fit_dominant_plane(d, v)
            with _unlimited_reach():
                old = cues.fit_dominant_plane(d, v)
            if (old.a, old.b, old.c) == (new.a, new.b, new.c):
                continue
            centre = (d.shape[0] // 2, d.shape[1] // 2)
            line = f"  frame {i}: plane depth at the centre {old.depth(d.shape)[centre]:.3f} -> {new.depth(d.shape)[centre]:.3f} m"
            if seg is not None and f.label is not None:
                after = _frame_iou(seg, d, f.label)
                with _unlimited_reach():
                    before = _frame_iou(seg, d, f.label)
                line += f"; IoU {before:.2f} -> {after:.2f}"
            changed.append(line)
        print(f"{src}: the plane changed on {len(changed)} of {n} frames")
        for line in changed:
            print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
