#!/usr/bin/env python
"""Draw a contact sheet (one PNG) of depth frames with their labels, to eyeball a recording.

Why: a person should see in seconds whether simulated (or imported) frames look like the
camera's and whether the labels sit on the objects. Each tile shows the Z depth as a viridis
colour map (near = yellow, far = dark blue; scaled per frame between the 2nd and 98th percentile of the
valid pixels), invalid pixels black, object pixels tinted red (viridis has no red) and outlined in white, and a caption:
frame index, object-pixel fraction (or "no labels") and invalid-pixel fraction.

    .venv/bin/python tools/contact_sheet.py RECORDING.mcap|DIR --out sheet.png [--frames 16] [--cols 4]
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from a checkout
    sys.path.insert(0, str(ROOT))

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from edge.cliutil import run  # noqa: E402
from edge.errors import ConfigError, DataError  # noqa: E402
from edge.io import Frame, iter_frames, write_bytes_atomic  # noqa: E402
from edge.preprocess import valid_mask  # noqa: E402

PROG = "contact_sheet"
CAPTION_H = 22  # px per tile caption strip at scale 1 (grows with scale)


def colorize_depth(depth: np.ndarray) -> np.ndarray:
    """BGR uint8 viridis map of Z (near yellow, far dark blue), invalid pixels black."""
    d = np.asarray(depth, dtype=np.float64)
    valid = valid_mask(d)
    out = np.zeros(d.shape + (3,), np.uint8)
    if not valid.any():
        return out
    lo, hi = np.percentile(d[valid], [2, 98])
    hi = hi if hi > lo else lo + 1e-3
    t = np.clip((hi - np.where(valid, d, hi)) / (hi - lo), 0, 1)  # near -> 1 -> yellow
    col = cv2.applyColorMap((t * 255).astype(np.uint8), cv2.COLORMAP_VIRIDIS)
    out[valid] = col[valid]
    return out


def render_tile(frame: Frame, index: int, scale: int = 2) -> np.ndarray:
    """One captioned tile: coloured depth, label tint and outline, caption strip below."""
    img = colorize_depth(frame.depth)
    valid = valid_mask(frame.depth)
    if frame.label is not None:
        obj = frame.label.astype(bool) & valid  # invalid pixels stay black
        img[obj] = (0.6 * img[obj] + 0.4 * np.array([40, 40, 255])).astype(np.uint8)  # red tint (BGR)
    img = cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    if frame.label is not None:
        big = cv2.resize(frame.label.astype(np.uint8), None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
        contours, _ = cv2.findContours(big, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        cv2.drawContours(img, contours, -1, (255, 255, 255), 1)
        what = f"obj {float(frame.label.mean()):.1%}"
    else:
        what = "no labels"
    cap_h = CAPTION_H * max(1, scale // 2)
    strip = np.full((cap_h, img.shape[1], 3), 32, np.uint8)
    text = f"#{index}  {what}  inv {1 - float(valid.mean()):.1%}"
    fs = 0.45 * max(1, scale // 2)
    cv2.putText(strip, text, (4, cap_h - 7), cv2.FONT_HERSHEY_SIMPLEX, fs, (240, 240, 240), 1, cv2.LINE_AA)
    return np.vstack([img, strip])


def contact_sheet(frames: Iterable[tuple[int, Frame]], cols: int = 4, scale: int = 2, gap: int = 4) -> np.ndarray:
    """Tiles in a grid, row-major, on a dark background; tiles of other sizes are letterboxed."""
    tiles = [render_tile(f, i, scale) for i, f in frames]
    if not tiles:
        raise DataError("no frames to draw")
    th = max(t.shape[0] for t in tiles)
    tw = max(t.shape[1] for t in tiles)
    cols = min(cols, len(tiles))
    rows = -(-len(tiles) // cols)
    sheet = np.full((rows * th + (rows + 1) * gap, cols * tw + (cols + 1) * gap, 3), 16, np.uint8)
    for k, t in enumerate(tiles):
        r, c = divmod(k, cols)
        y, x = gap + r * (th + gap), gap + c * (tw + gap)
        sheet[y : y + t.shape[0], x : x + t.shape[1]] = t
    return sheet


def write_png(img: np.ndarray, out: str | Path) -> Path:
    """Encode and write atomically (temp file, then rename)."""
    o = Path(out)
    ok, buf = cv2.imencode(".png", img, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    if not ok:  # pragma: no cover - opencv failure
        raise DataError(f"{o}: PNG encoding failed")
    return write_bytes_atomic(o, buf.tobytes())


def pick_frames(path: str | Path, n: int, stride: int = 1, depth_topic: str | None = None):
    """(index, frame) of frames 0, stride, 2*stride, ... (at most n), streamed."""
    taken = 0
    for i, f in enumerate(iter_frames(path, depth_topic=depth_topic)):
        if taken >= n:
            return
        if i % stride == 0:
            taken += 1
            yield i, f


parser = argparse.ArgumentParser(
    prog=PROG,
    description="Contact sheet PNG of depth frames from an MCAP file or a directory of them: depth as a "
    "colour map (invalid black), labels tinted red with a white outline, captions with frame index, "
    "object-pixel and invalid-pixel fractions.",
)
parser.add_argument("recording", help="an .mcap file or a directory of them (depthseg layout or ROS 2 Image)")
parser.add_argument("--out", required=True, help="output .png (written atomically)")
parser.add_argument("--frames", type=int, default=16, help="number of frames to draw (default 16)")
parser.add_argument("--cols", type=int, default=4, help="tiles per row (default 4)")
parser.add_argument("--stride", type=int, default=1, help="take every K-th frame (default 1)")
parser.add_argument("--scale", type=int, default=2, help="integer upscaling of each tile (default 2)")
parser.add_argument("--topic", default=None, help="depth topic (default /pico_flexx/image_depth)")


def main(argv: list[str] | None = None) -> int:
    args = parser.parse_args(argv)

    def body() -> int:
        for name in ("frames", "cols", "stride", "scale"):
            if getattr(args, name) < 1:
                raise ConfigError(f"--{name} must be >= 1, got {getattr(args, name)}")
        out = Path(args.out)
        if out.suffix.lower() != ".png":
            raise ConfigError(f"--out {out}: name must end in .png")
        if out.is_dir() or not out.parent.exists():
            raise ConfigError(f"--out {out}: not a file path in an existing directory")
        sheet = contact_sheet(pick_frames(args.recording, args.frames, args.stride, args.topic), args.cols, args.scale)
        write_png(sheet, out)
        print(f"wrote {out} ({sheet.shape[1]} x {sheet.shape[0]} px)")
        return 0

    return run(PROG, body, parser)


if __name__ == "__main__":
    raise SystemExit(main())
