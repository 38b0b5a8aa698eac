"""Segmentation scores as the paper defines them (III.E.f), over valid pixels only.

Why valid pixels only: an invalid pixel (0, negative, NaN, inf depth) carries no measurement, so
its prediction means nothing; padding never reaches the metrics because predictions are cropped
back to H x W before scoring. The paper averages the per-frame scores over the test set; we do
the same and also keep the pooled confusion counts (one IoU over all pixels of all frames),
which large objects dominate and which is harder to game with many empty frames.

Conventions for the cases where a ratio is 0 / 0 (documented because they move the means):

=========================================  ======  =========  ======
frame (valid pixels)                        IoU     precision  recall
=========================================  ======  =========  ======
no object pixels, no object predicted       1       1          1
no object pixels, some predicted            0       0          1
objects present, none predicted             0       0          0
=========================================  ======  =========  ======

i.e. an empty prediction has precision 1 only when there was nothing to find, and recall is 1
whenever there was nothing to find. A frame with no valid pixel at all has no score: it is
counted in ``skipped`` and left out of the means (pixel accuracy would be 0 / 0 too).

A pixel is predicted object when sigmoid(logit) >= threshold (the paper: values under the
decision boundary are background, all others object); `predict_mask` compares logits with
logit(threshold) so no sigmoid is evaluated per pixel.

Numpy only: used by the edge tools (tune, replay) as well as evaluation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from edge.errors import ConfigError, DataError

__all__ = [
    "Confusion",
    "FrameScores",
    "MetricSummary",
    "MetricAccumulator",
    "threshold_logit",
    "predict_mask",
    "confusion",
    "frame_scores",
]


@dataclass(frozen=True)
class Confusion:
    """Pixel counts over the valid pixels of one frame (or pooled over many)."""

    tp: int = 0
    fp: int = 0
    fn: int = 0
    tn: int = 0

    @property
    def total(self) -> int:
        return self.tp + self.fp + self.fn + self.tn

    def __add__(self, other: Confusion) -> Confusion:
        return Confusion(self.tp + other.tp, self.fp + other.fp, self.fn + other.fn, self.tn + other.tn)


@dataclass(frozen=True)
class FrameScores:
    """The paper's four scores for one frame, as fractions in [0, 1]."""

    pixel_accuracy: float
    iou: float
    precision: float
    recall: float


def threshold_logit(threshold: float) -> float:
    """The logit whose sigmoid equals ``threshold`` (a decision boundary in (0, 1))."""
    t = float(threshold)
    if not 0.0 < t < 1.0:
        raise ConfigError(f"threshold must lie strictly between 0 and 1, got {threshold}")
    return math.log(t) - math.log1p(-t)


def predict_mask(logits: np.ndarray, threshold: float = 0.5) -> np.ndarray:
    """Boolean object mask: sigmoid(logits) >= threshold, evaluated as logits >= logit(threshold)."""
    return np.asarray(logits) >= threshold_logit(threshold)


def confusion(pred: np.ndarray, label: np.ndarray, valid: np.ndarray | None = None) -> Confusion:
    """TP/FP/FN/TN of a predicted object mask against labels (nonzero = object), valid pixels only."""
    pred = np.asarray(pred)
    label = np.asarray(label)
    if pred.shape != label.shape:
        raise DataError(f"prediction shape {pred.shape} differs from label shape {label.shape}")
    p = pred.astype(bool, copy=False)
    g = label.astype(bool, copy=False)
    if valid is not None:
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != label.shape:
            raise DataError(f"valid-mask shape {valid.shape} differs from label shape {label.shape}")
        p = p[valid]
        g = g[valid]
    n = int(p.size)
    tp = int(np.count_nonzero(p & g))
    npred = int(np.count_nonzero(p))
    ntrue = int(np.count_nonzero(g))
    fp = npred - tp
    fn = ntrue - tp
    return Confusion(tp=tp, fp=fp, fn=fn, tn=n - tp - fp - fn)


def frame_scores(c: Confusion) -> FrameScores | None:
    """Per-frame scores with the 0/0 conventions of the module docstring; None if no valid pixel."""
    if c.total == 0:
        return None
    acc = (c.tp + c.tn) / c.total
    has_obj = (c.tp + c.fn) > 0
    union = c.tp + c.fp + c.fn
    iou = c.tp / union if union else 1.0
    npred = c.tp + c.fp
    precision = c.tp / npred if npred else (0.0 if has_obj else 1.0)
    recall = c.tp / (c.tp + c.fn) if has_obj else 1.0
    return FrameScores(pixel_accuracy=acc, iou=iou, precision=precision, recall=recall)


@dataclass(frozen=True)
class MetricSummary:
    """Means of the per-frame scores (the paper's numbers) plus pooled scores over all pixels."""

    frames: int  # frames scored (with at least one valid pixel)
    pixel_accuracy: float
    iou: float
    precision: float
    recall: float
    pooled_iou: float
    pooled: Confusion
    skipped: int = 0  # frames without any valid pixel

    def to_dict(self) -> dict[str, float | int]:
        """Fractions in [0, 1] under the keys the ``--json`` output uses."""
        return {
            "frames": self.frames,
            "pixel_accuracy": self.pixel_accuracy,
            "iou": self.iou,
            "precision": self.precision,
            "recall": self.recall,
            "pooled_iou": self.pooled_iou,
            "skipped_frames": self.skipped,
            "pooled_counts": {"tp": self.pooled.tp, "fp": self.pooled.fp, "fn": self.pooled.fn, "tn": self.pooled.tn},
        }


class MetricAccumulator:
    """Streaming mean of per-frame scores and pooled counts: constant memory for any test set."""

    def __init__(self) -> None:
        self.frames = 0
        self.skipped = 0
        self._sums = [0.0, 0.0, 0.0, 0.0]
        self.pooled = Confusion()

    def add_confusion(self, c: Confusion) -> FrameScores | None:
        s = frame_scores(c)
        if s is None:
            self.skipped += 1
            return None
        self.frames += 1
        for i, v in enumerate((s.pixel_accuracy, s.iou, s.precision, s.recall)):
            self._sums[i] += v
        self.pooled = self.pooled + c
        return s

    def add(self, pred: np.ndarray, label: np.ndarray, valid: np.ndarray | None = None) -> FrameScores | None:
        """Score one frame and fold it in; returns its scores (None when it has no valid pixel)."""
        return self.add_confusion(confusion(pred, label, valid))

    def summary(self) -> MetricSummary:
        if self.frames == 0:
            raise DataError(
                f"no frame could be scored ({self.skipped} frames had no valid pixel); "
                "check that the depth topic holds metres with valid pixels > 0"
            )
        n = self.frames
        acc, iou, prec, rec = (s / n for s in self._sums)
        p = self.pooled
        union = p.tp + p.fp + p.fn
        pooled_iou = p.tp / union if union else 1.0
        return MetricSummary(
            frames=n,
            pixel_accuracy=acc,
            iou=iou,
            precision=prec,
            recall=rec,
            pooled_iou=pooled_iou,
            pooled=p,
            skipped=self.skipped,
        )
