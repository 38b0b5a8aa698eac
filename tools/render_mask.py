"""Render the mask topic of a ``depthseg-replay --out`` file to a PNG, as Foxglove shows it.

    .venv/bin/python tools/render_mask.py seg.mcap --out docs/mask_topic.png [--frames 0,40,80] [--topic /depthseg/mask]

Reads the rgb8 ``<ns>/mask`` messages (the displayable mask: table dark blue, objects orange,
unknown magenta) with an independent decoder (``mcap_ros2``), tiles the chosen frames, each at 2x
beside the replay's overlay, and adds a legend. Nothing is recoloured here: the pixels are the
message's own.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def images(path: Path, topic: str) -> list[np.ndarray]:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    out = []
    with open(path, "rb") as fh:
        for _, _, _, m in make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages(topics=[topic]):
            if m.encoding != "rgb8":
                raise SystemExit(f"{topic}: encoding {m.encoding}, expected rgb8")
            out.append(np.frombuffer(bytes(m.data), np.uint8).reshape(m.height, m.step)[:, : m.width * 3]
                       .reshape(m.height, m.width, 3))
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("recording", type=Path)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--frames", default="0,40,80")
    p.add_argument("--namespace", default="/depthseg")
    args = p.parse_args(argv)
    masks = images(args.recording, f"{args.namespace}/mask")
    overlays = images(args.recording, f"{args.namespace}/overlay")
    idx = [int(i) for i in args.frames.split(",")]
    rows = []
    for i in idx:
        m = cv2.resize(masks[i], None, fx=2, fy=2, interpolation=cv2.INTER_NEAREST)
        o = cv2.resize(overlays[i], None, fx=2, fy=2, interpolation=cv2.INTER_NEAREST)
        gap = np.full((m.shape[0], 8, 3), 255, np.uint8)
        rows.append(np.hstack([m, gap, o]))
        rows.append(np.full((8, rows[-1].shape[1], 3), 255, np.uint8))
    grid = np.vstack(rows[:-1])
    legend = np.full((70, grid.shape[1], 3), 255, np.uint8)
    from replay.writer import MASK_COLOURS

    x = 10
    for cls, name in ((0, "table (background)"), (1, "object"), (255, "unknown (invalid depth)")):
        cv2.rectangle(legend, (x, 12), (x + 22, 34), tuple(int(c) for c in MASK_COLOURS[cls]), -1)
        cv2.putText(legend, name, (x + 28, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 0, 0), 1, cv2.LINE_AA)
        x += 40 + 11 * len(name)
    cv2.putText(legend, f"left: {args.namespace}/mask (rgb8)   right: {args.namespace}/overlay",
                (10, 60), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (60, 60, 60), 1, cv2.LINE_AA)
    img = np.vstack([legend, grid])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(args.out), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
    print(f"wrote {args.out} ({img.shape[1]}x{img.shape[0]}, frames {idx})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
