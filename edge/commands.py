"""The library behind ``depthseg-eval`` and ``depthseg-tune``: one typed call each.

Why a module of its own: a command is more than its algorithm (`edge.evaluate.evaluate`,
`edge.tune.tune`, both torch-free): it picks the model file (the shipped ONNX by default), checks
every path before any work (`edge.io.paths`: no FIFO as an input, no output on an input, nothing
written into the installed package), checks the optional modules it will need
(`edge.cliutil.require`), and for tune decides where the result may be written. That needs
`edge.predict` (a ``.pt`` model loads through `edge.train`), which the torch-free modules must not
import, so the glue lives here and the CLIs only parse, call, and print.

Messages name parameters in backticks (``"`out`"``); the CLIs turn them into flags.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

from edge.cliutil import require
from edge.defaults import SUFFIXES, is_shipped_model, resolve_model, user_models_dir
from edge.errors import ConfigError, DataError
from edge.evaluate import DEFAULT_BOUNDARY_PX, EvalReport, evaluate
from edge.io import Frame
from edge.io.paths import check_input_file, check_output_dir, check_outputs

__all__ = ["evaluate_model", "tune_model", "model_file"]

Wrap = Callable[[Iterable[Frame], int | None], Iterable[Frame]]  # (frames, total) -> frames, e.g. a progress bar


def _is_pt(path: Path) -> bool:
    return path.suffix.lower() in SUFFIXES["pt"]


def model_file(model: str | Path | None) -> Path:
    """The model file to use: ``model`` checked as an input (no FIFO, no directory), or the shipped ONNX default."""
    path = resolve_model(model, kinds=("onnx", "pt"))  # the model-specific message when it is missing
    if model is not None:
        check_input_file(path, "model")
    return path


def _frames(wrap: Wrap | None, frames: Iterator[Frame], total: int | None, limit: int | None) -> Iterable[Frame]:
    if limit is not None and total is not None:
        total = min(total, limit)
    return wrap(frames, total) if wrap is not None else frames


def evaluate_model(
    data: str | Path,
    model: str | Path | None = None,
    *,
    threshold: float | None = None,
    baseline: Any = None,
    figures: str | Path | None = None,
    max_figures: int = 8,
    figures_pick: str = "first",
    depth_topic: str | None = None,
    labels_topic: str | None = None,
    depth_scale: float = 1.0,
    limit: int | None = None,
    threads: int = 2,
    boundary_px: int = DEFAULT_BOUNDARY_PX,
    ignore_boundary: int | None = None,
    min_object_px: int | None = None,
    min_height_m: float | None = None,
    wrap: Wrap | None = None,
) -> EvalReport:
    """Score ``model`` (default: the shipped ONNX, no torch) on the labelled recordings in ``data``.

    Args:
        data: a recording or a directory of them.
        model: .onnx or .pt file; None = the shipped default.
        threshold: decision boundary (None: the model's stored one).
        baseline: an `edge.baseline.PlaneBaseline` to score beside the model (needs open3d), or None.
        figures: directory for PNG overlays (created), or None.
        max_figures, figures_pick, limit, boundary_px, ignore_boundary, min_object_px, min_height_m:
            as `edge.evaluate.evaluate`.
        depth_topic, labels_topic: topics (None: detected).
        depth_scale: multiply decoded depth by this (0.001: millimetres stored as 32FC1).
        threads: inference threads.
        wrap: ``wrap(frames, total)`` around the frame stream (a progress bar).

    Returns:
        The `EvalReport` (its ``meta`` is the model's metadata).

    Raises:
        ConfigError, DataError, ModelError, MissingExtraError: one line each, before any frame is
        run where the cause is known up front.
    """
    from edge.predict import load_predictor

    if threads < 1:
        raise ConfigError(f"`threads` must be >= 1, got {threads}")
    model_path = model_file(model)
    check_input_file(data, "data", allow_dir=True)
    check_output_dir(figures, "figures", {"model": model_path, "data": data}, probes=("frame_000000.png",))
    if _is_pt(model_path):
        require("train", ("torch",), f"the checkpoint {model_path.name}")
    if baseline:
        require("sim", ("open3d",), "the plane baseline (`baseline`)")
    from edge.io import open_frames

    # the scene records say what the labels mean, when a recording says it (`edge.evaluate.declared_labels`)
    frames, total = open_frames(data, depth_topic, labels_topic, require_labels=True, depth_scale=depth_scale,
                                extras=("scene",))
    predictor = load_predictor(model_path, threads=threads)
    report = evaluate(
        predictor, _frames(wrap, frames, total, limit), threshold=threshold, baseline=baseline or False,
        figures_dir=figures, max_figures=max_figures, figure_pick=figures_pick, limit=limit,
        boundary_px=boundary_px, ignore_boundary=ignore_boundary, min_object_px=min_object_px,
        min_height_m=min_height_m,
    )
    report.meta = predictor.meta
    return report


def _tune_frames(data, depth_topic, labels_topic, pseudo: bool, depth_scale: float = 1.0):
    from edge.io import open_frames

    if pseudo:
        return open_frames(data, depth_topic, labels_topic="", depth_scale=depth_scale)
    try:
        return open_frames(data, depth_topic, labels_topic, require_labels=True, depth_scale=depth_scale)
    except DataError as exc:
        if "no labels found" not in str(exc):
            raise
        raise DataError(f"{exc}, or tune against geometric pseudo-labels with `pseudo_labels`") from None


def tune_destination(model_path: Path, out: str | Path | None, dry_run: bool) -> tuple[Path | None, str]:
    """(file the tuned model goes to, why there): None for a dry run.

    ``out`` when given; a shipped model (the default, the fast option) is never rewritten: its tuned
    copy goes to `edge.defaults.user_models_dir`; any other model is rewritten in place (after a
    ``.bak`` copy).
    """
    if dry_run:
        return None, "dry run"
    if out is not None:
        return Path(out), "out"
    if is_shipped_model(model_path):
        return user_models_dir() / model_path.name, "user"
    return model_path, "in place"


def tune_model(
    data: str | Path,
    model: str | Path | None = None,
    *,
    objective: str = "iou",
    split: float = 0.25,
    seed: int = 0,
    out: str | Path | None = None,
    dry_run: bool = False,
    plot: str | Path | None = None,
    pseudo_labels: bool = False,
    pseudo_height: float = 0.008,
    depth_topic: str | None = None,
    labels_topic: str | None = None,
    depth_scale: float = 1.0,
    limit: int | None = None,
    threads: int = 2,
    wrap: Wrap | None = None,
) -> dict[str, Any]:
    """Choose a threshold for ``model`` on ``data`` and store it, unless the stored one is as good.

    The stored threshold is kept unless the new one is better on the held-out frames
    (`edge.tune.TuneResult.improves`); then only ``out`` is written (a copy carrying the stored
    threshold and a policy line saying it was kept), nothing in place. Where the result goes:
    `tune_destination` (``out``; for the shipped default without ``out`` a user directory,
    never the installed package; else the model in place after a ``.bak`` copy).

    Returns:
        The ``depthseg-tune --json`` object: `edge.tune.TuneResult.to_dict` plus ``policy``,
        ``dry_run``, ``kept``, ``written``, ``backup``, ``destination``, ``plot``.

    Raises:
        ConfigError, DataError, ModelError, ThresholdError, MissingExtraError: one line each;
        every option and path is checked before the pass over the frames.
    """
    from edge.tune import heldout_assigner, parse_objective, plot_pr_curve, pseudo_labeller, tune

    obj = parse_objective(objective)
    obj.check_attainable()
    heldout_assigner(split, seed)
    if threads < 1:
        raise ConfigError(f"`threads` must be >= 1, got {threads}")
    if limit is not None and limit < 1:
        raise ConfigError(f"`limit` must be >= 1 frame, got {limit}")
    if not pseudo_height > 0:
        raise ConfigError(f"`pseudo_height` must be > 0 m, got {pseudo_height}")
    model_path = model_file(model)
    check_input_file(data, "data", allow_dir=True)
    dest, why = tune_destination(model_path, out, dry_run)
    inputs = {"model": model_path, "data": data}
    if dest is not None and why != "in place":
        if dest.suffix.lower() != model_path.suffix.lower():
            raise ConfigError(f"`out` {dest}: must have the model's type ({model_path.suffix}), got '{dest.suffix}'")
        if why == "out" and not dest.parent.is_dir():
            raise ConfigError(f"`out` {dest}: directory {dest.parent} does not exist")
    if plot is not None and not Path(plot).parent.is_dir():
        raise ConfigError(f"`plot` {plot}: directory {Path(plot).parent} does not exist")
    check_outputs({"out": dest if why in ("out", "user") else None, "plot": plot}, inputs)
    if dest is not None and why == "in place":
        # rewriting in place: never inside the installed package; the plot never on the backup
        check_outputs({"model": model_path, "model_backup": model_path.with_name(model_path.name + ".bak")}, {})
        check_outputs({"plot": plot}, {"model": [model_path, model_path.with_name(model_path.name + ".bak")]})
    if _is_pt(model_path):
        require("train", ("torch",), f"the checkpoint {model_path.name}")
    elif dest is not None:
        require("train", ("onnx",), "writing the threshold into an ONNX model (or pass `dry_run`)")
    if plot is not None:
        require("train", ("matplotlib",), "the precision-recall plot (`plot`)")
    if pseudo_labels:
        require("sim", ("open3d",), "pseudo-labels (the plane baseline)")

    from edge.predict import load_predictor

    frames, total = _tune_frames(data, depth_topic, labels_topic, pseudo_labels, depth_scale)
    predictor = load_predictor(model_path, threads=threads)
    pseudo = None
    if pseudo_labels:
        pseudo = pseudo_labeller(pseudo_height, seed=seed, sensor=predictor.meta.sensor)
        labels = f"pseudo-labels: RANSAC floor plane + {1000 * pseudo_height:g} mm height (edge.baseline)"
    else:
        labels = "ground truth labels" + (f" ({labels_topic})" if labels_topic else "")
    result = tune(
        predictor, _frames(wrap, frames, total, limit), obj, split=split, seed=seed, limit=limit,
        pseudo_labels=pseudo, labels_name=labels,
        no_labels_hint="no label matched a depth frame; check `labels_topic`, or use `pseudo_labels`",
    )
    d = result.to_dict()
    policy = result.policy(Path(data).name)
    d.update(policy=policy, dry_run=bool(dry_run), kept=not result.improves, written=None, backup=None,
             destination=why)
    # `out` always gets a model (the better threshold); in place and the user copy only a change
    if dest is not None and (result.improves or why == "out"):
        from edge.train.threshold_store import store_threshold

        if why == "user":
            dest.parent.mkdir(parents=True, exist_ok=True)
        written, backup, _ = store_threshold(
            model_path, result.result_threshold, policy, out=None if why == "in place" else dest
        )
        d["written"] = str(written)
        d["backup"] = str(backup) if backup else None
    if plot is not None:
        d["plot"] = str(plot_pr_curve(result, plot))
    return d
