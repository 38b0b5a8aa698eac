#!/usr/bin/env python
"""Evaluate a model on the seed paper's own BlenSor scans (never trained on): the Table III/IV layout.

Why a separate tool: these scans are ``.npy`` arrays of *radial* range, not MCAP recordings.
`sim.importers` converts each to our layout in memory (Z = r / sqrt(1 + xn^2 + yn^2) with
BlenSor's 62 x 45 deg pinhole; label = object id != the ground's id) and the frames stream
straight into `edge.evaluate.evaluate`. Only scans with at least one object pixel are scored
(the shared set has 9 of them; scan_0 is the empty floor, used to find the ground's id).

    .venv/bin/python tools/eval_blensor.py [--model M] [--baseline] [--json] [--figures DIR]
        [--boundary-px B] [--ignore-boundary PX]
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from a checkout
    sys.path.insert(0, str(ROOT))

from edge.cliutil import print_json, run  # noqa: E402
from edge.errors import DataError  # noqa: E402
from edge.eval_cli import add_boundary_args, format_table  # noqa: E402
from edge.evaluate import FIGURE_PICKS, evaluate, model_label  # noqa: E402
from edge.io import Frame  # noqa: E402

PROG = "eval_blensor"
DEFAULT_DATA = ROOT.parent / "shared" / "data" / "blensor"

parser = argparse.ArgumentParser(
    prog=PROG,
    description="Score a model (and optionally the RANSAC baseline) on the seed paper's BlenSor scans "
    "that contain objects; same table (with the error breakdown) and --json as depthseg-eval.",
)
parser.add_argument("--model", "-m", default=None, help="model file (.onnx or .pt); default: the shipped model")
parser.add_argument("--data", default=str(DEFAULT_DATA), help=f"directory of scan_*.npy (default {DEFAULT_DATA})")
parser.add_argument("--threshold", "-t", type=float, default=None, help="decision boundary (default: the model's)")
parser.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
parser.add_argument("--baseline", action="store_true", help="also score the RANSAC plane + height baseline")
parser.add_argument("--figures", metavar="DIR", default=None, help="write Fig. 5 style PNG overlays here")
parser.add_argument("--max-figures", type=int, default=9, metavar="N", help="number of figures (default 9: all)")
parser.add_argument("--figures-pick", choices=FIGURE_PICKS, default="first", help="first or worst frames")
parser.add_argument("--threads", type=int, default=2, metavar="N", help="inference threads (default 2)")
add_boundary_args(parser)  # --boundary-px, --ignore-boundary: the same error breakdown as depthseg-eval


def blensor_frames(data: str | Path) -> tuple[list[Path], Iterator[Frame]]:
    """(scans with objects, a stream of their frames as Z depth + labels + CameraInfo)."""
    from sim.importers import (
        blensor_frame,
        blensor_intrinsics,
        detect_background_id,
        find_inputs,
        read_blensor_scan,
    )

    files = find_inputs([data], "scan_*.npy", "BlenSor scans")
    # the ground id needs every scan (scan_0 is ground only); ids are small, so read them once
    scans = [read_blensor_scan(f) for f in files]
    bg = detect_background_id(scans)
    with_objects = [s for s in scans if (s.ids != bg).any()]
    if not with_objects:
        raise DataError(f"{data}: none of the {len(scans)} BlenSor scans holds an object (background id {bg:g})")
    k = blensor_intrinsics(with_objects[0].radial.shape[1], with_objects[0].radial.shape[0])

    def gen() -> Iterator[Frame]:
        for i, s in enumerate(with_objects):
            depth, label = blensor_frame(s, bg, k)
            h, w = depth.shape
            info = {"fx": k[0], "fy": k[1], "cx": k[2], "cy": k[3], "height": h, "width": w, "d": []}
            yield Frame(depth=depth, stamp_ns=i * 100_000_000, label=label, info=info, extra={"file": s.path.name})

    return [s.path for s in with_objects], gen()


def main(argv: list[str] | None = None) -> int:
    args = parser.parse_args(argv)

    def body() -> int:
        from edge.predict import load_predictor

        files, frames = blensor_frames(args.data)
        predictor = load_predictor(args.model, threads=args.threads)
        report = evaluate(
            predictor, frames, threshold=args.threshold, baseline=args.baseline, figures_dir=args.figures,
            max_figures=args.max_figures, figure_pick=args.figures_pick,
            boundary_px=args.boundary_px, ignore_boundary=args.ignore_boundary,
        )
        if args.json:
            d = report.to_dict()
            d["data"] = str(args.data)
            d["scans"] = [f.name for f in files]
            print_json(d)
        else:
            print(f"model: {predictor.name}")
            print(f"data: {len(files)} BlenSor scans with objects in {args.data} ({', '.join(f.name for f in files)})")
            print(format_table(report, model_label(predictor.meta)))
        return 0

    return run(PROG, body, parser)


if __name__ == "__main__":
    raise SystemExit(main())
