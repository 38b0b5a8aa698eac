"""Score a model (and optionally the RANSAC baseline) on labelled depth frames, streaming.

Why streaming: a test set of thousands of frames must not be held in memory; `evaluate` pulls
one frame at a time from any iterable of `edge.io.Frame` and keeps only running sums
(`edge.metrics.MetricAccumulator`, `edge.metrics.BreakdownAccumulator`) plus at most
``max_figures`` frames for the figures.
Predictions are thresholded at the model's stored decision boundary unless told otherwise, the
way the model will be used; scores count valid pixels only. Model and baseline get the same
three scores: the paper's (plain), where their errors lie relative to the true object boundaries
(the breakdown of the pooled union), and optionally the plain scores again with a void band
around the true boundaries left out (``ignore_boundary``), always in addition to, never instead
of, the plain ones.

Figures follow the paper's Fig. 5: (a) the preprocessed input, (b) the ground truth, (c) the
prediction coloured grey = correct background, white = correct object, blue = missed object
(wrong background prediction), red = false object (wrong object prediction); invalid pixels
are drawn in dark violet everywhere, since they are not scored. With the baseline a fourth
panel shows its prediction in the same colours.
"""

from __future__ import annotations

import heapq
import re
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from edge.baseline import PlaneBaseline, intrinsics_for
from edge.errors import ConfigError, DataError
from edge.infer import Predictor, checked_logits
from edge.io import Frame, write_bytes_atomic
from edge.meta import ModelMeta
from edge.metrics import (
    BreakdownAccumulator,
    ErrorBreakdown,
    FrameScores,
    MetricAccumulator,
    MetricSummary,
    boundary_band,
    confusion,
    frame_scores,
    object_mask,
    threshold_logit,
)
from edge.postprocess import check_min_height, check_min_px, support_height
from edge.preprocess import standardize, valid_for, valid_mask

__all__ = ["EvalReport", "evaluate", "render_figure", "COLORS", "model_label", "declared_labels", "labels_line_mm"]

MAX_DECLARED = 4  # distinct label descriptions kept from a recording (memory stays bounded)
MAX_DECLARED_CHARS = 200


def declared_labels(scene: dict[str, Any] | None) -> str | None:
    """What a frame's scene record says its labels are, if it says (else None).

    ``depthseg-sim import ply --label-above-plane`` writes it under ``params.labels``,
    `tools/relabel_geometric.py` under ``labels``; simulated frames say nothing (their labels are
    the simulator's: every pixel of an object).

    Args:
        scene: the frame's ``/depthseg/scene`` record (`edge.io.Frame.scene`).
    """
    if not isinstance(scene, dict):
        return None
    params = scene.get("params")
    text = scene.get("labels", params.get("labels") if isinstance(params, dict) else None)
    return " ".join(text.split())[:MAX_DECLARED_CHARS] if isinstance(text, str) and text.strip() else None


def labels_line_mm(text: str) -> float | None:
    """The line of a geometric label description ("geometric: > 10 mm above ..." -> 10.0), else None."""
    m = re.match(r"geometric: > ([0-9]+(?:\.[0-9]+)?) mm above", text)
    return float(m.group(1)) if m else None


# RGB
COLORS: dict[str, tuple[int, int, int]] = {
    "correct background": (128, 128, 128),
    "correct object": (255, 255, 255),
    "missed object": (0, 90, 255),
    "false object": (230, 30, 30),
    "invalid": (60, 0, 80),
}
FIGURE_PICKS = ("first", "worst")
DEFAULT_BOUNDARY_PX = 2


