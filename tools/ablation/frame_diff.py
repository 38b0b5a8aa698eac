#!/usr/bin/env python
"""Where two models' difference in mean IoU on one labelled set comes from, frame by frame.

Why: the choice rule compares means over frames, and a frame with no object pixel scores 100 or
0 (any false object pixel, even one speck over the speck rule, makes its union all false). On a
300-frame set one such frame moves the mean by 0.33 points, so a set's difference can be a few
empty frames rather than a shift of the whole set (trays between two seeds of v20's recipe,
BENCHMARKS.md "v20's recipe with `--seed 1`, results"). This splits the difference into the
frames without object pixels and the rest, and lists the frames that fell most.

    .venv/bin/python tools/ablation/frame_diff.py data/test_tray edge/models/default.onnx runs/v20s1/model.onnx
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from edge.errors import DepthsegError  # noqa: E402
from edge.infer import Segmenter  # noqa: E402
from edge.io import open_frames  # noqa: E402
from edge.metrics import confusion, frame_scores  # noqa: E402
from edge.preprocess import valid_mask  # noqa: E402


def per_frame(data: str | Path, models: list[Segmenter]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-frame IoU (%) of each model, and which frames have no object pixel.

    Args:
        data: a labelled recording (file or folder).
        models: the models to score, each at its stored threshold and speck rule.

    Returns: (frame indices, IoU array [frames, models] in %, bool array [frames]: no object pixel).
    Frames without a valid pixel are left out, as `depthseg-eval` leaves them out.
    """
    frames, _ = open_frames(data, require_labels=True)
    idx, ious, empty = [], [], []
    for i, fr in enumerate(frames):
        depth, label = np.asarray(fr.depth), np.asarray(fr.label)
        valid = valid_mask(depth)
        scores = [frame_scores(confusion(seg.predict(depth).mask == 1, label, valid)) for seg in models]
        if any(s is None for s in scores):
            continue
        idx.append(i)
        ious.append([100 * s.iou for s in scores])
        empty.append(not bool((label[valid] == 1).any()))
    return np.asarray(idx, int), np.asarray(ious, float).reshape(-1, len(models)), np.asarray(empty, bool)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("data", help="labelled recording (file or folder)")
    ap.add_argument("old", help="the reference model (ONNX)")
    ap.add_argument("new", help="the model compared with it (ONNX)")
    ap.add_argument("--top", type=int, default=8, help="list up to this many frames whose IoU fell most (default 8)")
    args = ap.parse_args(argv)
    try:
        idx, ious, empty = per_frame(args.data, [Segmenter(args.old), Segmenter(args.new)])
    except DepthsegError as exc:
        print(f"frame_diff: {exc}", file=sys.stderr)
        return 2
    n = len(idx)
    if n == 0:
        print(f"frame_diff: {args.data} has no frame with a valid pixel; nothing to compare", file=sys.stderr)
        return 2
    diff = ious[:, 1] - ious[:, 0]
    # each part's contribution to the difference of the means, so the two parts sum to the whole
    print(f"{args.data}: {n} frames; mean IoU {ious[:, 0].mean():.2f} -> {ious[:, 1].mean():.2f} ({diff.mean():+.2f})")
    print(f"  frames without object pixels: {int(empty.sum())}, right (100) {int((ious[empty, 0] == 100).sum())} -> "
          f"{int((ious[empty, 1] == 100).sum())}; their share of the difference {diff[empty].sum() / n:+.2f}")
    print(f"  the other frames: {int((~empty).sum())}, share {diff[~empty].sum() / n:+.2f}, "
          f"median change {np.median(diff[~empty]) if (~empty).any() else 0.0:+.2f}")
    for k in np.argsort(diff, kind="stable")[: args.top]:
        if diff[k] < 0:
            tag = " (no object pixel)" if empty[k] else ""
            print(f"  frame {idx[k]}: {ious[k, 0]:.1f} -> {ious[k, 1]:.1f}{tag}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
