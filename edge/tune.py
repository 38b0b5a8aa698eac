"""Choose a model's decision boundary from data, for the user's goal (paper V.c, Fig. 6).

Why: the threshold trades precision against recall. The paper's model was useless on a real
capture at 0.5 and acceptable at 0.9999, found by hand; here it is found by a sweep.

How, in constant memory (never a list of pixels or frames):
- Every candidate threshold is an edge of one fixed, fine grid over the logits: ``N_EDGES``
  edges spaced evenly in asinh(logit / ``GRID_SCALE``) over [-16, 16], i.e. 8e-5 logit apart
  around 0 and 0.16 % of the logit apart in the tails (logit 9.21 = probability 0.9999 is
  resolved to +-0.015 logit, +-1.5e-6 in probability). Logit 0 (probability 0.5) and the
  model's stored threshold are exact edges, so "before" numbers are exact, not interpolated.
  Logits outside [-16, 16] fall into an under/overflow bin (counted, never lost). Why 16: the
  edge path compares float32 probabilities with the threshold (`edge.infer.Segmenter`), and
  above sigmoid(16) = 1 - 1.1e-7 float32 can no longer tell a probability from 1.
- Per frame, the valid pixels' logits are binned once per class (object / background); suffix
  sums give TP, FP, FN, TN at *every* edge, from which the frame's IoU, precision, recall and
  pixel accuracy at every edge follow, with the 0/0 conventions of `edge.metrics`. Only their
  running sums are kept (per-frame means, as the paper averages), plus the pooled per-class
  histograms (pooled IoU). Cost per frame: one ``searchsorted`` over its valid pixels.
- A pixel is object when ``logit >= edge``, exactly as `edge.metrics.predict_mask` decides
  with the stored probability ``sigmoid(edge)``.
- The speck rule that follows the threshold (`edge.postprocess`, ``ModelMeta.min_object_px``),
  and the height rule when a model has one (``ModelMeta.min_height_m``), are not in these scores:
  binned logits cannot see connected components. They are the numbers
  ``depthseg-eval --min-object-px 0`` prints; with the rule eval's are equal or higher where
  specks were false objects (on frames without objects, much higher).

Objectives (all on per-frame means, i.e. the numbers ``depthseg-eval`` prints):
``iou`` mean IoU; ``f1`` / ``fBETA`` the F-score of mean precision and mean recall;
``precision>=P`` the best mean recall with mean precision >= P; ``recall>=R`` the best mean
precision with mean recall >= R. Ties are broken towards the middle of the longest run of
equally good thresholds (the largest margin).

Honesty: frames are split (deterministically by seed) into tuning and held-out frames; the
threshold is chosen on the tuning frames only and the objective is reported on the held-out
frames at the model's stored threshold and at the chosen one, however small the gain. The
stored threshold is kept unless the new one is better there (`TuneResult.improves`): a tuned
0.671 is not replaced by a 0.572 that scores worse on frames it was not chosen on. Held-out frames are picked
by systematic sampling with a seeded random phase, so their share is exact for any frame
count; consecutive frames of a real recording are correlated, so their held-out numbers are
optimistic there.

Torch-free: torch is imported only when the model itself is a ``.pt`` checkpoint.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from edge.errors import ConfigError, DataError, ModelError, ThresholdError
from edge.infer import checked_logits
from edge.io import Frame, atomic_write
from edge.metrics import sigmoid, threshold_logit
from edge.preprocess import valid_mask

__all__ = [
    "N_EDGES",
    "LOGIT_LIMIT",
    "GRID_SCALE",
    "Objective",
    "parse_objective",
    "OBJECTIVE_FORMS",
    "logit_grid",
    "sigmoid",
    "ThresholdSweep",
    "Curves",
    "Choice",
    "choose_threshold",
    "TuneResult",
    "heldout_assigner",
    "pseudo_labeller",
    "tune",
    "plot_pr_curve",
]

N_EDGES = 8193  # odd: logit 0 is the middle edge
LOGIT_LIMIT = 16.0  # sigmoid(16) = 1 - 1.1e-7: about the last probability float32 tells from 1
GRID_SCALE = 0.05  # logits ~ this size get an evenly spaced grid; larger ones a relative one
OBJECTIVE_FORMS = "iou, f1, fBETA (e.g. f0.5, f2), precision>=P, recall>=R (P, R fractions, e.g. 0.98)"

_TIE_TOL = 1e-12


def logit_grid(
    n_edges: int = N_EDGES, limit: float = LOGIT_LIMIT, scale: float = GRID_SCALE, extra: Iterable[float] = ()
) -> np.ndarray:
    """Sorted candidate logit thresholds: asinh-spaced over [-limit, limit], symmetric, with 0 and ``extra`` exact."""
    if n_edges < 3:
        raise ConfigError(f"the threshold grid needs at least 3 edges, got {n_edges}")
    half = (n_edges - 1) // 2
    u = np.linspace(0.0, math.asinh(limit / scale), half + 1)[1:]
    pos = scale * np.sinh(u)
    pos[-1] = limit
    edges = np.concatenate([-pos[::-1], [0.0], pos])
    extra = [float(e) for e in extra if np.isfinite(e) and -limit <= e <= limit]
    if extra:
        edges = np.unique(np.concatenate([edges, extra]))
    return edges


# ---------------------------------------------------------------------------------------------
# Objectives


@dataclass(frozen=True)
class Objective:
    """What "best threshold" means. ``kind``: iou, fbeta, precision (>= target), recall (>= target)."""

    kind: str
    beta: float = 1.0
    target: float = 0.0
    text: str = ""

    @property
    def constrained(self) -> bool:
        return self.kind in ("precision", "recall")

    @property
    def metric(self) -> str:
        """The metric being maximised (for constrained objectives: the other one)."""
        return {"iou": "iou", "fbeta": self.fscore_key, "precision": "recall", "recall": "precision"}[self.kind]

    @property
    def fscore_key(self) -> str:
        return "f1" if self.beta == 1.0 else f"f{self.beta:g}"

    def check_attainable(self) -> None:
        """`ThresholdError` now (before any frame is run) for a target no threshold can ever meet."""
        if self.constrained and self.target > 1.0:
            pct = " (targets are fractions: 0.98, not 98)" if self.target > 1.5 else ""
            raise ThresholdError(f"no threshold can give mean {self.kind} >= {self.target:g}: it is at most 1{pct}")

    def describe(self) -> str:
        if self.kind == "iou":
            return "maximise per-frame mean IoU"
        if self.kind == "fbeta":
            return f"maximise F{self.beta:g} of per-frame mean precision and recall"
        other = "recall" if self.kind == "precision" else "precision"
        return f"maximise mean {other} subject to mean {self.kind} >= {self.target:g}"


_NUM = r"([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)"


def parse_objective(text: str) -> Objective:
    """Parse ``iou``, ``f1``, ``fBETA``, ``precision>=P`` or ``recall>=R`` (case and spaces ignored)."""
    raw = str(text)
    s = re.sub(r"\s+", "", raw).lower()
    if s in ("iou", "miou"):
        return Objective("iou", text="iou")
    m = re.fullmatch(r"f" + _NUM, s)
    if m:
        beta = float(m.group(1))
        if not (beta > 0 and math.isfinite(beta)):
            raise ConfigError(f"objective '{raw}': beta must be > 0; valid forms: {OBJECTIVE_FORMS}")
        return Objective("fbeta", beta=beta, text="f1" if beta == 1.0 else f"f{beta:g}")
    m = re.fullmatch(r"(precision|recall|p|r)>=" + _NUM, s)
    if m:
        kind = {"p": "precision", "r": "recall"}.get(m.group(1), m.group(1))
        target = float(m.group(2))
        if not (target > 0.0 and math.isfinite(target)):
            raise ConfigError(f"objective '{raw}': a {kind} target must be > 0; valid forms: {OBJECTIVE_FORMS}")
        return Objective(kind, target=target, text=f"{kind}>={target:g}")
    raise ConfigError(f"unknown objective '{raw}'; valid forms: {OBJECTIVE_FORMS}")


# ---------------------------------------------------------------------------------------------
# The sweep


def _per_frame(tp: np.ndarray, fp: np.ndarray, npos: int, n: int) -> tuple[np.ndarray, ...]:
    """(iou, precision, recall, accuracy) at every edge, with `edge.metrics.frame_scores`' 0/0 rules."""
    fn = npos - tp
    tn = n - npos - fp
    union = tp + fp + fn
    with np.errstate(invalid="ignore", divide="ignore"):
        iou = np.where(union > 0, tp / np.maximum(union, 1), 1.0)
        npred = tp + fp
        has_obj = npos > 0
        prec = np.where(npred > 0, tp / np.maximum(npred, 1), 0.0 if has_obj else 1.0)
        rec = tp / npos if has_obj else np.ones_like(iou)
    acc = (tp + tn) / n
    return iou, prec, rec, acc


