"""Regression tests for issue 10: one threshold rule and one reader, whoever asks.

- At the paper's extreme threshold 0.9999 the Segmenter, replay, depthseg-eval and
  depthseg-tune classify every pixel alike (they all compare logits with logit(t)).
- Labels logged 0.5 ms after their depth frame are used by training and evaluation alike
  (both read through `edge.io.open_frames`, pairing by stamp within a tolerance).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from edge.evaluate import evaluate
from edge.infer import Segmenter
from edge.io import TOPIC_DEPTH, TOPIC_LABELS, Frame, McapWriter, open_frames
from edge.meta import ModelMeta
from edge.metrics import confusion, logit, segmentation_mask, sigmoid, threshold_logit
from edge.tune import tune
from replay.replay import replay

T = 0.9999


class FixedLogits:
    """A predictor whose logits are given: dense around logit(0.9999), where float32 probabilities fail."""

    def __init__(self, logits: np.ndarray, threshold: float) -> None:
        self._logits = logits
        # the threshold rule alone: the speck rule after it has its own test below
        self.meta = ModelMeta(encoder="vgg11", width=0.125, in_channels=1, threshold=threshold, min_object_px=0)
        self.name = "fixed"
        self.threshold = threshold
        self.min_object_px = 0

    def logits(self, depth: np.ndarray) -> np.ndarray:
        return self._logits

    def predict(self, depth: np.ndarray):
        valid = np.isfinite(depth) & (depth > 0)
        mask = segmentation_mask(self._logits, valid, self.threshold)
        return SimpleNamespace(prob=sigmoid(self._logits), logits=self._logits, mask=mask, valid=valid,
                               timings={"total": 0.0})


def _dense_frame() -> tuple[Frame, np.ndarray]:
    rng = np.random.default_rng(0)
    h, w = 200, 500
    logits = (threshold_logit(T) + rng.uniform(-2e-3, 2e-3, (h, w))).astype(np.float32)
    label = (rng.random((h, w)) < 0.5).astype(np.uint8)
    depth = np.full((h, w), 0.3, np.float32)
    depth[:3, :3] = 0.0  # a few invalid pixels: never scored
    return Frame(depth=depth, stamp_ns=1, label=label), logits


def test_the_threshold_rule_at_0_9999_is_the_same_everywhere():
    fr, logits = _dense_frame()
    valid = fr.depth > 0
    rule = segmentation_mask(logits, valid, T)
    # the test has teeth: comparing float32 probabilities gives other classes here
    assert np.count_nonzero((sigmoid(logits) >= np.float32(T)) != (rule == 1)) > 100

    # Segmenter-like predictor at its own threshold, and replay overriding a 0.5 segmenter
    seg = FixedLogits(logits, T)
    assert np.array_equal(seg.predict(fr.depth).mask, rule)
    masks = []
    s = replay([fr], FixedLogits(logits, 0.5), threshold=T, on_frame=lambda r: masks.append(r.mask.copy()))
    assert np.array_equal(masks[0], rule)
    expect = confusion(rule == 1, fr.label, valid)
    assert s.metrics.pooled == expect
    # depthseg-eval and depthseg-tune (scores at the stored threshold) agree with it
    ev = evaluate(seg, [fr])
    assert ev.threshold == T and ev.metrics.pooled == expect
    cur = tune(seg, [fr], "iou", split=0.0).current()
    assert cur is not None and cur["threshold"] == pytest.approx(T, abs=1e-12)
    for k in ("iou", "precision", "recall", "pixel_accuracy"):
        assert cur[k] == pytest.approx(getattr(ev.metrics, k), abs=1e-12), k


def test_an_onnx_model_at_0_9999_scores_alike_in_segmenter_replay_eval_and_tune(tmp_path, scene):
    from onnxgen import linear_model

    path = linear_model(tmp_path / "m.onnx", threshold=T, k=40.0, bias=-20.0)
    seg = Segmenter(path, threads=1)
    assert seg.threshold == T
    frames = [Frame(depth=d, stamp_ns=i, label=lab) for i, (d, lab) in enumerate(scene(i, 48, 64) for i in range(4))]
    pooled = sum((confusion(seg.predict(f.depth).mask == 1, f.label, f.depth > 0) for f in frames[1:]),
                 confusion(seg.predict(frames[0].depth).mask == 1, frames[0].label, frames[0].depth > 0))
    assert replay(frames, Segmenter(path, threads=1, threshold=0.5), threshold=T).metrics.pooled == pooled
    ev = evaluate(seg, frames)
    assert ev.metrics.pooled == pooled and ev.min_object_px == seg.min_object_px == 6
    # tune scores the threshold rule alone (binned logits cannot see specks): eval without the speck rule
    bare = evaluate(seg, frames, min_object_px=0)
    cur = tune(seg, frames, "iou", split=0.0).current()
    for k in ("iou", "precision", "recall"):
        assert cur[k] == pytest.approx(getattr(bare.metrics, k), abs=1e-12), k
    assert logit(np.float32(T)) == pytest.approx(threshold_logit(T), abs=1e-3)


@pytest.mark.parametrize("stamped", [True, False], ids=["header-stamps", "stamps-0-log-time"])
def test_labels_logged_half_a_millisecond_late_train_and_evaluate_alike(tmp_path, scene, stamped):
    from edge.train.data import load_frames

    path = tmp_path / "late.mcap"
    t0, n = 1_700_000_000_000_000_000, 5
    with McapWriter(path) as w:
        dch, lch = w.image_channel(TOPIC_DEPTH), w.image_channel(TOPIC_LABELS)
        for i in range(n):
            d, lab = scene(i)
            t = t0 + i * 50_000_000
            w.add_image(dch, t, t if stamped else 0, "cam", d, "32FC1", i)
            w.add_image(lch, t + 500_000, (t + 500_000) if stamped else 0, "cam", lab, "mono8", i)
    frames, total = open_frames(path, require_labels=True)
    got = list(frames)
    assert total == n and len(got) == n and all(f.label is not None for f in got)
    for i, f in enumerate(got):
        assert np.array_equal(f.label, scene(i)[1])
    fs = load_frames([path])
    assert len(fs) == n and np.array_equal(fs.label[2], scene(2)[1])
    ev = evaluate(FixedLogits(np.zeros((24, 32), np.float32), 0.5), open_frames(path, require_labels=True)[0])
    assert ev.frames == n and ev.unlabelled == 0