@dataclass
class EvalReport:
    """What `evaluate` measured; `to_dict` is the ``depthseg-eval --json`` object."""

    model: str
    threshold: float
    metrics: MetricSummary
    min_object_px: int = 0  # the speck rule applied to the model's masks (edge.postprocess)
    min_height_m: float = 0.0  # the height rule applied to them (edge.postprocess.remove_low_parts); 0 = off
    labels_declared: list[str] = field(default_factory=list)  # what the recording says its labels are (`declared_labels`)
    baseline: MetricSummary | None = None
    baseline_params: dict[str, Any] | None = None
    unlabelled: int = 0
    figures: list[Path] = field(default_factory=list)
    breakdown: ErrorBreakdown | None = None
    baseline_breakdown: ErrorBreakdown | None = None
    ignore_boundary_px: int | None = None  # void band width when --ignore-boundary was asked for
    ignore_boundary: MetricSummary | None = None  # None also when no frame had a pixel outside the band
    baseline_ignore_boundary: MetricSummary | None = None
    meta: ModelMeta | None = None  # the model's metadata (not in `to_dict`: the model file has it)

    @property
    def frames(self) -> int:
        return self.metrics.frames

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"model": self.model, "threshold": self.threshold, "min_object_px": self.min_object_px,
                             "min_height_m": self.min_height_m,
                             "labels_declared": list(self.labels_declared), "unlabelled_frames": self.unlabelled}
        d.update(self.metrics.to_dict())
        self._add_extra_scores(d, self.breakdown, self.ignore_boundary)
        if self.baseline is not None:
            b = self.baseline.to_dict()
            params = dict(self.baseline_params or {})
            b["method"] = "ransac-plane-height"
            b["threshold"] = params.get("height_threshold_m")  # metres above the fitted plane
            b.update(params)
            self._add_extra_scores(b, self.baseline_breakdown, self.baseline_ignore_boundary)
            d["baseline"] = b
        if self.figures:
            d["figures"] = [str(p) for p in self.figures]
        return d

    def _add_extra_scores(self, d: dict[str, Any], bd: ErrorBreakdown | None, ign: MetricSummary | None) -> None:
        """``breakdown`` and ``ignore_boundary`` keys of one method (model or baseline), in place."""
        if bd is not None:
            d["breakdown"] = bd.to_dict()
        if self.ignore_boundary_px is not None:
            d["ignore_boundary"] = {"px": self.ignore_boundary_px, **(ign.to_dict() if ign is not None else {"frames": 0})}


class _MethodScores:
    """The streaming scores of one method (model or baseline) over the frames: plain, breakdown, void band."""

    def __init__(self, boundary_px: int, ignore_px: int | None) -> None:
        self.plain = MetricAccumulator()
        self.breakdown = BreakdownAccumulator(boundary_px)
        self.ignored = MetricAccumulator() if ignore_px is not None else None

    def add(self, pred: np.ndarray, label: np.ndarray, valid: np.ndarray, outside_void: np.ndarray | None) -> FrameScores | None:
        s = self.plain.add(pred, label, valid)
        self.breakdown.add(pred, label, valid)
        if self.ignored is not None and outside_void is not None:
            self.ignored.add(pred, label, outside_void)
        return s

    def ignored_summary(self) -> MetricSummary | None:
        return self.ignored.summary() if self.ignored is not None and self.ignored.frames else None


def model_label(meta: ModelMeta | None) -> str:
    if meta is None:
        return "model"
    return f"FCN-8s {meta.encoder}{'_bn' if meta.batch_norm and not meta.encoder.endswith('_bn') else ''} x{meta.width:g}"


def _overlay(pred: np.ndarray | None, label: np.ndarray, valid: np.ndarray) -> np.ndarray:
    g = label.astype(bool)
    img = np.empty(label.shape + (3,), np.uint8)
    if pred is None:  # ground-truth panel
        img[:] = COLORS["correct background"]
        img[g] = COLORS["correct object"]
    else:
        p = pred.astype(bool)
        img[~p & ~g] = COLORS["correct background"]
        img[p & g] = COLORS["correct object"]
        img[~p & g] = COLORS["missed object"]
        img[p & ~g] = COLORS["false object"]
    img[~valid] = COLORS["invalid"]
    return img


def _input_panel(depth: np.ndarray, valid: np.ndarray) -> np.ndarray:
    z, _, _ = standardize(depth, valid)
    g = np.zeros(z.shape, np.uint8)
    if valid.any():  # near = bright, contrast stretched over the 1st-99th percentile of valid pixels
        lo, hi = np.percentile(z[valid], [1.0, 99.0])
        g = np.clip((hi - z) / max(hi - lo, 1e-6) * 255.0, 0, 255).astype(np.uint8)
    img = np.repeat(g[..., None], 3, axis=2)
    img[~valid] = COLORS["invalid"]
    return img


