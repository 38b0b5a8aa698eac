"""``depthseg-tune``: choose a model's decision boundary from data and store it in the model."""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from pathlib import Path

from edge.cliutil import add_version, print_json, progress, run
from edge.io import TOPIC_DEPTH, TOPIC_LABELS, Frame
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
        "0.5 and at the chosen threshold."
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
                    help="write the tuned model here (same type); default: rewrite --model in place after a .bak copy")
parser.add_argument("--dry-run", action="store_true", help="report only; write nothing into any model")
parser.add_argument("--json", action="store_true", help="print one JSON object instead of the text report")
parser.add_argument("--plot", metavar="PR.png", default=None,
                    help="write a precision-recall curve with the 0.5 and the chosen points marked")
parser.add_argument(
    "--pseudo-labels", action="store_true",
    help="for an unlabelled recording: tune against geometric pseudo-labels (RANSAC floor plane + height "
    "threshold, as depthseg-eval --baseline) instead of ground truth; reported and stored as such",
)
parser.add_argument("--pseudo-height", type=float, default=0.008, metavar="M",
                    help="pseudo-labels: height above the plane that counts as object, metres (default 0.008)")
parser.add_argument("--depth-topic", default=None, help=f"depth Image topic (default: {TOPIC_DEPTH}, else auto-detected)")
parser.add_argument("--labels-topic", default=None, help=f"label Image topic (default: {TOPIC_LABELS}, else auto-detected)")
parser.add_argument("--depth-scale", type=float, default=1.0, metavar="S", help="multiply decoded depth by S (0.001: millimetres stored as 32FC1; default 1)")
parser.add_argument("--limit", type=int, default=None, metavar="N", help="use at most N frames")
parser.add_argument("--threads", type=int, default=2, metavar="N", help="inference threads (default 2)")


def open_frames(path: str, depth_topic: str | None, labels_topic: str | None, pseudo: bool, depth_scale: float = 1.0) -> tuple[Iterator[Frame], int | None]:
    """Frames of every recording in PATH through `edge.io.open_frames` (labelled, or depth only for pseudo-labels)."""
    from edge.errors import DataError
    from edge.io import open_frames as open_recordings

    if pseudo:
        return open_recordings(path, depth_topic, labels_topic="", depth_scale=depth_scale)
    try:
        return open_recordings(path, depth_topic, labels_topic, require_labels=True, depth_scale=depth_scale)
    except DataError as exc:
        if "no labels found" not in str(exc):
            raise
        raise DataError(f"{exc}, or tune against geometric pseudo-labels with `pseudo_labels`") from None