class ThresholdSweep:
    """Streaming accumulator: feed (logits, labels, valid) frames; read `curves` at every edge."""

    def __init__(self, edges: np.ndarray | None = None) -> None:
        self.edges = np.asarray(logit_grid() if edges is None else edges, dtype=np.float64)
        if self.edges.ndim != 1 or np.any(np.diff(self.edges) <= 0):
            raise ConfigError("threshold edges must be a strictly increasing 1-D array")
        k = len(self.edges)
        self.frames = 0
        self.skipped = 0  # frames without a valid pixel: no score (as edge.metrics)
        self._sums = np.zeros((4, k), dtype=np.float64)  # iou, precision, recall, accuracy
        self.pos_hist = np.zeros(k + 1, dtype=np.int64)  # bin i: edges[i-1] <= logit < edges[i]
        self.neg_hist = np.zeros(k + 1, dtype=np.int64)

    def add(self, logits: np.ndarray, label: np.ndarray, valid: np.ndarray | None = None) -> bool:
        """Fold in one frame; False when it has no valid pixel (skipped, like `MetricAccumulator`)."""
        logits = np.asarray(logits)
        label = np.asarray(label)
        if logits.shape != label.shape:
            raise DataError(f"logits shape {logits.shape} differs from label shape {label.shape}")
        if valid is None:
            valid = np.ones(label.shape, dtype=bool)
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != label.shape:
            raise DataError(f"valid-mask shape {valid.shape} differs from label shape {label.shape}")
        x = logits[valid].astype(np.float64, copy=False)
        n = int(x.size)
        if n == 0:
            self.skipped += 1
            return False
        if np.isnan(x).any():
            raise ModelError(f"the model produced NaN logits on {int(np.isnan(x).sum())} valid pixels of a frame")
        g = label[valid].astype(bool, copy=False)
        idx = np.searchsorted(self.edges, x, side="right")
        k1 = len(self.edges) + 1
        ph = np.bincount(idx[g], minlength=k1)
        nh = np.bincount(idx[~g], minlength=k1)
        self.pos_hist += ph
        self.neg_hist += nh
        tp = np.cumsum(ph[::-1])[::-1][1:].astype(np.float64)  # pixels with logit >= edges[k]
        fp = np.cumsum(nh[::-1])[::-1][1:].astype(np.float64)
        for i, arr in enumerate(_per_frame(tp, fp, int(g.sum()), n)):
            self._sums[i] += arr
        self.frames += 1
        return True

    def curves(self) -> Curves:
        if self.frames == 0:
            raise DataError(f"no frame could be scored ({self.skipped} frames had no valid pixel)")
        iou, prec, rec, acc = self._sums / self.frames
        tp = np.cumsum(self.pos_hist[::-1])[::-1][1:].astype(np.float64)
        fp = np.cumsum(self.neg_hist[::-1])[::-1][1:].astype(np.float64)
        fn = float(self.pos_hist.sum()) - tp
        union = tp + fp + fn
        pooled_iou = np.where(union > 0, tp / np.maximum(union, 1), 1.0)
        return Curves(self.edges, iou, prec, rec, acc, pooled_iou, self.frames, self.skipped)