def render_figure(
    depth: np.ndarray,
    label: np.ndarray,
    pred: np.ndarray,
    baseline_pred: np.ndarray | None = None,
    title: str = "",
    scale: int = 2,
) -> np.ndarray:
    """The Fig. 5 style panel row as an RGB uint8 image (input | ground truth | prediction [| baseline])."""
    import cv2

    valid = valid_mask(depth)
    panels = [("(a) input (standardised)", _input_panel(depth, valid)), ("(b) ground truth", _overlay(None, label, valid))]
    s = frame_scores(confusion(pred, label, valid))
    iou = f" IoU {100 * s.iou:.1f}%" if s else ""
    panels.append((f"(c) prediction{iou}", _overlay(pred, label, valid)))
    if baseline_pred is not None:
        sb = frame_scores(confusion(baseline_pred, label, valid))
        panels.append((f"(d) RANSAC baseline{f' IoU {100 * sb.iou:.1f}%' if sb else ''}", _overlay(baseline_pred, label, valid)))
    h, w = depth.shape
    ph, pw = h * scale, w * scale
    head, gap, foot = 22, 8, 24
    canvas = np.full((head + ph + foot + (18 if title else 0), len(panels) * (pw + gap) + gap, 3), 255, np.uint8)
    top = 18 if title else 0
    font = cv2.FONT_HERSHEY_SIMPLEX
    if title:
        cv2.putText(canvas, title, (gap, 14), font, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    for i, (name, img) in enumerate(panels):
        x0 = gap + i * (pw + gap)
        big = cv2.resize(img, (pw, ph), interpolation=cv2.INTER_NEAREST)
        canvas[top + head : top + head + ph, x0 : x0 + pw] = big
        cv2.putText(canvas, name, (x0, top + head - 6), font, 0.42, (0, 0, 0), 1, cv2.LINE_AA)
    x = gap
    y = top + head + ph + 6
    for name, col in COLORS.items():
        cv2.rectangle(canvas, (x, y), (x + 12, y + 12), col, -1)
        cv2.rectangle(canvas, (x, y), (x + 12, y + 12), (0, 0, 0), 1)
        cv2.putText(canvas, name, (x + 16, y + 11), font, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
        x += 16 + cv2.getTextSize(name, font, 0.4, 1)[0][0] + 14
    return canvas


def _write_png(path: Path, rgb: np.ndarray) -> Path:
    import cv2

    ok, buf = cv2.imencode(".png", np.ascontiguousarray(rgb[..., ::-1]))
    if not ok:  # pragma: no cover - cv2 fails only on absurd inputs
        raise DataError(f"{path}: could not encode the figure as PNG")
    return write_bytes_atomic(path, buf.tobytes())


def evaluate(
    predictor: Predictor,
    frames: Iterable[Frame],
    threshold: float | None = None,
    baseline: bool | PlaneBaseline = False,
    figures_dir: str | Path | None = None,
    max_figures: int = 8,
    figure_pick: str = "first",
    limit: int | None = None,
    boundary_px: int = DEFAULT_BOUNDARY_PX,
    ignore_boundary: int | None = None,
    min_object_px: int | None = None,
    min_height_m: float | None = None,
) -> EvalReport:
    """Stream ``frames`` through ``predictor`` and score them (frames without labels are counted, not scored).

    ``threshold`` defaults to the model's stored decision boundary (``meta.threshold``), else
    0.5. ``baseline`` (True or a configured `PlaneBaseline`) scores the RANSAC plane baseline on
    the same frames. ``figure_pick`` chooses which frames get a figure: the ``first`` ones or the
    ``worst`` by IoU (kept in a bounded heap, so memory stays constant). ``limit`` stops after
    that many labelled frames. ``boundary_px`` is the band around true object boundaries that
    splits the errors into the breakdown (`edge.metrics.boundary_band`); ``ignore_boundary``
    (pixels, or None for off) adds a second set of scores with a void band of that width around
    the true boundaries left out, PASCAL VOC style. ``min_object_px`` defaults to the model's
    speck rule (``meta.min_object_px``; `edge.postprocess`), else 0 (every object pixel kept);
    ``min_height_m`` likewise to the model's height rule (``meta.min_height_m``), else 0 (off).
    The plane fit is scored as it is, whatever the model's rules.
    """
    meta = getattr(predictor, "meta", None)
    if threshold is None:
        threshold = float(meta.threshold) if meta is not None else 0.5
    threshold_logit(threshold)  # checks it lies in (0, 1) before any frame is run
    if min_object_px is None:
        min_object_px = meta.min_object_px if meta is not None else 0
    min_object_px = check_min_px(min_object_px)  # before any frame is run
    if min_height_m is None:
        min_height_m = meta.min_height_m if meta is not None else 0.0
    min_height_m = check_min_height(min_height_m)
    if figure_pick not in FIGURE_PICKS:
        raise ConfigError(f"unknown figure pick '{figure_pick}'; choose from {', '.join(FIGURE_PICKS)}")
    if max_figures < 0:
        raise ConfigError(f"`max_figures` must be >= 0, got {max_figures}")
    if limit is not None and limit < 1:
        raise ConfigError(f"`limit` must be >= 1 frame, got {limit}")
    base = PlaneBaseline() if baseline is True else (baseline or None)
    fig_dir = Path(figures_dir) if figures_dir is not None else None
    if fig_dir is not None:
        fig_dir.mkdir(parents=True, exist_ok=True)
    sensor = meta.sensor if meta is not None else None

    if ignore_boundary is not None:
        boundary_band(np.zeros((1, 1), bool), ignore_boundary)  # fail on a bad width before any inference
    acc = _MethodScores(boundary_px, ignore_boundary)
    bacc = _MethodScores(boundary_px, ignore_boundary) if base is not None else None
    unlabelled = 0
    declared: list[str] = []
    seen = 0
    figures: list[Path] = []
    worst: list[tuple[float, int, tuple]] = []  # min-heap on -iou: the worst frames so far

    def fig_title(i: int, fr: Frame) -> str:
        src = f"{model_label(meta)} @ {threshold:g}"
        return f"frame {i} (t={fr.stamp_ns} ns) - {src}"

    for fr in frames:
        if fr.label is None:
            unlabelled += 1
            continue
        said = declared_labels(fr.scene)
        if said is not None and said not in declared and len(declared) < MAX_DECLARED:
            declared.append(said)
        depth = np.asarray(fr.depth)
        label = np.asarray(fr.label)
        if label.shape != depth.shape:
            raise DataError(f"frame at t={fr.stamp_ns} ns: label shape {label.shape} differs from depth shape {depth.shape}")
        valid = valid_mask(depth)
        logits = checked_logits(predictor, depth)
        # the plane as the model's own preprocessing fits it (its sensor range), as `Segmenter` does
        height = support_height(depth, valid_for(depth, meta) if meta is not None else valid) if min_height_m > 0 else None
        pred = object_mask(logits, valid, threshold, min_object_px, height, min_height_m)
        outside_void = valid & ~boundary_band(label, ignore_boundary) if ignore_boundary is not None else None
        s = acc.add(pred, label, valid, outside_void)
        bpred = None
        if base is not None and bacc is not None:
            bpred = base.predict(depth, intrinsics_for(depth.shape, fr.info, sensor))
            bacc.add(bpred, label, valid, outside_void)
        i = seen
        seen += 1
        if fig_dir is not None and max_figures > 0 and s is not None:
            if figure_pick == "first" and len(figures) < max_figures:
                figures.append(_write_png(fig_dir / f"frame_{i:06d}.png", render_figure(depth, label, pred, bpred, fig_title(i, fr))))
            elif figure_pick == "worst":
                item = (-s.iou, -i, (depth.copy(), label.copy(), pred, bpred, fig_title(i, fr)))
                if len(worst) < max_figures:
                    heapq.heappush(worst, item)
                elif item[:2] > worst[0][:2]:
                    heapq.heapreplace(worst, item)
        if limit is not None and seen >= limit:
            break

    if seen == 0:
        raise DataError(
            f"no labelled frames to evaluate ({unlabelled} frames without labels); "
            "point `data` at MCAP files with a label topic, or name it with `labels_topic`"
        )
    for _, neg_i, (depth, label, pred, bpred, title) in sorted(worst, reverse=True):  # worst first
        path = Path(fig_dir or ".") / f"worst_{-neg_i:06d}.png"
        figures.append(_write_png(path, render_figure(depth, label, pred, bpred, title)))
    return EvalReport(
        model=getattr(predictor, "name", "model"),
        threshold=float(threshold),
        min_object_px=min_object_px,
        min_height_m=min_height_m,
        labels_declared=declared,
        metrics=acc.plain.summary(),
        baseline=bacc.plain.summary() if bacc is not None else None,
        baseline_params=asdict(base) if base is not None else None,
        unlabelled=unlabelled,
        figures=figures,
        breakdown=acc.breakdown.summary(),
        baseline_breakdown=bacc.breakdown.summary() if bacc is not None else None,
        ignore_boundary_px=ignore_boundary,
        ignore_boundary=acc.ignored_summary(),
        baseline_ignore_boundary=bacc.ignored_summary() if bacc is not None else None,
    )
