"""``depthseg-tune``: choose a model's decision boundary from data and store it in the model."""

from __future__ import annotations

import argparse

from edge.cliutil import add_recording_args, add_version, print_json, progress, run
from edge.tune import OBJECTIVE_FORMS

PROG = "depthseg-tune"

parser = argparse.ArgumentParser(
    prog=PROG,
    description=(
        "Choose the decision boundary (threshold on the object probability) that best serves an objective, "
        "from labelled depth frames, and write it with the policy that chose it into the model's metadata, "
        "where depthseg-eval, depthseg-replay and depthseg-bench read it. The model runs once over the frames; "
        "logits of valid pixels are binned on a fine fixed grid, so memory stays constant and every threshold "
        "on the grid is tried. Part of the frames (--split) is held out: the objective is reported there at "
        "the model's stored threshold and at the chosen one, and the stored threshold is kept unless the new one "
        "is better there."
    ),
    epilog=(
        f"Objectives ({OBJECTIVE_FORMS}) use per-frame mean scores over valid pixels, the numbers depthseg-eval "
        "prints: iou = mean IoU; fBETA = F-beta of mean precision and mean recall (f0.5 favours precision, f2 "
        "recall); precision>=P = the best recall whose precision is at least P; recall>=R likewise. "
        "Examples: depthseg-tune --model m.onnx --data out/val --objective 'precision>=0.98' --out m_tuned.onnx; "
        "depthseg-tune --model m.onnx --data capture.mcap --pseudo-labels --dry-run. "
        "Tuning an int8 ONNX tunes on the int8 model's own outputs."
    ),
)
add_version(parser, PROG)
parser.add_argument("--model", "-m", default=None, help="model file (.onnx or .pt); default: the shipped model")
parser.add_argument("--data", "-d", required=True, metavar="PATH", help="labelled recording (.mcap, .bag, .db3, ROS 2 bag directory) or a directory of them")
parser.add_argument("--objective", "-o", default="iou", help=f"what to optimise: {OBJECTIVE_FORMS} (default iou)")
parser.add_argument("--split", type=float, default=0.25, metavar="F",
                    help="fraction of frames held out for the before/after report (default 0.25; 0 = report in-sample)")
parser.add_argument("--seed", type=int, default=0, help="seed of the held-out split (and of the pseudo-label RANSAC)")
parser.add_argument("--out", default=None, metavar="M2",
                    help="write the tuned model here (same type; never the model or data file); default: rewrite --model "
                    "in place after a .bak copy; the shipped model is never rewritten: without --out its tuned copy goes "
                    "to $XDG_DATA_HOME/depthseg/models (~/.local/share/depthseg/models)")
parser.add_argument("--dry-run", action="store_true", help="report only; write nothing into any model")
parser.add_argument("--json", action="store_true", help="print one JSON object instead of the text report")
parser.add_argument("--plot", metavar="PR.png", default=None,
                    help="write a precision-recall curve with the stored and the chosen points marked")
parser.add_argument(
    "--pseudo-labels", action="store_true",
    help="for an unlabelled recording: tune against geometric pseudo-labels (RANSAC floor plane + height "
    "threshold, as depthseg-eval --baseline) instead of ground truth; reported and stored as such",
)
parser.add_argument("--pseudo-height", type=float, default=0.008, metavar="M",
                    help="pseudo-labels: height above the plane that counts as object, metres (default 0.008)")
add_recording_args(parser, limit_help="use at most N frames")


def _fmt_point(name: str, p: dict, metric: str) -> str:
    extra = f"  {metric} {p[metric]:.4f}" if metric not in ("iou", "precision", "recall", "f1") else ""
    return (
        f"  {name:<16} {p['threshold']:<12.8g} {p['iou']:>7.4f} {p['precision']:>9.4f} {p['recall']:>7.4f} "
        f"{p['f1']:>7.4f} {p['pooled_iou']:>10.4f}{extra}"
    )


