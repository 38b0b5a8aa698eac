#!/usr/bin/env python
"""How high above the table are a model's false-object pixels, near object outlines and away from them?

Why: issue 9 read the false-object pixels within 2 px of true outlines on real and BlenSor
frames as a "halo" the model learned from the simulator's edge blur. A halo of blur lies at
table level; the lowest part of an object's side (its base, seen obliquely from the wrist
camera) lies a few millimetres up. The two call for different fixes (sensor model vs. what the
labels call object), and the height above the fitted floor plane tells them apart. On frames
labelled by the real capture's rule ("object = more than 10 mm above the RANSAC plane"), every
false-object pixel is below 10 mm by definition; the split shows how much of it is at table
level (< ``--low-mm``) and how much is raised but under the rule's line.

The same heights bound what any method that calls table-level pixels table can score on frames
labelled by object (the simulator's) whose support is one plane (on curved tables, trays and
flat objects the plane misplaces the table and the bound fails): ``ceiling_iou`` is the labels themselves with their
table-level object pixels made table (mixed and blurred pixels at outlines whose range reads the
table), scored like a model. Where the plane fit scores within 3 points of that ceiling, issue 9's
3-point margin over it cannot be reached without learning to call table-level pixels object, the
simulator's edge convention that does not transfer to real frames.

    .venv/bin/python tools/false_object_heights.py data/royale_lab.mcap
    .venv/bin/python tools/false_object_heights.py data/test_geo10 --model runs/v19/model.onnx --json

Heights come from `edge.baseline.PlaneBaseline.heights` (the labeller of the real capture: RANSAC
plane with the frame's intrinsics, 3 x 3 median), the band from `edge.metrics.boundary_band` (the
breakdown of ``depthseg-eval``), the mask from `edge.infer.Segmenter` (stored threshold and speck
rule). Shares are of the pooled union (TP + FP + FN), as in the eval breakdown. Torch-free.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from edge.baseline import PlaneBaseline, intrinsics_for  # noqa: E402
from edge.cliutil import print_json, run  # noqa: E402
from edge.errors import ConfigError, DataError  # noqa: E402
from edge.infer import Segmenter  # noqa: E402
from edge.io import open_frames  # noqa: E402
from edge.metrics import UNKNOWN, BreakdownAccumulator, MetricAccumulator  # noqa: E402
from edge.preprocess import valid_mask  # noqa: E402

PROG = "false_object_heights"


def height_split(data: Path, seg: Segmenter, boundary_px: int = 2, low_m: float = 0.003, rule_m: float = 0.010,
                 limit: int | None = None) -> dict[str, float | int]:
    """Pooled shares of the union: false-object pixels in the band, split by height above the plane.

    Args:
        data: a labelled recording (file or folder).
        seg: the model (its stored threshold and speck rule apply).
        boundary_px: half-width of the band around true outlines (`boundary_band`).
        low_m: below this height (metres) a pixel counts as table level (a blur halo).
        rule_m: the labelling rule's line (metres); pixels from ``low_m`` up to it are raised
            but under the line, pixels above it are over it.
        limit: score at most this many frames.

    Returns:
        ``frames``, ``union`` (pixels), and in % of the union: ``fp_near`` and its parts
        ``fp_near_table_level``, ``fp_near_raised_under_rule``, ``fp_near_over_rule``; ``fp_far``
        and its parts ``fp_far_table_level``, ``fp_far_raised_under_rule``, ``fp_far_over_rule``
        (false objects away from outlines: at table level a patch of table called object, raised a
        flat thing on it that the labels call table);
        the missed object pixels in the band ``fn_near`` and the part of them at table level,
        ``fn_near_table_level`` (object surface that depth alone cannot tell from the table);
        ``ceiling_iou`` and ``ceiling_pooled_iou`` (%): the per-frame mean and pooled IoU of the
        labels with their table-level object pixels made table (see the module docstring).

    Raises:
        DataError: no labelled frame.
        ConfigError: ``low_m`` not below ``rule_m``.
    """
    if not 0 <= low_m < rule_m:
        raise ConfigError(f"the table-level height must be >= 0 and below the rule's line, got {low_m} and {rule_m}")
    base = PlaneBaseline()
    frames, _n = open_frames(data)
    # One `BreakdownAccumulator` (the eval breakdown's own counting) over all scored pixels, and one
    # per height class over that class's pixels only: the classes partition the pixels, so their
    # error counts split the overall ones.
    total = BreakdownAccumulator(boundary_px)
    classes = {name: BreakdownAccumulator(boundary_px) for name in ("table_level", "raised_under_rule", "over_rule")}
    ceiling = MetricAccumulator()
    n = 0
    for fr in frames:
        if fr.label is None:
            continue
        if limit is not None and n >= limit:
            break
        mask = seg.predict(fr.depth).mask
        known = mask != UNKNOWN
        obj = mask == 1
        h = base.heights(fr.depth, intrinsics_for(fr.depth.shape, fr.info))
        total.add(obj, fr.label, known)
        for name, sel in (("table_level", h < low_m), ("raised_under_rule", (h >= low_m) & (h <= rule_m)),
                          ("over_rule", h > rule_m)):
            classes[name].add(obj, fr.label, known & sel)
        ceiling.add((fr.label != 0) & (h >= low_m), fr.label, valid_mask(fr.depth))  # scored as depthseg-eval scores
        n += 1
    if n == 0:
        raise DataError(f"{data}: no labelled frame; give a recording with a labels topic")
    t = total.summary()
    c = {name: acc.summary() for name, acc in classes.items()}
    top = ceiling.summary()

    def pct(count: int) -> float:
        return 100.0 * count / max(t.union, 1)

    return {"frames": n, "union": t.union, "fp_near": pct(t.fp_boundary),
            **{f"fp_near_{name}": pct(b.fp_boundary) for name, b in c.items()},
            "fp_far": pct(t.fp_far), **{f"fp_far_{name}": pct(b.fp_far) for name, b in c.items()},
            "fn_near": pct(t.fn_boundary), "fn_near_table_level": pct(c["table_level"].fn_boundary),
            "ceiling_iou": 100.0 * top.iou, "ceiling_pooled_iou": 100.0 * top.pooled_iou}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("data", type=Path, help="labelled recording (file or folder)")
    p.add_argument("--model", type=Path, default=None, help="ONNX model (default: the shipped one)")
    p.add_argument("--boundary-px", type=int, default=2, help="band around true outlines, px (default 2)")
    p.add_argument("--low-mm", type=float, default=3.0, help="table level: below this height (default 3 mm)")
    p.add_argument("--rule-mm", type=float, default=10.0, help="the labelling rule's line (default 10 mm)")
    p.add_argument("--limit", type=int, default=None, help="score at most this many frames")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)

    def body() -> int:
        r = height_split(args.data, Segmenter(args.model, threads=2), args.boundary_px, args.low_mm / 1000,
                         args.rule_mm / 1000, args.limit)
        if args.json:
            print_json(r)
        else:
            print(f"{args.data}: {r['frames']} frames; false object in % of the union: within {args.boundary_px} px "
                  f"of outlines {r['fp_near']:.2f} = table level (< {args.low_mm:g} mm) {r['fp_near_table_level']:.2f}"
                  f" + raised under {args.rule_mm:g} mm {r['fp_near_raised_under_rule']:.2f} + over it "
                  f"{r['fp_near_over_rule']:.2f}; farther {r['fp_far']:.2f} = table level {r['fp_far_table_level']:.2f}"
                  f" + raised {r['fp_far_raised_under_rule']:.2f} + over {r['fp_far_over_rule']:.2f}."
                  f" Missed object within {args.boundary_px}"
                  f" px: {r['fn_near']:.2f}, at table level {r['fn_near_table_level']:.2f}. Ceiling of a method"
                  f" that calls table-level pixels table: IoU {r['ceiling_iou']:.2f}, pooled {r['ceiling_pooled_iou']:.2f}")
        return 0

    return run(PROG, body, p)


if __name__ == "__main__":
    raise SystemExit(main())
