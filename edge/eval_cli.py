"""``depthseg-eval``: score a model on labelled depth recordings, like the paper's Tables III/IV."""

from __future__ import annotations

import argparse
import struct
from collections.abc import Iterator
from pathlib import Path

from edge.cliutil import print_json, progress, run
from edge.errors import DataError
from edge.evaluate import FIGURE_PICKS, EvalReport, evaluate, model_label
from edge.frames import TOPIC_CLEAN, TOPIC_DEPTH, TOPIC_LABELS, Frame, list_mcap_files

PROG = "depthseg-eval"

parser = argparse.ArgumentParser(
    prog=PROG,
    description=(
        "Evaluate a segmentation model on labelled depth frames. Per frame: pixel accuracy, object IoU, "
        "precision and recall over valid pixels (the paper's definitions), averaged over frames; plus the "
        "pooled IoU over all pixels. A frame without object pixels and without object prediction scores 1."
    ),
    epilog=(
        "PATH is a .mcap file or a directory of them: simulated data from depthseg-sim, or any ROS 2 "
        "recording with a depth Image topic (32FC1 metres or 16UC1 mm) and a label Image topic "
        "(mono8, nonzero = object). Example: depthseg-eval --data out/test --baseline --figures out/figs"
    ),
)
parser.add_argument("--model", "-m", default=None, help="model file (.onnx or .pt); default: the shipped model")
parser.add_argument("--data", "-d", required=True, metavar="PATH", help="labelled .mcap file or directory of them")
parser.add_argument(
    "--threshold", "-t", type=float, default=None,
    help="decision boundary on the object probability (default: the one stored in the model, else 0.5)",
)
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
parser.add_argument("--depth-topic", default=None, help=f"depth Image topic (default: {TOPIC_DEPTH}, else auto-detected)")
parser.add_argument("--labels-topic", default=None, help=f"label Image topic (default: {TOPIC_LABELS}, else auto-detected)")
parser.add_argument("--limit", type=int, default=None, metavar="N", help="stop after N labelled frames")
parser.add_argument("--threads", type=int, default=2, metavar="N", help="inference threads (default 2)")


def _channels(files: list[Path]) -> dict[str, int]:
    """Topic -> message count over all files (from the MCAP summaries; a scan when a file has none)."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    topics: dict[str, int] = {}
    for f in files:
        try:
            with open(f, "rb") as fh:
                reader = make_reader(fh)
                summary = reader.get_summary()
                if summary is not None and summary.statistics is not None:
                    counts = summary.statistics.channel_message_counts
                    for cid, ch in summary.channels.items():
                        topics[ch.topic] = topics.get(ch.topic, 0) + int(counts.get(cid, 0))
                    continue
                for _s, ch, _m in reader.iter_messages():
                    topics[ch.topic] = topics.get(ch.topic, 0) + 1
        except (McapError, ValueError, OSError, EOFError, struct.error) as exc:
            raise DataError(f"{f}: not a readable MCAP file ({type(exc).__name__}: {str(exc)[:120]})") from None
    # a registered channel without messages (e.g. labels never written) is not data
    return {t: n for t, n in topics.items() if n > 0}


def _pick(topics: dict[str, int], given: str | None, default: str, words: tuple[str, ...], what: str, flag: str,
          exclude: tuple[str, ...] = ()) -> str:
    names = sorted(topics)
    if given is not None:
        if given not in topics:
            raise DataError(f"no {what} topic '{given}' in the data; topics present: {', '.join(names) or 'none'}")
        return given
    if default in topics:
        return default
    cands = [t for t in names if any(w in t.lower() for w in words) and t not in exclude]
    if len(cands) == 1:
        return cands[0]
    hint = f"several candidates ({', '.join(cands)})" if cands else "none found"
    raise DataError(f"no {what} topic ({hint}); topics present: {', '.join(names) or 'none'}; pass {flag}")


def open_frames(path: str, depth_topic: str | None, labels_topic: str | None) -> tuple[Iterator[Frame], int | None]:
    """A stream of labelled frames from PATH and the number of depth messages (for the bar)."""
    try:  # the general reader (foxglove images, damaged files) when it is installed
        from replay.reader import open_depth_stream  # type: ignore[attr-defined]
    except ImportError:
        open_depth_stream = None
    files = list_mcap_files(path)
    topics = _channels(files)
    dt = _pick(topics, depth_topic, TOPIC_DEPTH, ("depth",), "depth", "--depth-topic", exclude=(TOPIC_CLEAN,))
    lt = _pick(topics, labels_topic, TOPIC_LABELS, ("label", "mask", "seg"), "label", "--labels-topic")
    if open_depth_stream is not None:
        return iter(open_depth_stream(path, topic=dt, labels_topic=lt)), topics.get(dt) or None
    from edge.frames import iter_frames

    return iter_frames(path, depth_topic=dt, labels_topic=lt), topics.get(dt) or None


def format_table(report: EvalReport, model_name: str) -> str:
    """The paper's Table III/IV layout: mean per-frame scores in %, plus pooled IoU."""
    rows = [(model_name, report.metrics)]
    if report.baseline is not None:
        h = (report.baseline_params or {}).get("height_threshold_m", 0.0)
        rows.append((f"RANSAC plane + {1000 * h:g} mm", report.baseline))
    w = max(len(r[0]) for r in rows + [("Model", None)])
    head = f"{'Model':<{w}}  {'Pixel acc.':>10}  {'IoU':>7}  {'Precision':>9}  {'Recall':>7}  {'Pooled IoU':>10}"
    lines = [head, "-" * len(head)]
    for name, m in rows:
        lines.append(
            f"{name:<{w}}  {100 * m.pixel_accuracy:>10.2f}  {100 * m.iou:>7.2f}  {100 * m.precision:>9.2f}  "
            f"{100 * m.recall:>7.2f}  {100 * m.pooled_iou:>10.2f}"
        )
    notes = [
        f"{report.frames} frames, threshold {report.threshold:g}; each score is the mean over frames in % "
        "(pooled IoU: over all valid pixels of all frames).",
    ]
    if report.metrics.skipped:
        notes.append(f"{report.metrics.skipped} frames without valid pixels were not scored.")
    if report.unlabelled:
        notes.append(f"{report.unlabelled} frames without labels were skipped.")
    if report.figures:
        notes.append(f"{len(report.figures)} figures written to {report.figures[0].parent}")
    return "\n".join(lines + [""] + notes)


def main(argv: list[str] | None = None) -> int:
    args = parser.parse_args(argv)

    def body() -> int:
        from edge.baseline import PlaneBaseline
        from edge.errors import ConfigError
        from edge.predict import load_predictor

        if args.threads < 1:
            raise ConfigError(f"--threads must be >= 1, got {args.threads}")
        base = PlaneBaseline(height_threshold_m=args.baseline_height) if args.baseline else False
        frames, total = open_frames(args.data, args.depth_topic, args.labels_topic)
        predictor = load_predictor(args.model, threads=args.threads)
        if args.limit is not None and total is not None:
            total = min(total, args.limit)
        with progress(frames, total=total, desc="eval", unit="frame") as bar:
            report = evaluate(
                predictor, bar, threshold=args.threshold, baseline=base, figures_dir=args.figures,
                max_figures=args.max_figures, figure_pick=args.figures_pick, limit=args.limit,
            )
        if args.json:
            print_json(report.to_dict())
        else:
            print(f"model: {predictor.name}")
            print(format_table(report, model_label(predictor.meta)))
        return 0

    return run(PROG, body)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