def _model_paths(model: str | None) -> tuple[Path, list[Path]]:
    """(model to tune, other files to store the result in).

    Without --model the shipped default is tuned: its ONNX file when present (what replay and
    bench run), and the threshold is stored in both of its files (checkpoint and ONNX export of
    the same weights), so every tool agrees.
    """
    from edge.defaults import default_models, resolve_model

    if model is not None:
        return resolve_model(model), []
    present = default_models(("onnx", "pt"))
    if not present:
        return resolve_model(None), []  # raises the one-line "default model missing" error
    return present[0], present[1:]


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
    lines.append(f"{where}: per-frame means")
    lines.append(f"  {'':<16} {'threshold':<12} {'IoU':>7} {'precision':>9} {'recall':>7} {'F1':>7} {'pooled IoU':>10}")
    lines.append(_fmt_point("before (0.5)", d["before"], d["metric"]))
    lines.append(_fmt_point("after (tuned)", d["after"], d["metric"]))
    gain = d["after"]["objective"] - d["before"]["objective"]
    if "meets_target" in d["after"]:
        kind = d["objective"].split(">=")[0]
        met = {True: "met", False: "NOT met"}
        lines.append(
            f"target {d['objective']}: {kind} {d['before'][kind]:.4f} at 0.5 ({met[d['before']['meets_target']]}), "
            f"{d['after'][kind]:.4f} tuned ({met[d['after']['meets_target']]}); "
            f"{d['metric']} {d['before']['objective']:.4f} -> {d['after']['objective']:.4f} ({gain:+.4f})"
        )
    else:
        lines.append(f"{d['metric']}: {d['before']['objective']:.4f} -> {d['after']['objective']:.4f} ({gain:+.4f})")
    if "meets_target" in d["after"] and not d["after"]["meets_target"]:
        lines.append(f"note: the target {d['objective']} is met on the tuning frames but not on the held-out frames")
    if d.get("written"):
        lines.append(f"wrote threshold into {d['written']}" + (f" (backup {d['backup']})" if d.get("backup") else ""))
        for w in d.get("also_written", []):
            lines.append(f"wrote threshold into {w['written']}" + (f" (backup {w['backup']})" if w.get("backup") else ""))
    elif d.get("dry_run"):
        lines.append("dry run: no model written")
    if d.get("plot"):
        lines.append(f"precision-recall curve: {d['plot']}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    args = parser.parse_args(argv)

    def body() -> int:
        from edge.errors import ConfigError
        from edge.predict import load_predictor
        from edge.train.threshold_store import store_threshold
        from edge.tune import heldout_assigner, parse_objective, plot_pr_curve, pseudo_labeller, tune

        # Check every option before the (slow) pass over the frames.
        objective = parse_objective(args.objective)
        objective.check_attainable()
        heldout_assigner(args.split, args.seed)
        if args.threads < 1:
            raise ConfigError(f"--threads must be >= 1, got {args.threads}")
        if args.limit is not None and args.limit < 1:
            raise ConfigError(f"--limit must be >= 1 frame, got {args.limit}")
        if args.pseudo_height <= 0:
            raise ConfigError(f"--pseudo-height must be > 0 m, got {args.pseudo_height}")
        model_path, siblings = _model_paths(args.model)
        if args.out is not None and not args.dry_run:
            out = Path(args.out)
            if out.suffix.lower() != model_path.suffix.lower():
                raise ConfigError(f"--out {out}: must have the model's type ({model_path.suffix}), got '{out.suffix}'")
            if not out.parent.exists():
                raise ConfigError(f"--out {out}: directory {out.parent} does not exist")
        if args.plot is not None and not Path(args.plot).parent.exists():
            raise ConfigError(f"--plot {args.plot}: directory {Path(args.plot).parent} does not exist")

        pseudo = None
        frames, total = open_frames(args.data, args.depth_topic, args.labels_topic, args.pseudo_labels, args.depth_scale)
        predictor = load_predictor(model_path, threads=args.threads)
        if args.pseudo_labels:
            pseudo = pseudo_labeller(args.pseudo_height, seed=args.seed, sensor=predictor.meta.sensor)
            labels = f"pseudo-labels: RANSAC floor plane + {1000 * args.pseudo_height:g} mm height (edge.baseline)"
        else:
            labels = "ground truth labels" + (f" ({args.labels_topic})" if args.labels_topic else "")
        if args.limit is not None and total is not None:
            total = min(total, args.limit)
        with progress(frames, total=total, desc="tune", unit="frame") as bar:
            result = tune(
                predictor, bar, objective, split=args.split, seed=args.seed, limit=args.limit,
                pseudo_labels=pseudo, labels_name=labels,
                no_labels_hint="no label matched a depth frame; check --labels-topic, or use --pseudo-labels",
            )
        d = result.to_dict()
        policy = result.policy(Path(args.data).name)
        d["policy"] = policy
        d["dry_run"] = bool(args.dry_run)
        if not args.dry_run:
            written, backup, _ = store_threshold(model_path, result.threshold, policy, out=args.out)
            d["written"] = str(written)
            d["backup"] = str(backup) if backup else None
            if args.out is None:
                for other in siblings:  # the shipped default's other file: same weights, same boundary
                    w2, b2, _ = store_threshold(other, result.threshold, policy)
                    d.setdefault("also_written", []).append({"written": str(w2), "backup": str(b2) if b2 else None})
        if args.plot is not None:
            d["plot"] = str(plot_pr_curve(result, args.plot))
        if args.json:
            print_json(d)
        else:
            print(format_report(d))
        return 0

    return run(PROG, body, parser)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