def _fscore(p: np.ndarray, r: np.ndarray, beta: float) -> np.ndarray:
    b2 = beta * beta
    den = b2 * p + r
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, (1 + b2) * p * r / np.where(den > 0, den, 1.0), 0.0)


@dataclass(frozen=True)
class Curves:
    """Per-frame mean scores (and pooled IoU) at every candidate logit threshold."""

    edges: np.ndarray
    iou: np.ndarray
    precision: np.ndarray
    recall: np.ndarray
    pixel_accuracy: np.ndarray
    pooled_iou: np.ndarray
    frames: int
    skipped: int = 0

    @property
    def thresholds(self) -> np.ndarray:
        return sigmoid(self.edges)

    def fscore(self, beta: float = 1.0) -> np.ndarray:
        return _fscore(self.precision, self.recall, beta)

    def index_of(self, logit: float) -> int:
        """Index of the edge equal to ``logit`` (it must be an edge of the grid)."""
        i = int(np.searchsorted(self.edges, logit))
        if i >= len(self.edges) or self.edges[i] != logit:
            raise ConfigError(f"logit {logit} is not an edge of the threshold grid")
        return i

    def point(self, i: int, objective: Objective | None = None) -> dict[str, Any]:
        """All scores at edge ``i`` (and the objective's value / target check) as a JSON-able dict."""
        d: dict[str, Any] = {
            "threshold": float(sigmoid(self.edges[i])),
            "threshold_logit": float(self.edges[i]),
            "iou": float(self.iou[i]),
            "precision": float(self.precision[i]),
            "recall": float(self.recall[i]),
            "f1": float(self.fscore(1.0)[i]),
            "pixel_accuracy": float(self.pixel_accuracy[i]),
            "pooled_iou": float(self.pooled_iou[i]),
            "frames": self.frames,
        }
        if objective is not None:
            if objective.kind == "fbeta":
                d[objective.fscore_key] = float(self.fscore(objective.beta)[i])
            d["objective"] = d[objective.metric]
            if objective.constrained:
                d["meets_target"] = bool(d[objective.kind] >= objective.target)
        return d


