#!/usr/bin/env python
"""What the height cue told the model on one labelled frame: which plane it took for the support.

Why: when the model calls a whole table object, the first question is whether the cue's plane
fit (`edge.cues.fit_dominant_plane`) took the floor past a table edge for the support.

    .venv/bin/python tools/height_cue_frame.py data/val4 703
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


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", help="labelled recording or directory")
    ap.add_argument("index", type=int, help="frame index (as depthseg-eval numbers its figures)")
    args = ap.parse_args()
    frames, _ = open_frames(args.data, require_labels=True)
    for i, fr in enumerate(frames):
        if i < args.index:
            continue
        d = np.asarray(fr.depth)
        v = valid_mask(d)
        bg = v & ~np.asarray(fr.label).astype(bool)
        fit = fit_dominant_plane(d, v)
        h = height_cue(d, v)
        zp = fit.depth(d.shape)
        print(f"frame {i}: plane fit ok={fit.ok}, inlier share of the grid {fit.inlier_share:.3f}")
        print(f"  labelled background: median depth {np.median(d[bg]):.3f} m, plane depth there {np.median(zp[bg]):.3f} m,"
              f" {100 * np.mean(h[bg] > 1):.1f} % of it more than 1 cm above the plane (median {np.median(h[bg]):.1f} cm)")
        return 0
    print(f"{args.data}: fewer than {args.index + 1} labelled frames", file=sys.stderr)
    return 2


if __name__ == "__main__":
    raise SystemExit(main())
