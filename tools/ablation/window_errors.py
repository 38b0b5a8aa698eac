#!/usr/bin/env python
"""Where in the frame a checkpoint errs, and how much it leans on seeing the whole frame.

Why: training on windows (`depthseg-train --crop`) first cut them from the unpadded frame, and
that model erred far more next to the zero band that pads 171 rows to 192 at inference
(BENCHMARKS.md "candidate C, stopped"). This prints, per checkpoint, the share of valid pixels
that are wrong in the whole frame, in its first and last 16 rows and in its middle half of
rows; then the middle window fed alone against the same pixels in the whole frame, which shows
how much a model needs the frame's layout (a whole-frame model erred several times as often on a
window fed alone).

    .venv/bin/python tools/ablation/window_errors.py data/test_default edge/models/default.pt runs/c128/best.pt
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from edge.errors import DepthsegError  # noqa: E402

BAND = 16  # rows at the top and the bottom of the frame


def _share(err: np.ndarray, valid: np.ndarray) -> float:
    """Wrong pixels in % of the valid ones (nan without valid pixels)."""
    n = valid.sum()
    return float(100 * err.sum() / n) if n else float("nan")


def window_errors(data: str, checkpoint: str, frames: int, window: tuple[int, int]) -> dict[str, float]:
    """Error shares (% of valid pixels) of one checkpoint on the first ``frames`` frames of ``data``.

    Args:
        data: labelled recording (file or folder).
        checkpoint: a depthseg `.pt` checkpoint.
        frames: how many frames to read.
        window: (height, width) of the middle window fed alone, multiples of the model's stride.
    """
    import torch

    from edge.train.checkpoint import checkpoint_meta, read_checkpoint
    from edge.train.data import check_crop, load_frames, make_batch, prepare_frames
    from edge.train.model import build_model

    blob = read_checkpoint(checkpoint)
    meta = checkpoint_meta(checkpoint, blob)
    model = build_model(meta)
    model.load_state_dict(blob["state_dict"])
    model.eval()
    fs = load_frames([data], limit=frames)
    h, w = fs.label.shape[1:]
    check_crop(window, (h, w), meta.pad_multiple)
    x, t, m = make_batch(prepare_frames(fs, meta), np.arange(len(fs)), meta)
    top, left = (h - window[0]) // 2, (w - window[1]) // 2
    rows, cols = slice(top, top + window[0]), slice(left, left + window[1])
    xw = np.ascontiguousarray(x[:, :, rows, cols])
    with torch.no_grad():
        whole = np.concatenate([model(torch.from_numpy(x[i : i + 16])).numpy() for i in range(0, len(x), 16)])
        alone = np.concatenate([model(torch.from_numpy(xw[i : i + 16])).numpy() for i in range(0, len(xw), 16)])
    label, valid = t > 0.5, m > 0
    err = ((whole > 0) != label) & valid
    mid = slice(h // 4, 3 * h // 4)
    return {
        "whole frame": _share(err, valid),
        f"first {BAND} rows": _share(err[..., :BAND, :], valid[..., :BAND, :]),
        f"rows {mid.start}-{mid.stop - 1}": _share(err[..., mid, :], valid[..., mid, :]),
        f"last {BAND} rows": _share(err[..., h - BAND : h, :], valid[..., h - BAND : h, :]),
        "middle window, in the whole frame": _share(err[..., rows, cols], valid[..., rows, cols]),
        "middle window, fed alone": _share(((alone > 0) != label[..., rows, cols]) & valid[..., rows, cols],
                                           valid[..., rows, cols]),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("data", help="labelled recording (file or folder)")
    ap.add_argument("checkpoints", nargs="+", help="depthseg .pt checkpoints")
    ap.add_argument("--frames", type=int, default=96, help="frames read from DATA (default %(default)s)")
    ap.add_argument("--window", default="128x160", help="middle window fed alone, HxW (default %(default)s)")
    args = ap.parse_args(argv)
    from edge.train.data import parse_crop

    try:
        window = parse_crop(args.window)
        results = {c: window_errors(args.data, c, args.frames, window) for c in args.checkpoints}
    except DepthsegError as exc:
        print(f"window_errors: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    print(f"wrong pixels, % of the valid ones, first {args.frames} frames of {args.data}; "
          f"middle window {window[0]}x{window[1]}")
    for ckpt, res in results.items():
        print(ckpt)
        for k, v in res.items():
            print(f"  {k:<36} {v:6.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
