"""Run a model over a recording frame by frame, as the robot would, and score it where labelled.

Why a loop of its own rather than the evaluation code: replay is about *behaviour in time*:
latency per frame, throughput, pacing to the recording's clock (``rate=1.0`` shows what the
robot sees at its frame rate; a frame whose processing starts more than 5 ms after it would have
arrived, because the previous one was still busy, is counted as late, not dropped), damaged files, and an output recording to look at. Scoring reuses
`edge.metrics` (the paper's per-frame means plus pooled counts, valid pixels only), so replay and
`depthseg-eval` agree on the numbers.

Each frame goes through ``segmenter.predict`` (`edge.infer.Segmenter`: the shared preprocessing,
padding to multiples of 32 for any frame size, onnxruntime). Its mask says 0 background, 1 object
and 255 *unknown* for pixels without a valid depth: those are shown and counted separately and
never scored.

Memory is constant in the number of frames: latencies go into a log-spaced histogram (0.5 %
bins), scores into a streaming accumulator.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from edge.errors import ConfigError, DataError, McapDataError
from edge.io import Frame
from edge.metrics import (
    UNKNOWN,
    FrameScores,
    MetricAccumulator,
    MetricSummary,
    confusion,
    logit,
    segmentation_mask,
)
from edge.postprocess import describe_height_rule

__all__ = ["replay", "ReplaySummary", "FrameResult", "LatencyHistogram", "ReplayDataError", "UNKNOWN", "check_rate",
           "MAX_GAP_S"]

LATE_SLACK_S = 0.005  # a paced frame starting more than this after its due time counts as late
MAX_GAP_S = 1.0  # pacing skips a jump of the recording clock longer than this (a paused recorder, a 116-day gap)
RATE_RANGE = (1e-3, 1e3)  # --rate: slower than 1/1000 or faster than 1000x real time is not a pace


def check_rate(rate: float | None) -> float | None:
    """``rate`` if it is a usable pace (a finite number in `RATE_RANGE`); else `ConfigError`, one line."""
    if rate is None:
        return None
    lo, hi = RATE_RANGE
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not lo <= rate <= hi:
        raise ConfigError(
            f"`rate` must be a number from {lo:g} to {hi:g} (1.0 = real time, 2 = twice as fast), got {rate}"
        )
    return float(rate)


class _Prediction(Protocol):
    prob: np.ndarray  # (and ``logits`` when the segmenter gives them, as edge.infer.Segmenter does)
    mask: np.ndarray
    valid: np.ndarray
    timings: dict[str, float]


class _Segmenter(Protocol):
    threshold: float
    min_object_px: int  # the speck rule of its masks (edge.postprocess); a threshold override keeps it
    # (and ``min_height_m``, the height rule, when the segmenter has one: `edge.infer.Segmenter`)

    def predict(self, depth: np.ndarray) -> _Prediction: ...


class ReplayDataError(McapDataError):
    """The recording broke mid-way; ``summary`` holds what was replayed before it."""

    def __init__(self, message: str, summary: ReplaySummary) -> None:
        super().__init__(message)
        self.summary = summary


class LatencyHistogram:
    """Percentiles of many latencies in constant memory: log-spaced bins, 0.5 % wide."""

    LO_MS = 1e-3
    RATIO = 1.005

    def __init__(self, hi_ms: float = 1e6) -> None:
        self._log_ratio = math.log(self.RATIO)
        self.n_bins = int(math.ceil(math.log(hi_ms / self.LO_MS) / self._log_ratio)) + 1
        self.counts = np.zeros(self.n_bins, dtype=np.int64)
        self.n = 0
        self.total_ms = 0.0
        self.max_ms = 0.0
        self.min_ms = math.inf

    def add(self, ms: float) -> None:
        ms = float(ms)
        i = 0 if ms <= self.LO_MS else int(math.log(ms / self.LO_MS) / self._log_ratio)
        self.counts[min(i, self.n_bins - 1)] += 1
        self.n += 1
        self.total_ms += ms
        self.max_ms = max(self.max_ms, ms)
        self.min_ms = min(self.min_ms, ms)

    def percentile(self, q: float) -> float:
        """The q-th percentile (0-100), to within half a bin (0.25 %); NaN when empty."""
        if self.n == 0:
            return math.nan
        rank = max(1, math.ceil(q / 100.0 * self.n))
        i = int(np.searchsorted(np.cumsum(self.counts), rank))
        centre = self.LO_MS * self.RATIO ** (i + 0.5)
        return min(max(centre, self.min_ms), self.max_ms)

    @property
    def mean(self) -> float:
        return self.total_ms / self.n if self.n else math.nan


@dataclass
class FrameResult:
    """What one frame produced; handed to ``on_frame`` (arrays are only valid during the call)."""

    index: int
    stamp_ns: int
    frame: Frame
    mask: np.ndarray  # uint8 H x W: 0 background, 1 object, 255 unknown
    latency_ms: float
    unknown_fraction: float
    object_fraction: float  # of the valid pixels
    scores: FrameScores | None  # None without a label (or without a valid pixel)
    late: bool = False


@dataclass
class ReplaySummary:
    """Totals of a replay; ``to_dict`` gives the ``--json`` object."""

    frames: int
    seconds: float
    latency: LatencyHistogram
    threshold: float
    min_height_m: float = 0.0  # the height rule of the masks (edge.postprocess.remove_low_parts); 0 = off
    depth_topic: str = ""
    labels_topic: str | None = None
    labelled_frames: int = 0
    metrics: MetricSummary | None = None
    late_frames: int = 0
    rate: float | None = None
    gaps_skipped: int = 0
    unknown_fraction: float = 0.0
    object_fraction: float = 0.0
    sizes: list[tuple[int, int]] = field(default_factory=list)
    timings_ms: dict[str, float] = field(default_factory=dict)
    error: str | None = None
    out: str | None = None

    @property
    def fps(self) -> float:
        return self.frames / self.seconds if self.seconds > 0 else math.nan

    def to_dict(self) -> dict[str, Any]:
        lat = self.latency

        def num(v: float) -> float | None:
            return None if v is None or (isinstance(v, float) and math.isnan(v)) else round(float(v), 6)

        d: dict[str, Any] = {
            "frames": self.frames,
            "fps": num(self.fps),
            "seconds": num(self.seconds),
            "p50_ms": num(lat.percentile(50)),
            "p90_ms": num(lat.percentile(90)),
            "p99_ms": num(lat.percentile(99)),
            "mean_ms": num(lat.mean),
            "max_ms": num(lat.max_ms) if lat.n else None,
            "threshold": self.threshold,
            "min_height_m": self.min_height_m,
            "depth_topic": self.depth_topic,
            "labels_topic": self.labels_topic,
            "unknown_fraction": num(self.unknown_fraction),
            "object_fraction": num(self.object_fraction),
            "sizes": [f"{w}x{h}" for h, w in self.sizes],
            "stage_ms": {k: num(v) for k, v in self.timings_ms.items()},
        }
        if self.rate is not None:
            d["rate"] = self.rate
            d["late_frames"] = self.late_frames
            d["gaps_skipped"] = self.gaps_skipped
        if self.metrics is not None:
            m = self.metrics
            d.update(
                labelled_frames=self.labelled_frames,
                iou=num(m.iou),
                precision=num(m.precision),
                recall=num(m.recall),
                pixel_accuracy=num(m.pixel_accuracy),
                pooled_iou=num(m.pooled_iou),
            )
        if self.out:
            d["out"] = self.out
        if self.error:
            d["error"] = self.error
        return d

    def lines(self) -> list[str]:
        """Human summary, one fact per line."""
        lat = self.latency
        out = [
            f"depth topic: {self.depth_topic}" + (f"  labels: {self.labels_topic}" if self.labels_topic else ""),
            f"frames: {self.frames}  ({', '.join(f'{w}x{h}' for h, w in self.sizes) or 'none'})",
            f"frames/s: {self.fps:.1f}  (wall clock incl. decoding{' and writing' if self.out else ''})",
            f"latency ms: p50 {lat.percentile(50):.2f}  p90 {lat.percentile(90):.2f}  p99 {lat.percentile(99):.2f}"
            f"  max {lat.max_ms:.2f}" if lat.n else "latency ms: n/a",
            f"unknown (invalid depth) pixels: {100 * self.unknown_fraction:.1f} %; "
            f"object share of valid pixels: {100 * self.object_fraction:.1f} %  (threshold {self.threshold:g}"
            + (f", {describe_height_rule(self.min_height_m)}" if self.min_height_m else "") + ")",
        ]
        if self.rate is not None:
            skipped = f"; {self.gaps_skipped} gaps over {MAX_GAP_S:g} s skipped" if self.gaps_skipped else ""
            out.append(f"paced at {self.rate:g}x recording time: {self.late_frames} frames late{skipped}")
        if self.metrics is not None:
            m = self.metrics
            out.append(
                f"labelled frames: {self.labelled_frames}  iou {m.iou:.4f}  precision {m.precision:.4f}  "
                f"recall {m.recall:.4f}  pixel_accuracy {m.pixel_accuracy:.4f}  (pooled iou {m.pooled_iou:.4f})"
            )
        elif self.labels_topic:
            out.append("labels: none matched a depth frame with valid pixels")
        if self.out:
            out.append(f"wrote {self.out}")
        return out


def _mask_for(pred: _Prediction, threshold: float | None, min_object_px: int, min_height_m: float = 0.0) -> np.ndarray:
    """The segmenter's mask, or (with a ``threshold`` of the caller's) the one threshold rule of
    `edge.metrics` applied to its logits, then the segmenter's height and speck rules, so a replay
    at 0.9999 agrees with the Segmenter, eval and tune."""
    if threshold is None:
        return np.asarray(pred.mask, dtype=np.uint8)
    logits = getattr(pred, "logits", None)
    if logits is None:
        logits = logit(np.asarray(pred.prob, dtype=np.float32))
    return segmentation_mask(logits, pred.valid, threshold, min_object_px, getattr(pred, "height_m", None),
                             min_height_m)


def replay(
    stream: Iterable[Frame],
    segmenter: _Segmenter,
    out: str | Path | None = None,
    rate: float | None = None,
    threshold: float | None = None,
    on_frame: Callable[[FrameResult], None] | None = None,
    warmup: int = 1,
    out_namespace: str = "/depthseg",
    on_note: Callable[[str], None] | None = None,
    max_gap_s: float = MAX_GAP_S,
) -> ReplaySummary:
    """Segment every frame of ``stream``; optionally pace, score, and write ``out``.

    ``stream`` is normally a `edge.io.reader.DepthStream` (any iterable of `Frame` works, then
    ``out`` copies nothing through). ``threshold`` overrides the segmenter's. When the stream
    breaks mid-way (damaged file, malformed frame), ``out`` is still completed and a
    `ReplayDataError` carrying the partial summary is raised. The first frame is first run
    ``warmup`` times untimed (onnxruntime allocates on its first run), so the latency
    percentiles describe the steady state; the wall clock for frames/s includes it.
    ``out_namespace`` prefixes the topics added to ``out`` (``<ns>/mask``, ``<ns>/mask_raw``,
    ``<ns>/overlay``); a namespace whose topics the input already has is refused
    (`replay.writer.check_output_topics`).

    Pacing (``rate``, within `RATE_RANGE`) follows the frames' log times, except across a jump of
    the recording clock (forwards or back) longer than ``max_gap_s`` of recording time: that gap is
    skipped (pacing restarts at the next frame), counted in ``gaps_skipped`` and, the first time,
    told through ``on_note``, so a recorder paused for days does not make replay wait for days.
    """
    rate = check_rate(rate)
    if threshold is not None and not 0.0 < float(threshold) < 1.0:
        raise ConfigError(f"`threshold` must lie strictly between 0 and 1, got {threshold}")
    thr = float(threshold) if threshold is not None else float(segmenter.threshold)
    over = None if threshold is None or float(threshold) == float(segmenter.threshold) else float(threshold)

    writer = None
    if out is not None:
        from replay.writer import ReplayWriter, check_output_topics

        check_output_topics(getattr(stream, "topics", None) or (), out_namespace)
        writer = ReplayWriter(out, profile=getattr(stream, "profile", ""), namespace=out_namespace)
        if hasattr(stream, "message_hook"):
            stream.message_hook = writer.copy

    lat = LatencyHistogram()
    acc = MetricAccumulator()
    labelled = 0
    late = 0
    n = 0
    n_pix = n_unknown = n_valid = n_obj = 0
    sizes: list[tuple[int, int]] = []
    stage_sums: dict[str, float] = {}
    t_start = time.perf_counter()
    first_stamp: int | None = None
    prev_stamp = 0
    gaps = 0
    t_origin = t_start
    error: str | None = None
    try:
        try:
            for fr in stream:
                if n == 0:
                    for _ in range(max(0, int(warmup))):
                        segmenter.predict(fr.depth)
                is_late = False
                if rate is not None:
                    if first_stamp is not None and abs(fr.stamp_ns - prev_stamp) > max_gap_s * 1e9:
                        if gaps == 0 and on_note is not None:
                            on_note(
                                f"the recording clock jumps by {(fr.stamp_ns - prev_stamp) / 1e9:.6g} s before frame "
                                f"{n}; pacing skips gaps longer than {max_gap_s:g} s (this note is given once)"
                            )
                        gaps += 1
                        first_stamp = None
                    prev_stamp = fr.stamp_ns
                    if first_stamp is None:
                        first_stamp, t_origin = fr.stamp_ns, time.perf_counter()
                    due = t_origin + (fr.stamp_ns - first_stamp) / 1e9 / rate
                    wait = due - time.perf_counter()
                    if wait > 0:
                        time.sleep(wait)
                    is_late = wait < -LATE_SLACK_S
                    late += int(is_late)
                t0 = time.perf_counter()
                pred = segmenter.predict(fr.depth)
                ms = (time.perf_counter() - t0) * 1e3
                mask = _mask_for(pred, over, segmenter.min_object_px, getattr(segmenter, "min_height_m", 0.0))
                lat.add(ms)
                for k, v in (getattr(pred, "timings", None) or {}).items():
                    stage_sums[k] = stage_sums.get(k, 0.0) + float(v)
                hw = tuple(mask.shape)
                if hw not in sizes:
                    sizes.append(hw)  # type: ignore[arg-type]
                valid = mask != UNKNOWN
                nv = int(valid.sum())
                no = int((mask == 1).sum())
                n_pix += mask.size
                n_valid += nv
                n_unknown += mask.size - nv
                n_obj += no
                scores = None
                if fr.label is not None:
                    if fr.label.shape != mask.shape:
                        raise McapDataError(
                            f"label of frame {n} is {fr.label.shape[1]}x{fr.label.shape[0]} but the depth is "
                            f"{mask.shape[1]}x{mask.shape[0]}"
                        )
                    scores = acc.add_confusion(confusion(mask == 1, fr.label, valid))
                    labelled += 1
                if writer is not None:
                    writer.write(fr, mask)
                if on_frame is not None:
                    on_frame(
                        FrameResult(
                            index=n, stamp_ns=fr.stamp_ns, frame=fr, mask=mask, latency_ms=ms,
                            unknown_fraction=1.0 - nv / mask.size, object_fraction=no / nv if nv else 0.0,
                            scores=scores, late=is_late,
                        )
                    )
                n += 1
        except DataError as exc:  # damaged file, malformed frame, frame the model cannot take
            error = str(exc)
        seconds = time.perf_counter() - t_start
        if writer is not None:
            writer.close()
    except BaseException:
        if writer is not None:
            writer.abort()
        raise
    finally:
        if hasattr(stream, "message_hook") and writer is not None:
            stream.message_hook = None

    metrics = acc.summary() if acc.frames else None
    summary = ReplaySummary(
        frames=n,
        seconds=seconds,
        latency=lat,
        threshold=thr,
        min_height_m=float(getattr(segmenter, "min_height_m", 0.0)),
        depth_topic=getattr(stream, "depth_topic", ""),
        labels_topic=getattr(stream, "labels_topic", None),
        labelled_frames=labelled,
        metrics=metrics,
        late_frames=late,
        rate=rate,
        gaps_skipped=gaps,
        unknown_fraction=n_unknown / n_pix if n_pix else 0.0,
        object_fraction=n_obj / n_valid if n_valid else 0.0,
        sizes=sizes,
        timings_ms={k: v / n for k, v in stage_sums.items()} if n else {},
        error=error,
        out=str(out) if out is not None else None,
    )
    if error is not None:
        raise ReplayDataError(error, summary)
    if n == 0:
        raise DataError("the recording produced no depth frames; nothing was replayed")
    return summary

