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

**The threshold rule** (the only one; `Segmenter`, replay, eval and tune all use it): a pixel is
predicted object when sigmoid(logit) >= threshold (the paper: values under the decision boundary
are background, all others object), evaluated as ``logit >= logit(threshold)``
(`threshold_logit`, `predict_mask`, `segmentation_mask`). Comparing float32 probabilities
instead gives other classes near extreme thresholds: at the paper's 0.9999 every logit above
about 16 is a probability of exactly 1 in float32. After the threshold, object specks under the
model's ``min_object_px`` become background (`object_mask`, `edge.postprocess`), and, when the
model asks for a ``min_height_m``, object pixels under that line above the support become table
in components reaching over it; tune chooses thresholds on the pixels before those rules. `UNKNOWN` (255) is the mask value of a pixel
without valid depth; `sigmoid` and `logit` are the one pair of conversions.

Where the errors are (`boundary_band`, `BreakdownAccumulator`): most disagreement between a
segmentation and its labels sits on the object outline, where a label is a matter of a pixel
either way, and that says something different about a model than a false blob in the middle of
the table or a whole missed object. So the pooled union (TP + FP + FN over valid pixels of all
frames) is split into TP and four error shares: false object (FP) and missed object (FN), each
within ``B`` px of a true object boundary ("boundary") or farther away ("far"). The five shares
sum to 1 and the TP share equals the pooled IoU, so the four error shares say how the pooled
IoU's shortfall from 1 divides up. The same band, as a void region excluded from scoring (the
way PASCAL VOC ignores a 5 px band around its outlines), gives `depthseg-eval --ignore-boundary`.

Numpy, and OpenCV's connected components for the speck rule (no torch): used by the edge tools
(tune, replay) as well as evaluation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from edge.errors import ConfigError, DataError
from edge.postprocess import check_min_height, remove_low_parts, remove_specks

__all__ = [
    "UNKNOWN",
    "sigmoid",
    "logit",
    "segmentation_mask",
    "object_mask",
    "Confusion",
    "FrameScores",
    "MetricSummary",
    "MetricAccumulator",
    "threshold_logit",
    "predict_mask",
    "confusion",
    "frame_scores",
    "boundary_band",
    "ErrorBreakdown",
    "BreakdownAccumulator",
]


UNKNOWN = 255  # mask value of invalid pixels: the sensor gave no range, so no class either
_LOGIT_CLIP = 80.0  # exp(80) is finite in float32; beyond it the sigmoid is 0 or 1 anyway
_PROB_EPS = 1e-7  # probabilities are clipped to [eps, 1 - eps] before their logit is taken


def sigmoid(x: np.ndarray | float) -> np.ndarray | float:
    """Logistic function without overflow warnings; float32 in -> float32 out, else float64.

    Args:
        x: logits (array or scalar); not modified.

    Returns:
        A new array of the same shape (a Python float for a scalar).
    """
    a = np.asarray(x)
    if a.dtype != np.float32:
        a = a.astype(np.float64)
    p = np.array(np.clip(a, -_LOGIT_CLIP, _LOGIT_CLIP), dtype=a.dtype)  # a new array, even for a scalar
    np.negative(p, out=p)
    np.exp(p, out=p)
    p += 1.0
    np.reciprocal(p, out=p)
    return p if p.ndim else float(p)


def logit(p: np.ndarray | float) -> np.ndarray | float:
    """Inverse of `sigmoid`, probabilities clipped to [1e-7, 1 - 1e-7]; float32 in -> float32 out."""
    a = np.asarray(p)
    if a.dtype != np.float32:
        a = a.astype(np.float64)
    a = np.clip(a, _PROB_EPS, 1.0 - _PROB_EPS)
    out = (np.log(a) - np.log1p(-a)).astype(a.dtype, copy=False)
    return out if out.ndim else float(out)


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
    """Boolean object mask: sigmoid(logits) >= threshold, evaluated as logits >= logit(threshold).

    The comparison is exact: float32 logits are compared with the smallest float32 not below the
    float64 logit(threshold), which decides every pixel as a float64 comparison would (NumPy would
    otherwise round the threshold to float32 and move pixels within one ulp of it), and as
    `edge.tune` does with its float64 grid.
    """
    t = threshold_logit(threshold)
    x = np.asarray(logits)
    if x.dtype == np.float32:
        c = np.float32(t)
        if float(c) < t:  # float(): NumPy would compare in float32 and never see the difference
            c = np.nextafter(c, np.float32(np.inf))
        return x >= c
    return x >= t


