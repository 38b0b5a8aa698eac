"""Metric definitions (paper III.E.f) and their 0/0 conventions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from edge.errors import ConfigError, DataError
from edge.metrics import (
    Confusion,
    MetricAccumulator,
    confusion,
    frame_scores,
    predict_mask,
    threshold_logit,
)


def scores(pred, label, valid=None):
    return frame_scores(confusion(np.asarray(pred), np.asarray(label), valid))


def test_all_correct_with_objects():
    label = np.array([[0, 1], [1, 0]], np.uint8)
    s = scores(label.astype(bool), label)
    assert (s.pixel_accuracy, s.iou, s.precision, s.recall) == (1.0, 1.0, 1.0, 1.0)


def test_all_wrong():
    label = np.array([[0, 1], [1, 0]], np.uint8)
    s = scores(label == 0, label)
    assert (s.pixel_accuracy, s.iou, s.precision, s.recall) == (0.0, 0.0, 0.0, 0.0)


def test_empty_label_empty_prediction_counts_one():
    z = np.zeros((3, 4), np.uint8)
    s = scores(z.astype(bool), z)
    assert (s.pixel_accuracy, s.iou, s.precision, s.recall) == (1.0, 1.0, 1.0, 1.0)


def test_empty_label_some_prediction():
    z = np.zeros((2, 2), np.uint8)
    pred = np.array([[1, 0], [0, 0]], bool)
    s = scores(pred, z)
    assert s.pixel_accuracy == 0.75
    assert (s.iou, s.precision, s.recall) == (0.0, 0.0, 1.0)


def test_objects_present_none_predicted():
    label = np.array([[1, 0], [0, 0]], np.uint8)
    s = scores(np.zeros((2, 2), bool), label)
    assert s.pixel_accuracy == 0.75
    assert (s.iou, s.precision, s.recall) == (0.0, 0.0, 0.0)


def test_partial_overlap_values():
    label = np.array([[1, 1, 0, 0]], np.uint8)
    pred = np.array([[0, 1, 1, 0]], bool)
    c = confusion(pred, label)
    assert c == Confusion(tp=1, fp=1, fn=1, tn=1)
    s = frame_scores(c)
    assert s.iou == pytest.approx(1 / 3)
    assert s.precision == 0.5 and s.recall == 0.5 and s.pixel_accuracy == 0.5


def test_invalid_pixels_are_ignored():
    label = np.array([[1, 1, 0, 0]], np.uint8)
    pred = np.array([[1, 0, 1, 0]], bool)  # wrong exactly on the two invalid pixels
    valid = np.array([[True, False, False, True]])
    s = scores(pred, label, valid)
    assert (s.pixel_accuracy, s.iou, s.precision, s.recall) == (1.0, 1.0, 1.0, 1.0)
    assert confusion(pred, label, valid).total == 2


def test_frame_without_valid_pixels_is_skipped():
    acc = MetricAccumulator()
    label = np.ones((2, 2), np.uint8)
    assert acc.add(np.zeros((2, 2), bool), label, np.zeros((2, 2), bool)) is None
    with pytest.raises(DataError, match="no frame could be scored"):
        acc.summary()
    acc.add(label.astype(bool), label)
    s = acc.summary()
    assert s.frames == 1 and s.skipped == 1 and s.iou == 1.0


def test_per_frame_mean_differs_from_pooled():
    acc = MetricAccumulator()
    # frame 1: big object, perfect. frame 2: one object pixel, missed.
    big = np.zeros((10, 10), np.uint8)
    big[:5] = 1
    acc.add(big.astype(bool), big)
    small = np.zeros((10, 10), np.uint8)
    small[0, 0] = 1
    acc.add(np.zeros((10, 10), bool), small)
    s = acc.summary()
    assert s.frames == 2
    assert s.iou == pytest.approx(0.5)  # mean of 1 and 0
    assert s.pooled_iou == pytest.approx(50 / 51)  # 50 TP, 1 FN
    assert s.pixel_accuracy == pytest.approx((1.0 + 0.99) / 2)
    assert s.precision == pytest.approx(0.5) and s.recall == pytest.approx(0.5)
    assert s.pooled == Confusion(tp=50, fp=0, fn=1, tn=149)
    d = s.to_dict()
    assert d["frames"] == 2 and d["iou"] == s.iou and d["pooled_iou"] == s.pooled_iou


def test_accumulator_matches_direct_mean_on_random_frames():
    rng = np.random.default_rng(7)
    acc = MetricAccumulator()
    ious = []
    for _ in range(20):
        label = rng.random((8, 9)) < rng.random()
        pred = rng.random((8, 9)) < 0.3
        valid = rng.random((8, 9)) < 0.9
        acc.add(pred, label, valid)
        p, g = pred[valid], label[valid]
        union = (p | g).sum()
        ious.append((p & g).sum() / union if union else 1.0)
    assert acc.summary().iou == pytest.approx(float(np.mean(ious)))


def test_threshold_is_sigmoid_boundary():
    assert threshold_logit(0.5) == 0.0
    t = 0.9
    assert 1 / (1 + math.exp(-threshold_logit(t))) == pytest.approx(t)
    logits = np.array([-1.0, 0.0, 2.0, 2.3])
    assert predict_mask(logits, 0.5).tolist() == [False, True, True, True]
    assert predict_mask(logits, 0.9).tolist() == [False, False, False, True]
    for bad in (0.0, 1.0, -0.1, 2):
        with pytest.raises(ConfigError):
            threshold_logit(bad)


def test_shape_mismatch_is_a_data_error():
    with pytest.raises(DataError, match="shape"):
        confusion(np.zeros((2, 2), bool), np.zeros((2, 3), np.uint8))
