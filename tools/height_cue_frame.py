#!/usr/bin/env python
"""What the height cue told the model on labelled frames: which plane it took for the support.

Why: when the model calls a whole table object, the first question is whether the cue's plane
fit (`edge.cues.fit_dominant_plane`) took the floor past a table edge for the support. With a
frame index it explains that frame; without one it scans every frame and counts those where the
fit took a plane *below* the support, i.e. where more than ``--share`` of the labelled
background reads more than ``--above-cm`` above the plane (the failure of validation frame 703
before `edge.cues.REACH_M`), so one knows how often it happens before changing the rule.

    .venv/bin/python tools/height_cue_frame.py data/val4 703      # one frame
    .venv/bin/python tools/height_cue_frame.py data/test_table_edge  # how often, over a set
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from edge.cues import fit_dominant_plane, height_cue  # noqa: E402
from edge.io import open_frames  # noqa: E402
from edge.preprocess import valid_mask  # noqa: E402


def _explain(i: int, d: np.ndarray, v: np.ndarray, bg: np.ndarray) -> None:
    fit = fit_dominant_plane(d, v)
    h = height_cue(d, v)
    zp = fit.depth(d.shape)
    print(f"frame {i}: plane fit ok={fit.ok}, inlier share of the grid {fit.inlier_share:.3f}")
    print(f"  labelled background: median depth {np.median(d[bg]):.3f} m, plane depth there {np.median(zp[bg]):.3f} m,"
          f" {100 * np.mean(h[bg] > 1):.1f} % of it more than 1 cm above the plane (median {np.median(h[bg]):.1f} cm)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", help="labelled recording or directory")
    ap.add_argument("index", type=int, nargs="?",
                    help="frame index (as depthseg-eval numbers its figures); omitted: scan every frame")
    ap.add_argument("--above-cm", type=float, default=3.0,
                    help="scan: background this high above the plane counts as misread (default %(default)s)")
    ap.add_argument("--share", type=float, default=0.2,
                    help="scan: a frame is flagged when more than this share of its background is misread "
                    "(default %(default)s)")
    args = ap.parse_args(argv)
    frames, _ = open_frames(args.data, require_labels=True)
    flagged: list[tuple[int, float]] = []
    n = 0
    for i, fr in enumerate(frames):
        if args.index is not None and i < args.index:
            continue
        d = np.asarray(fr.depth)
        v = valid_mask(d)
        bg = v & ~np.asarray(fr.label).astype(bool)
        if args.index is not None:
            _explain(i, d, v, bg)
            return 0
        if not bg.any():
            continue
        n += 1
        share = float(np.mean(height_cue(d, v)[bg] > args.above_cm))
        if share > args.share:
            flagged.append((i, share))
    if args.index is not None:
        print(f"{args.data}: fewer than {args.index + 1} labelled frames", file=sys.stderr)
        return 2
    shown = ", ".join(f"{i} ({100 * s:.0f} %)" for i, s in flagged[:20]) or "none"
    print(f"{args.data}: {len(flagged)} of {n} frames with background have more than {100 * args.share:g} % of it "
          f"more than {args.above_cm:g} cm above the fitted plane: {shown}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