@dataclass(frozen=True)
class Choice:
    index: int
    logit: float
    threshold: float  # probability in (0, 1)
    value: float  # the maximised metric at the chosen threshold (tuning frames)


def _middle_of_longest_run(indices: np.ndarray) -> int:
    breaks = np.flatnonzero(np.diff(indices) != 1)
    starts = np.concatenate([[0], breaks + 1])
    ends = np.concatenate([breaks + 1, [len(indices)]])
    j = int(np.argmax(ends - starts))
    run = indices[starts[j] : ends[j]]
    return int(run[(len(run) - 1) // 2])


def _best(values: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    v = values[candidates]
    return candidates[v >= v.max() - _TIE_TOL]


def choose_threshold(curves: Curves, objective: Objective) -> Choice:
    """The edge that optimises ``objective``; `ThresholdError` when a target is met nowhere."""
    allidx = np.arange(len(curves.edges))
    if objective.kind == "iou":
        best = _best(curves.iou, allidx)
        values = curves.iou
    elif objective.kind == "fbeta":
        values = curves.fscore(objective.beta)
        best = _best(values, allidx)
    else:
        constrained = curves.precision if objective.kind == "precision" else curves.recall
        values = curves.recall if objective.kind == "precision" else curves.precision
        feasible = allidx[constrained >= objective.target - _TIE_TOL]
        if feasible.size == 0:
            j = int(np.argmax(constrained))
            raise ThresholdError(
                f"no threshold reaches mean {objective.kind} >= {objective.target:g} on {curves.frames} tuning frames "
                f"(best {constrained[j]:.4f} at threshold {float(sigmoid(curves.edges[j])):.6g}); lower the target"
            )
        best = _best(values, feasible)
        best = _best(constrained, best)  # among equally good, the safest margin on the target
    i = _middle_of_longest_run(best)
    return Choice(i, float(curves.edges[i]), float(sigmoid(curves.edges[i])), float(values[i]))


# ---------------------------------------------------------------------------------------------
# Frames -> result


def heldout_assigner(split: float, seed: int) -> Callable[[int], bool]:
    """``f(i) -> True`` when the i-th labelled frame is held out: an exact share ``split`` for any count.

    Systematic sampling with a random phase drawn from ``np.random.default_rng(seed)``: of the
    first n frames, floor(n * split + u) are held out, spread evenly through the stream.
    """
    if not 0.0 <= split < 1.0:
        raise ConfigError(f"`split` must lie in [0, 1) (the held-out fraction), got {split}")
    u = float(np.random.default_rng(seed).random())

    def held(i: int) -> bool:
        return math.floor((i + 1) * split + u) > math.floor(i * split + u)

    return held


def pseudo_labeller(height_threshold_m: float = 0.008, seed: int = 0, sensor=None) -> Callable[[Frame], np.ndarray]:
    """Geometric pseudo-labels for unlabelled frames: object = higher than ``height_threshold_m`` above the
    RANSAC floor plane (`edge.baseline.PlaneBaseline`). Not ground truth: the tuned threshold then
    reproduces the plane baseline's idea of an object, mistakes included."""
    from edge.baseline import PlaneBaseline, intrinsics_for

    base = PlaneBaseline(height_threshold_m=height_threshold_m, seed=seed)

    def label(fr: Frame) -> np.ndarray:
        depth = np.asarray(fr.depth)
        return base.predict(depth, intrinsics_for(depth.shape, fr.info, sensor)).astype(np.uint8)

    return label


@dataclass
class TuneResult:
    """Everything `tune` found; `to_dict` is the ``depthseg-tune --json`` object (minus CLI fields)."""

    objective: Objective
    choice: Choice
    tuning: Curves
    heldout: Curves | None
    split: float
    seed: int
    model: str
    stored_threshold: float
    stored_policy: str
    labels: str  # "ground truth (<topic>)" or "pseudo-labels (...)"
    pseudo_labels: bool = False
    unlabelled: int = 0
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def threshold(self) -> float:
        return self.choice.threshold

    @property
    def report_curves(self) -> Curves:
        """Where before/after are measured: held-out frames, or the tuning frames when ``split`` is 0."""
        return self.heldout if self.heldout is not None else self.tuning

    @property
    def in_sample(self) -> bool:
        return self.heldout is None

    def stored_index(self) -> int:
        """Edge of the grid at the model's stored threshold (exact: `tune` puts it on the grid;
        clipped to the grid's ends for a threshold beyond sigmoid(+-16))."""
        c = self.report_curves
        x = float(np.clip(threshold_logit(self.stored_threshold), c.edges[0], c.edges[-1]))
        i = int(np.searchsorted(c.edges, x))
        if i > 0 and (i == len(c.edges) or x - c.edges[i - 1] < c.edges[i] - x):
            i -= 1
        return i

    def before(self) -> dict[str, Any]:
        """Scores at the stored threshold (what the model does now), on the report frames."""
        return self.report_curves.point(self.stored_index(), self.objective)

    def after(self) -> dict[str, Any]:
        return self.report_curves.point(self.choice.index, self.objective)

    def current(self) -> dict[str, Any] | None:
        """Scores at the threshold the model carried before tuning (same as `before`)."""
        return self.before()

    @property
    def improves(self) -> bool:
        """Whether the new threshold beats the stored one on the report frames (held-out unless ``split`` 0).

        For a target objective: meeting the target beats missing it; when both miss, the one
        closer to the target is better; when both meet it, the higher optimised metric. Ties
        keep the stored threshold.
        """
        if self.choice.index == self.stored_index():
            return False
        b, a = self.before(), self.after()
        if self.objective.constrained:
            if a["meets_target"] != b["meets_target"]:
                return bool(a["meets_target"])
            if not a["meets_target"]:
                kind = self.objective.kind
                return a[kind] > b[kind] + _TIE_TOL
        return a["objective"] > b["objective"] + _TIE_TOL

    @property
    def result_threshold(self) -> float:
        """The threshold the model should carry: the new one if it `improves`, else the stored one."""
        return self.threshold if self.improves else self.stored_threshold

    def policy(self, data_name: str = "") -> str:
        """One line stored in the model beside the threshold: how it was chosen and what it bought."""
        b, a = self.before(), self.after()
        where = "in-sample (no held-out frames)" if self.in_sample else f"held-out ({self.report_curves.frames} frames)"
        src = f" of {data_name}" if data_name else ""
        head = "PSEUDO-LABELS, not ground truth: " + self.labels + "; " if self.pseudo_labels else ""
        if not self.improves:
            head = f"kept the stored threshold {self.stored_threshold:.6g} (the tuned one was not better): " + head
        return (
            f"{head}depthseg-tune objective {self.objective.text} on {self.tuning.frames} frames{src} "
            f"(split {self.split:g}, seed {self.seed}); {where} {self.objective.metric} "
            f"{b['objective']:.4f} at the stored {self.stored_threshold:.6g} -> {a['objective']:.4f} at {self.threshold:.6g}"
        )

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "threshold": self.threshold,
            "threshold_logit": self.choice.logit,
            "objective": self.objective.text,
            "objective_description": self.objective.describe(),
            "metric": self.objective.metric,
            "before": self.before(),
            "after": self.after(),
            "current": {"stored_threshold": self.stored_threshold, "stored_policy": self.stored_policy, **self.before()},
            "improves": self.improves,
            "result_threshold": self.result_threshold,
            "tuning_value": self.choice.value,
            "tuning_frames": self.tuning.frames,
            "heldout_frames": 0 if self.heldout is None else self.heldout.frames,
            "in_sample": self.in_sample,
            "skipped_frames": self.tuning.skipped + (self.heldout.skipped if self.heldout is not None else 0),
            "unlabelled_frames": self.unlabelled,
            "split": self.split,
            "seed": self.seed,
            "model": self.model,
            "labels": self.labels,
            "pseudo_labels": self.pseudo_labels,
            "scores": "threshold rule alone, before the model's speck rule (depthseg-eval --min-object-px 0)",
        }
        d.update(self.extra)
        return d


def tune(
    predictor: Any,
    frames: Iterable[Frame],
    objective: Objective | str = "iou",
    split: float = 0.25,
    seed: int = 0,
    limit: int | None = None,
    pseudo_labels: Callable[[Frame], np.ndarray] | None = None,
    labels_name: str = "ground truth",
    edges: np.ndarray | None = None,
    wrap: Callable[[Iterator[Frame]], Iterator[Frame]] | None = None,
    no_labels_hint: str = "",
) -> TuneResult:
    """Run ``predictor`` (``.meta``, ``.name``, ``.logits(depth)``) over labelled ``frames`` and choose a threshold.

    Frames without labels are counted and skipped (not run through the model) unless
    ``pseudo_labels`` makes labels for every frame. ``limit`` caps the frames used.
    ``no_labels_hint`` ends the error raised when no frame has a label (e.g. the topics present).
    """
    obj = parse_objective(objective) if isinstance(objective, str) else objective
    if limit is not None and limit < 1:
        raise ConfigError(f"`limit` must be >= 1 frame, got {limit}")
    held = heldout_assigner(split, seed)
    meta = getattr(predictor, "meta", None)
    stored = float(meta.threshold) if meta is not None else 0.5
    stored_policy = str(meta.threshold_policy) if meta is not None else ""
    grid = logit_grid(extra=[threshold_logit(stored)]) if edges is None else np.asarray(edges, dtype=np.float64)
    if 0.0 not in grid:
        raise ConfigError("the threshold grid must contain logit 0 (probability 0.5)")
    tuning, heldout = ThresholdSweep(grid), ThresholdSweep(grid)
    used = unlabelled = 0
    it: Iterator[Frame] = iter(frames)
    if wrap is not None:
        it = wrap(it)
    for fr in it:
        if pseudo_labels is not None:
            label = pseudo_labels(fr)
        elif fr.label is None:
            unlabelled += 1
            continue
        else:
            label = fr.label
        depth = np.asarray(fr.depth)
        label = np.asarray(label)
        if label.shape != depth.shape:
            raise DataError(f"frame at t={fr.stamp_ns} ns: label shape {label.shape} differs from depth shape {depth.shape}")
        logits = checked_logits(predictor, depth)
        (heldout if held(used) else tuning).add(logits, label, valid_mask(depth))
        used += 1
        if limit is not None and used >= limit:
            break
    if used == 0:
        raise DataError(
            f"no labelled frames to tune on ({unlabelled} frames without labels)" + (f"; {no_labels_hint}" if no_labels_hint else "")
        )
    if tuning.frames == 0:
        raise DataError(
            f"no tuning frames left: {used} labelled frames, {heldout.frames} held out by `split` {split:g}; "
            "lower `split` or add frames"
        )
    if split > 0 and heldout.frames == 0:
        raise DataError(
            f"only {used} labelled frames: `split` {split:g} held none out; add frames, raise `split`, "
            "or pass `split` 0 for in-sample numbers"
        )
    tc = tuning.curves()
    choice = choose_threshold(tc, obj)
    return TuneResult(
        objective=obj,
        choice=choice,
        tuning=tc,
        heldout=heldout.curves() if heldout.frames else None,
        split=split,
        seed=seed,
        model=str(getattr(predictor, "name", "model")),
        stored_threshold=stored,
        stored_policy=stored_policy,
        labels=labels_name,
        pseudo_labels=pseudo_labels is not None,
        unlabelled=unlabelled,
    )


def plot_pr_curve(result: TuneResult, path: str | Path, title: str = "") -> Path:
    """Precision-recall curve (per-frame means over all thresholds) with the stored and chosen points; atomic PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    fig, ax = plt.subplots(figsize=(6.0, 5.0), dpi=110)
    try:
        sets = [("tuning", result.tuning, "-")]
        if result.heldout is not None:
            sets.append(("held-out", result.heldout, "--"))
        for name, c, ls in sets:
            ax.plot(c.recall, c.precision, ls, lw=1.4, label=f"{name} frames ({c.frames})")
        c = result.report_curves
        where = "in-sample" if result.in_sample else "held-out"
        b, a = result.stored_index(), result.choice.index
        ax.plot(c.recall[b], c.precision[b], "o", ms=8, mfc="none", mec="tab:red", mew=2,
                label=f"stored {result.stored_threshold:.6g} ({where}): P {c.precision[b]:.3f} R {c.recall[b]:.3f}")
        ax.plot(c.recall[a], c.precision[a], "*", ms=13, color="tab:green",
                label=f"chosen {result.threshold:.6g} ({where}): P {c.precision[a]:.3f} R {c.recall[a]:.3f}")
        if result.objective.constrained:
            t = result.objective.target
            (ax.axhline if result.objective.kind == "precision" else ax.axvline)(t, color="grey", lw=0.8, ls=":")
        ax.set_xlabel("recall (per-frame mean)")
        ax.set_ylabel("precision (per-frame mean)")
        ax.set_xlim(0, 1.01)
        ax.set_ylim(0, 1.01)
        ax.grid(alpha=0.3)
        kind = "PSEUDO-LABELS" if result.pseudo_labels else "ground-truth labels"
        ax.set_title(title or f"depthseg-tune {result.objective.text} ({kind})", fontsize=10)
        ax.legend(loc="best", fontsize=8)
        fig.tight_layout()
        with atomic_write(path) as tmp:
            fig.savefig(tmp, format="png")
    finally:
        plt.close(fig)
    return path
