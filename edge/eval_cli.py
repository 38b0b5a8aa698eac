"""``depthseg-eval``: score a model on labelled depth recordings, like the paper's Tables III/IV."""

from __future__ import annotations

import argparse

from edge.cliutil import add_min_height_arg, add_recording_args, add_version, print_json, progress, run
from edge.evaluate import DEFAULT_BOUNDARY_PX, FIGURE_PICKS, EvalReport, model_label
from edge.metrics import ErrorBreakdown, MetricSummary
from edge.postprocess import describe_height_rule

PROG = "depthseg-eval"

parser = argparse.ArgumentParser(
    prog=PROG,
    description=(
        "Evaluate a segmentation model on labelled depth frames. Per frame: pixel accuracy, object IoU, "
        "precision and recall over valid pixels (the paper's definitions), averaged over frames; plus the "
        "pooled IoU over all pixels. A frame without object pixels and without object prediction scores 1. "
        "Also where the errors are: the pooled union (TP + FP + FN) split into TP, false object and missed "
        "object near the true object boundaries (within --boundary-px) and far from them."
    ),
    epilog=(
        "PATH is a .mcap file or a directory of them: simulated data from depthseg-sim, or any ROS 2 "
        "recording with a depth Image topic (32FC1 metres or 16UC1 mm) and a label Image topic "
        "(mono8, nonzero = object). Example: depthseg-eval --data out/test --baseline --figures out/figs"
    ),
)
add_version(parser, PROG)
parser.add_argument("--model", "-m", default=None,
                    help="model file (.onnx, or .pt with the train extra); default: the shipped ONNX model")
parser.add_argument("--data", "-d", required=True, metavar="PATH", help="labelled recording (.mcap, .bag, .db3, ROS 2 bag directory) or a directory of them")
parser.add_argument(
    "--threshold", "-t", type=float, default=None,
    help="decision boundary on the object probability (default: the one stored in the model, else 0.5)",
)
parser.add_argument(
    "--min-object-px", type=int, default=None, metavar="PX",
    help="object specks (8-connected) under PX pixels become background (default: the model's rule, 6 px "
         "unless stored otherwise; 0 keeps every object pixel)",
)
add_min_height_arg(parser)
parser.add_argument("--json", action="store_true", help="print one JSON object (fractions in [0, 1]) instead of a table")
parser.add_argument("--figures", metavar="DIR", default=None, help="write PNG overlays like the paper's Fig. 5 here")
parser.add_argument("--max-figures", type=int, default=8, metavar="N", help="number of figures to write (default 8)")
parser.add_argument(
    "--figures-pick", choices=FIGURE_PICKS, default="first",
    help="which frames get a figure: the first ones or the worst by IoU (default first)",
)
parser.add_argument(
    "--baseline", action="store_true",
    help="also score the classical baseline (RANSAC floor plane + height threshold) on the same frames",
)
parser.add_argument("--baseline-height", type=float, default=0.008, metavar="M",
                    help="baseline: height above the plane that counts as object, metres (default 0.008)")
parser.add_argument("--baseline-median", type=int, choices=(0, 3, 5), default=3, metavar="PX",
                    help="baseline: median filter on the height map, 0 (off), 3 or 5 pixels (default 3)")
add_recording_args(parser, limit_help="stop after N labelled frames")


def add_boundary_args(p: argparse.ArgumentParser) -> None:
    """The ``--boundary-px`` and ``--ignore-boundary`` options, shared with tools/eval_blensor.py.

    Args:
        p: the parser to extend.
    """
    p.add_argument(
        "--boundary-px", type=int, default=DEFAULT_BOUNDARY_PX, metavar="B",
        help="error breakdown: errors within B px (chessboard distance) of a true boundary pixel count as "
        f"'boundary', the rest as 'far' (default {DEFAULT_BOUNDARY_PX})",
    )
    p.add_argument(
        "--ignore-boundary", type=int, default=None, metavar="PX",
        help="also score with a void band of PX px around the true object boundaries left out (PASCAL VOC "
        "style), printed beside the plain scores (default: off)",
    )


add_boundary_args(parser)


def _score_rows(names: list[str], summaries: list[MetricSummary | None]) -> list[str]:
    """Header, rule and one row per method of the paper's scores in % (a missing summary prints as -)."""
    w = max(len(n) for n in names + ["Model"])
    head = f"{'Model':<{w}}  {'Pixel acc.':>10}  {'IoU':>7}  {'Precision':>9}  {'Recall':>7}  {'Pooled IoU':>10}"
    lines = [head, "-" * len(head)]
    for name, m in zip(names, summaries):
        if m is None:
            lines.append(f"{name:<{w}}  {'-':>10}  {'-':>7}  {'-':>9}  {'-':>7}  {'-':>10}")
            continue
        lines.append(
            f"{name:<{w}}  {100 * m.pixel_accuracy:>10.2f}  {100 * m.iou:>7.2f}  {100 * m.precision:>9.2f}  "
            f"{100 * m.recall:>7.2f}  {100 * m.pooled_iou:>10.2f}"
        )
    return lines


