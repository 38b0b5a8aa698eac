#!/usr/bin/env python
"""The paper's Fig. 6 on our model: predictions on a real pico flexx capture (no labels).

Panels: the preprocessed input, the model's mask at the stored threshold, at 0.5 and at the
paper's 0.9999, the RANSAC floor-plane baseline (the only reference we have without labels), and
the model's mask with the height rule (`--min-height-mm`, default 10: the labels' meaning of the
real capture; `edge.postprocess.remove_low_parts`: the stored threshold, the height rule, the speck rule).
The last line of the figure gives, per panel, the object share and the agreement (IoU) with the
baseline, so "looks right" comes with a number. Reads the royaleviewer PLY from ../shared at run
time (nothing from it is committed but this figure). Torch-free (edge path).

    .venv/bin/python tools/real_capture_figure.py [--ply FILE] [--model M.onnx] [--rule-mm 10] [--out docs/real_capture.png]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from edge.baseline import PlaneBaseline, intrinsics_for  # noqa: E402
from edge.cliutil import print_json, run  # noqa: E402
from edge.infer import Segmenter  # noqa: E402
from edge.io import write_bytes_atomic  # noqa: E402
from edge.preprocess import preprocess, valid_mask  # noqa: E402
from sim.importers import fit_intrinsics, read_ply  # noqa: E402

PROG = "real_capture_figure"
DEFAULT_PLY = ROOT.parent / "shared" / "data" / "royale" / "royale_20200513_203219_0.ply"


def _iou(a: np.ndarray, b: np.ndarray, valid: np.ndarray) -> float:
    a, b = a & valid, b & valid
    u = (a | b).sum()
    return float((a & b).sum() / u) if u else 1.0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog=PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--ply", type=Path, default=DEFAULT_PLY)
    p.add_argument("--model", type=Path, default=None, help="ONNX model (default: the shipped one)")
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "real_capture.png")
    p.add_argument("--rule-mm", type=float, default=10.0, help="the height rule's line of the last panel (default 10)")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)

    def body() -> int:
        import cv2

        cap = read_ply(args.ply)
        depth = cap.depth
        seg = Segmenter(args.model, threads=2)
        valid = valid_mask(depth)
        (fx, fy, cx, cy), _rms = fit_intrinsics(cap.points, cap.valid)
        info = {"fx": fx, "fy": fy, "cx": cx, "cy": cy, "height": depth.shape[0], "width": depth.shape[1]}
        k = intrinsics_for(depth.shape, info, seg.meta.sensor)
        base = PlaneBaseline().predict(depth, k).astype(bool)
        panels = [("input (standardised)", None)]
        stats = {}
        for name, t in (("stored", seg.threshold), ("0.5", 0.5), ("0.9999", 0.9999)):
            m = seg.predict(depth, threshold=t).mask == 1  # the one threshold rule, then the speck rule
            label = f"model @ {t:.4g}" + (" (stored)" if name == "stored" else "")
            stats[label] = {"object_share": float(m[valid].mean()), "iou_vs_baseline": _iou(m, base, valid)}
            panels.append((label, m))
        stats["RANSAC baseline"] = {"object_share": float(base[valid].mean()), "iou_vs_baseline": 1.0}
        panels.append(("RANSAC baseline", base))
        ruled = Segmenter(args.model, threads=2, min_height_m=args.rule_mm / 1000.0).predict(depth).mask == 1
        label = f"model, height rule {args.rule_mm:g} mm"
        stats[label] = {"object_share": float(ruled[valid].mean()), "iou_vs_baseline": _iou(ruled, base, valid)}
        panels.append((label, ruled))

        x = preprocess(depth).x[0][: depth.shape[0], : depth.shape[1]]
        g = np.clip((x + 2.5) / 5.0, 0, 1)
        tiles = []
        for label, m in panels:
            if m is None:
                rgb = np.dstack([g, g, g])
            else:
                rgb = np.dstack([g * 0.5 + 0.25] * 3)
                rgb[m] = (1.0, 0.55, 0.1)
            rgb[~valid] = (0.25, 0.0, 0.3)
            img = (cv2.resize((rgb * 255).astype(np.uint8), None, fx=2, fy=2, interpolation=cv2.INTER_NEAREST))
            img = cv2.copyMakeBorder(img, 40, 4, 4, 4, cv2.BORDER_CONSTANT, value=(255, 255, 255))
            cv2.putText(img, label, (8, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
            if m is not None:
                s = stats[label]
                txt = f"objects {100 * s['object_share']:.1f}%  IoU vs baseline {100 * s['iou_vs_baseline']:.1f}%"
                cv2.putText(img, txt, (8, 34), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
            tiles.append(img)
        row1 = np.hstack(tiles[:3])
        row2 = np.hstack(tiles[3:6])
        sheet = np.vstack([row1, row2])
        args.out.parent.mkdir(parents=True, exist_ok=True)
        ok, buf = cv2.imencode(".png", cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
        write_bytes_atomic(args.out, buf.tobytes())
        out = {"ply": str(args.ply), "model": str(seg.path), "out": str(args.out), "panels": stats}
        if args.json:
            print_json(out)
        else:
            for label, s in stats.items():
                print(f"{label:28s} objects {100 * s['object_share']:5.1f} %   IoU vs baseline {100 * s['iou_vs_baseline']:5.1f} %")
            print(f"wrote {args.out}")
        return 0

    return run(PROG, body)


if __name__ == "__main__":
    raise SystemExit(main())