def format_report(d: dict) -> str:
    lines = [f"model: {d['model']} (stored threshold {d['current']['stored_threshold']:.8g})"]
    if d["pseudo_labels"]:
        lines.append(f"labels: {d['labels']}  <- NOT ground truth: scores measure agreement with the plane baseline")
    else:
        lines.append(f"labels: {d['labels']}")
    lines.append(
        f"frames: {d['tuning_frames']} tuning, {d['heldout_frames']} held out (split {d['split']:g}, seed {d['seed']})"
        + (f", {d['unlabelled_frames']} unlabelled skipped" if d["unlabelled_frames"] else "")
        + (f", {d['skipped_frames']} without valid pixels" if d["skipped_frames"] else "")
    )
    lines.append(f"objective: {d['objective']} ({d['objective_description']})")
    lines.append(
        f"chosen threshold: {d['threshold']:.8g} (logit {d['threshold_logit']:.4f}); "
        f"tuning-frames {d['metric']} {d['tuning_value']:.4f}"
    )
    where = "in-sample (tuning frames, --split 0)" if d["in_sample"] else f"held-out frames ({d['heldout_frames']})"
    lines.append(f"{where}: per-frame means of the threshold rule alone (before the model's speck rule; "
                 "depthseg-eval --min-object-px 0 gives these)")
    lines.append(f"  {'':<16} {'threshold':<12} {'IoU':>7} {'precision':>9} {'recall':>7} {'F1':>7} {'pooled IoU':>10}")
    lines.append(_fmt_point("before (stored)", d["before"], d["metric"]))
    lines.append(_fmt_point("after (tuned)", d["after"], d["metric"]))
    gain = d["after"]["objective"] - d["before"]["objective"]
    if "meets_target" in d["after"]:
        kind = d["objective"].split(">=")[0]
        met = {True: "met", False: "NOT met"}
        lines.append(
            f"target {d['objective']}: {kind} {d['before'][kind]:.4f} stored ({met[d['before']['meets_target']]}), "
            f"{d['after'][kind]:.4f} tuned ({met[d['after']['meets_target']]}); "
            f"{d['metric']} {d['before']['objective']:.4f} -> {d['after']['objective']:.4f} ({gain:+.4f})"
        )
    else:
        lines.append(f"{d['metric']}: {d['before']['objective']:.4f} -> {d['after']['objective']:.4f} ({gain:+.4f})")
    if "meets_target" in d["after"] and not d["after"]["meets_target"]:
        lines.append(f"note: the target {d['objective']} is met on the tuning frames but not on the held-out frames")
    if d["kept"]:
        lines.append(
            f"kept the stored threshold {d['current']['stored_threshold']:.8g}: the new {d['threshold']:.8g} is not better "
            f"on the {'tuning' if d['in_sample'] else 'held-out'} frames"
            + (f"; copy with the stored threshold written to {d['written']}" if d.get("written") else "; no model written")
        )
    elif d.get("written"):
        where = " (a user copy: the shipped model is never rewritten; use it with --model)" if d["destination"] == "user" else ""
        lines.append(f"wrote threshold into {d['written']}" + (f" (backup {d['backup']})" if d.get("backup") else "") + where)
    elif d.get("dry_run"):
        lines.append("dry run: no model written")
    if d.get("plot"):
        lines.append(f"precision-recall curve: {d['plot']}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    args = parser.parse_args(argv)

    def body() -> int:
        from edge.commands import tune_model

        d = tune_model(
            args.data, args.model, objective=args.objective, split=args.split, seed=args.seed, out=args.out,
            dry_run=args.dry_run, plot=args.plot, pseudo_labels=args.pseudo_labels, pseudo_height=args.pseudo_height,
            depth_topic=args.depth_topic, labels_topic=args.labels_topic, depth_scale=args.depth_scale, limit=args.limit,
            threads=args.threads,
            wrap=lambda frames, total: progress(frames, total=total, desc="tune", unit="frame"),
        )
        if args.json:
            print_json(d)
        else:
            print(format_report(d))
        return 0

    return run(PROG, body, parser)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