def object_mask(
    logits: np.ndarray,
    valid: np.ndarray,
    threshold: float = 0.5,
    min_object_px: int = 0,
    height_m: np.ndarray | None = None,
    min_height_m: float = 0.0,
) -> np.ndarray:
    """Boolean object mask a model reports: `predict_mask` on valid pixels, low parts and specks removed.

    Args:
        logits: float H x W.
        valid: bool H x W, pixels with a range; the others are never object.
        threshold: the decision boundary (a probability).
        min_object_px: object components (8-connected) with fewer pixels become background
            (`edge.postprocess.remove_specks`; ``ModelMeta.min_object_px``); 0 keeps all.
        height_m: float H x W metres above the support (`edge.postprocess.support_height`);
            needed when ``min_height_m`` > 0.
        min_height_m: object pixels below this height become table in components that reach
            above it (`edge.postprocess.remove_low_parts`; ``ModelMeta.min_height_m``); 0 = off.
    """
    obj = predict_mask(logits, threshold) & np.asarray(valid, dtype=bool)
    if check_min_height(min_height_m) > 0:
        if height_m is None:
            raise ConfigError("a minimum object height needs the heights above the support (`height_m`)")
        obj = remove_low_parts(obj, height_m, min_height_m)
    return remove_specks(obj, min_object_px)


def segmentation_mask(
    logits: np.ndarray,
    valid: np.ndarray,
    threshold: float = 0.5,
    min_object_px: int = 0,
    height_m: np.ndarray | None = None,
    min_height_m: float = 0.0,
) -> np.ndarray:
    """The uint8 mask a user sees: 1 object, 0 background (`object_mask`), `UNKNOWN` where not ``valid``."""
    obj = object_mask(logits, valid, threshold, min_object_px, height_m, min_height_m)  # False where not valid
    # UNKNOWN x not-valid + object, branch-free (a boolean assignment took 2x as long)
    mask = np.multiply((~np.asarray(valid, dtype=bool)).view(np.uint8), np.uint8(UNKNOWN))
    return np.bitwise_or(mask, obj.view(np.uint8), out=mask)


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


def _window_any(mask: np.ndarray, r: int) -> np.ndarray:
    """True where the (2r+1) x (2r+1) window around a pixel, clipped to the image, holds a True pixel.

    Separable (rows, then columns) over a False-padded copy, so pixels outside the image never count.
    """
    k = 2 * r + 1
    m = np.pad(mask, r, constant_values=False)
    m = np.lib.stride_tricks.sliding_window_view(m, k, axis=0).any(axis=-1)
    return np.lib.stride_tricks.sliding_window_view(m, k, axis=1).any(axis=-1)


def boundary_band(label: np.ndarray, px: int) -> np.ndarray:
    """Pixels within ``px`` px (chessboard distance) of a true object boundary pixel.

    A true boundary pixel is one whose 8-neighbourhood (inside the image) holds the other class
    of the ground truth (nonzero = object); the validity mask plays no part, so the band does not
    move with sensor dropouts. Boundary pixels lie on both sides of an outline, so the band spans
    ``px + 1`` pixels on each side of it (``px = 0``: just the two rings of boundary pixels). The
    image border is no boundary. Equivalently, a pixel is in the band when the
    (2 px + 3)-square window around it holds both classes, which is how it is computed.

    Args:
        label: H x W ground truth, nonzero = object.
        px: band half-width in pixels, >= 0.

    Returns:
        H x W bool mask, True inside the band (all False for a frame of one class only).

    Raises:
        ConfigError: ``px`` is negative or not an integer.
    """
    if isinstance(px, bool) or not isinstance(px, (int, np.integer)) or px < 0:
        raise ConfigError(f"boundary band width must be an integer >= 0 pixels, got {px!r}")
    g = np.asarray(label).astype(bool, copy=False)
    if g.ndim != 2:
        raise DataError(f"labels must be an H x W image, got shape {g.shape}")
    r = int(px) + 1
    return _window_any(g, r) & _window_any(~g, r)