BREAKDOWN_COLUMNS = (("tp", "TP"), ("fp_boundary", "FP bound."), ("fp_far", "FP far"),
                     ("fn_boundary", "FN bound."), ("fn_far", "FN far"))


def _breakdown_rows(names: list[str], breakdowns: list[ErrorBreakdown]) -> list[str]:
    """One row per method: the shares of the pooled union in %, which sum to 100."""
    w = max(len(n) for n in names + ["Model"])
    head = f"{'Model':<{w}}" + "".join(f"  {title:>9}" for _, title in BREAKDOWN_COLUMNS)
    lines = [head, "-" * len(head)]
    for name, bd in zip(names, breakdowns):
        sh = bd.shares()
        lines.append(f"{name:<{w}}" + "".join(f"  {100 * sh[k]:>9.2f}" for k, _ in BREAKDOWN_COLUMNS))
    return lines


def format_table(report: EvalReport, model_name: str) -> str:
    """The paper's Table III/IV layout (mean per-frame scores in %, plus pooled IoU) and the extra blocks.

    Below the plain table: where the errors are (the breakdown of the pooled union) and, with
    ``--ignore-boundary``, the same scores with the void band left out, labelled as such.

    Args:
        report: what `edge.evaluate.evaluate` measured.
        model_name: the name of the model row.

    Returns:
        The printable text, lines joined with newlines.
    """
    names = [model_name]
    plain = [report.metrics]
    breakdowns = [report.breakdown]
    ignored = [report.ignore_boundary]
    if report.baseline is not None:
        bp = report.baseline_params or {}
        med = f" (median {bp['median_px']})" if bp.get("median_px") else ""
        names.append(f"RANSAC plane + {1000 * bp.get('height_threshold_m', 0.0):g} mm{med}")
        plain.append(report.baseline)
        breakdowns.append(report.baseline_breakdown)
        ignored.append(report.baseline_ignore_boundary)
    lines = _score_rows(names, plain)
    bds = [b for b in breakdowns if b is not None]
    if len(bds) == len(names):
        lines += [
            "",
            "Where the errors are, in % of the pooled union (TP + FP + FN over valid pixels; sums to 100, TP = pooled IoU).",
            f"FP = false object, FN = missed object; bound. = within {bds[0].boundary_px} px of a true object boundary "
            "pixel, far = farther:",
        ]
        lines += _breakdown_rows(names, bds)
    if report.ignore_boundary_px is not None:
        lines += [
            "",
            f"EXTRA score, ignoring a {report.ignore_boundary_px} px void band around true object boundaries "
            "(the plain scores above count every valid pixel):",
        ]
        lines += _score_rows([f"{n} [void band]" for n in names], ignored)
    notes = [
        f"{report.frames} frames, threshold {report.threshold:g}, "
        + (f"model's {describe_height_rule(report.min_height_m)}, " if report.min_height_m else "")
        + f"model's object specks under {report.min_object_px} px removed; each score is the mean over frames in % "
        "(pooled IoU: over all valid pixels of all frames).",
    ]
    notes += _labels_notes(report)
    if report.metrics.skipped:
        notes.append(f"{report.metrics.skipped} frames without valid pixels were not scored.")
    if report.unlabelled:
        notes.append(f"{report.unlabelled} frames without labels were skipped.")
    if report.figures:
        notes.append(f"{len(report.figures)} figures written to {report.figures[0].parent}")
    return "\n".join(lines + [""] + notes)


def _labels_notes(report) -> list[str]:
    """What the recording says its labels are, and the flag that scores the model in that meaning."""
    from edge.evaluate import labels_line_mm

    out = [f"labels, as the recording describes them: {text}" for text in report.labels_declared]
    lines = {labels_line_mm(t) for t in report.labels_declared} - {None}
    if len(lines) == 1 and not report.min_height_m:
        mm = lines.pop()
        out.append(
            f"note: these labels call the lowest {mm:g} mm of every object table, the model's training labels call "
            f"it object; --min-height-mm {mm:g} scores the model with the labels' meaning (README, 'Results')"
        )
    return out


def main(argv: list[str] | None = None) -> int:
    args = parser.parse_args(argv)

    def body() -> int:
        from edge.baseline import PlaneBaseline
        from edge.commands import evaluate_model

        base = PlaneBaseline(height_threshold_m=args.baseline_height, median_px=args.baseline_median) if args.baseline else None
        report = evaluate_model(
            args.data, args.model, threshold=args.threshold, baseline=base, figures=args.figures,
            max_figures=args.max_figures, figures_pick=args.figures_pick, depth_topic=args.depth_topic,
            labels_topic=args.labels_topic, depth_scale=args.depth_scale, limit=args.limit, threads=args.threads,
            boundary_px=args.boundary_px,
            ignore_boundary=args.ignore_boundary, min_object_px=args.min_object_px,
            min_height_m=args.min_height_m, wrap=lambda frames, total: progress(frames, total=total, desc="eval", unit="frame"),
        )
        if args.json:
            print_json(report.to_dict())
        else:
            print(f"model: {report.model}")
            print(format_table(report, model_label(report.meta)))
        return 0

    return run(PROG, body, parser)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