@dataclass(frozen=True)
class ErrorBreakdown:
    """Pooled pixel counts of the union (TP + FP + FN), with the errors split by the boundary band."""

    boundary_px: int
    tp: int = 0
    fp_boundary: int = 0  # false object within the band
    fp_far: int = 0  # false object outside the band
    fn_boundary: int = 0  # missed object within the band
    fn_far: int = 0  # missed object outside the band

    @property
    def union(self) -> int:
        return self.tp + self.fp_boundary + self.fp_far + self.fn_boundary + self.fn_far

    def __add__(self, other: ErrorBreakdown) -> ErrorBreakdown:
        if other.boundary_px != self.boundary_px:
            raise ConfigError(f"cannot pool breakdowns of {self.boundary_px} px and {other.boundary_px} px bands")
        return ErrorBreakdown(
            self.boundary_px, tp=self.tp + other.tp, fp_boundary=self.fp_boundary + other.fp_boundary,
            fp_far=self.fp_far + other.fp_far, fn_boundary=self.fn_boundary + other.fn_boundary,
            fn_far=self.fn_far + other.fn_far,
        )

    def shares(self) -> dict[str, float]:
        """Each count as a fraction of the union; they sum to 1 and ``tp`` is the pooled IoU.

        Returns:
            ``tp``, ``fp_boundary``, ``fp_far``, ``fn_boundary``, ``fn_far`` in [0, 1]. An empty
            union (no object anywhere, none predicted) gives ``tp`` 1 and no error, like the
            pooled IoU's 0 / 0 convention.
        """
        u = self.union
        counts = {"tp": self.tp, "fp_boundary": self.fp_boundary, "fp_far": self.fp_far,
                  "fn_boundary": self.fn_boundary, "fn_far": self.fn_far}
        if u == 0:
            return {k: (1.0 if k == "tp" else 0.0) for k in counts}
        return {k: v / u for k, v in counts.items()}

    def to_dict(self) -> dict[str, object]:
        """The ``--json`` ``breakdown`` object: the shares, the band width and the raw counts."""
        d: dict[str, object] = {"boundary_px": self.boundary_px, **self.shares()}
        d["counts"] = {"union": self.union, "tp": self.tp, "fp_boundary": self.fp_boundary, "fp_far": self.fp_far,
                       "fn_boundary": self.fn_boundary, "fn_far": self.fn_far}
        return d


class BreakdownAccumulator:
    """Streaming `ErrorBreakdown` over any number of frames (constant memory: five counters).

    Args:
        boundary_px: band half-width in pixels around true object boundaries (see `boundary_band`).
    """

    def __init__(self, boundary_px: int = 2) -> None:
        boundary_band(np.zeros((1, 1), bool), boundary_px)  # validate once, at construction
        self.boundary_px = int(boundary_px)
        self._counts = ErrorBreakdown(boundary_px=self.boundary_px)

    def add(self, pred: np.ndarray, label: np.ndarray, valid: np.ndarray | None = None) -> ErrorBreakdown:
        """Fold in one frame, valid pixels only (as `confusion`).

        Args:
            pred: H x W predicted object mask.
            label: H x W ground truth, nonzero = object.
            valid: H x W mask of scored pixels; None scores all.

        Returns:
            This frame's counts.
        """
        band = boundary_band(label, self.boundary_px)
        if valid is not None:
            valid = np.asarray(valid, dtype=bool)
            if valid.shape != band.shape:
                raise DataError(f"valid-mask shape {valid.shape} differs from label shape {band.shape}")
            near, far = valid & band, valid & ~band
        else:
            near, far = band, ~band
        cn, cf = confusion(pred, label, near), confusion(pred, label, far)
        frame = ErrorBreakdown(self.boundary_px, tp=cn.tp + cf.tp, fp_boundary=cn.fp, fp_far=cf.fp,
                               fn_boundary=cn.fn, fn_far=cf.fn)
        self._counts = self._counts + frame
        return frame

    def summary(self) -> ErrorBreakdown:
        """The pooled counts so far (`ErrorBreakdown.shares` turns them into fractions)."""
        return self._counts
