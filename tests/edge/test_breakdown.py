"""Where the errors are: the boundary band, the breakdown of the pooled union, and void-band scoring.

Hand-made frames with exact counts: a 10 x 10 object (rows/cols 10-19) in a 30 x 30 frame. With
band width B the band covers B + 1 pixels on each side of the outline: rows/cols 9-B .. 20+B,
minus the object's core that is more than B + 1 px inside.
"""

from __future__ import annotations

import numpy as np
import pytest

from edge.errors import ConfigError, DataError
from edge.evaluate import evaluate
from edge.io import Frame
from edge.meta import ModelMeta
from edge.metrics import BreakdownAccumulator, ErrorBreakdown, MetricAccumulator, boundary_band
from edge.predict import Predictor

N = 30
LO, HI = 10, 20  # object rows/cols LO .. HI-1


def square(lo: int = LO, hi: int = HI) -> np.ndarray:
    m = np.zeros((N, N), bool)
    m[lo:hi, lo:hi] = True
    return m


LABEL = square().astype(np.uint8)


def ring(outer: int, inner: int) -> int:
    """Pixels of a square of side ``outer`` minus a centred one of side ``inner``."""
    return outer * outer - inner * inner


def test_band_of_a_square_object():
    # B = 0: the two rings of boundary pixels (rows 9..20 minus 11..18)
    assert boundary_band(LABEL, 0).sum() == ring(12, 8)
    # B = 2: rows 7..22 minus the core 13..16
    band = boundary_band(LABEL, 2)
    assert band.sum() == ring(16, 4)
    assert band[7, 7] and not band[6, 15] and band[13, 12] and not band[13, 13]
    # one class only: no boundary anywhere (the image border is none)
    assert not boundary_band(np.zeros((N, N), np.uint8), 2).any()
    assert not boundary_band(np.ones((N, N), np.uint8), 2).any()


def test_band_matches_brute_force_definition():
    """8-neighbourhood boundary pixels, then chessboard distance <= B, on random labels."""
    rng = np.random.default_rng(3)
    for _ in range(30):
        lab = rng.random((9, 11)) < rng.random()
        px = int(rng.integers(0, 4))
        h, w = lab.shape
        bnd = np.array([[0 < lab[max(i - 1, 0):i + 2, max(j - 1, 0):j + 2].sum() < lab[max(i - 1, 0):i + 2, max(j - 1, 0):j + 2].size
                         for j in range(w)] for i in range(h)])
        ref = np.array([[bnd[max(i - px, 0):i + px + 1, max(j - px, 0):j + px + 1].any() for j in range(w)] for i in range(h)])
        assert (boundary_band(lab, px) == ref).all()


def test_halo_prediction_is_all_boundary_fp():
    acc = BreakdownAccumulator(2)
    frame = acc.add(square(LO - 1, HI + 1), LABEL)  # the object plus a 1 px halo
    assert frame == ErrorBreakdown(2, tp=100, fp_boundary=ring(12, 10))
    sh = acc.summary().shares()
    assert sh["tp"] == pytest.approx(100 / 144) and sh["fp_boundary"] == pytest.approx(44 / 144)
    assert sh["fp_far"] == sh["fn_boundary"] == sh["fn_far"] == 0.0


def test_far_blob_missed_core_and_missed_edge():
    pred = LABEL.astype(bool).copy()
    pred[25:28, 25:28] = True  # false blob 5+ px from the object: outside a 2 px band (rows <= 22)
    pred[15, 15] = False  # missed pixel in the object's core
    pred[LO, LO] = False  # missed corner pixel: on the boundary
    acc = BreakdownAccumulator()  # default B = 2
    assert acc.boundary_px == 2
    acc.add(pred, LABEL)
    b = acc.summary()
    assert b == ErrorBreakdown(2, tp=98, fp_boundary=0, fp_far=9, fn_boundary=1, fn_far=1)
    assert b.union == 109
    assert sum(b.shares().values()) == pytest.approx(1.0)


def test_band_width_option_moves_errors_between_near_and_far():
    pred = square(LO - 2, HI + 2)  # a 2 px halo
    near1 = BreakdownAccumulator(0)
    near1.add(pred, LABEL)
    # B = 0: the band reaches 1 px out, so the outer halo ring is far
    assert near1.summary() == ErrorBreakdown(0, tp=100, fp_boundary=ring(12, 10), fp_far=ring(14, 12))
    wide = BreakdownAccumulator(1)
    wide.add(pred, LABEL)
    assert wide.summary() == ErrorBreakdown(1, tp=100, fp_boundary=ring(14, 10))
    for bad in (-1, 1.5, True):
        with pytest.raises(ConfigError):
            BreakdownAccumulator(bad)


def test_empty_frames():
    z = np.zeros((N, N), np.uint8)
    acc = BreakdownAccumulator()
    acc.add(np.zeros((N, N), bool), z)  # nothing anywhere: no union
    b = acc.summary()
    assert b.union == 0 and b.shares() == {"tp": 1.0, "fp_boundary": 0.0, "fp_far": 0.0, "fn_boundary": 0.0, "fn_far": 0.0}
    acc.add(square(), z)  # predicted object on an empty frame: no boundary, all far
    acc.add(np.zeros((N, N), bool), np.ones((N, N), np.uint8))  # all object, none predicted: far misses
    assert acc.summary() == ErrorBreakdown(2, fp_far=100, fn_far=N * N)


def test_invalid_pixels_are_ignored_but_do_not_move_the_band():
    pred = square(LO - 1, HI + 1)
    pred[15, 15] = False  # a core miss ...
    valid = np.ones((N, N), bool)
    valid[LO - 1, :] = False  # ... the halo's top row and
    valid[15, 15] = False  # the core miss are invalid
    valid[14:17, 14:17] = False  # a hole inside the object: no boundary around it
    acc = BreakdownAccumulator(0)
    acc.add(pred, LABEL, valid)
    assert acc.summary() == ErrorBreakdown(0, tp=100 - 9, fp_boundary=ring(12, 10) - 12)
    with pytest.raises(DataError, match="shape"):
        acc.add(pred, LABEL, valid[:-1])
    with pytest.raises(DataError, match="shape"):
        acc.add(pred[:-1], LABEL, None)


def test_pooled_over_frames_tp_share_is_pooled_iou():
    rng = np.random.default_rng(11)
    bd, m = BreakdownAccumulator(1), MetricAccumulator()
    for _ in range(15):
        label = rng.random((12, 13)) < rng.random()
        pred = rng.random((12, 13)) < 0.4
        valid = rng.random((12, 13)) < 0.9
        bd.add(pred, label, valid)
        m.add(pred, label, valid)
    b, s = bd.summary(), m.summary()
    assert b.tp == s.pooled.tp and b.fp_boundary + b.fp_far == s.pooled.fp and b.fn_boundary + b.fn_far == s.pooled.fn
    assert b.shares()["tp"] == pytest.approx(s.pooled_iou)
    assert sum(b.shares().values()) == pytest.approx(1.0)
    d = b.to_dict()
    assert d["boundary_px"] == 1 and d["counts"]["union"] == b.union
    with pytest.raises(ConfigError):
        b + ErrorBreakdown(2)


class Fixed(Predictor):
    """Logits +/-5 from one fixed object mask, whatever the depth."""

    def __init__(self, mask: np.ndarray):
        self.meta = ModelMeta(encoder="vgg11", width=0.125, batch_norm=True, in_channels=1, threshold=0.5)
        self.name = "fixed"
        self.mask = mask

    def logits(self, depth):
        return np.where(self.mask, 5.0, -5.0).astype(np.float32)


def test_ignore_boundary_scores_beside_the_plain_ones():
    depth = np.full((N, N), 0.3, np.float32)
    depth[0, :] = 0.0  # invalid row, far from the object
    pred = square(LO - 1, HI + 1)  # 1 px halo
    pred[15, 15] = False  # one core miss
    frames = [Frame(depth=depth, stamp_ns=0, label=LABEL)]
    r = evaluate(Fixed(pred), iter(frames))
    assert r.ignore_boundary_px is None and r.ignore_boundary is None and "ignore_boundary" not in r.to_dict()
    assert r.metrics.iou == pytest.approx(99 / 144)
    r = evaluate(Fixed(pred), iter(frames), ignore_boundary=0, boundary_px=0)
    assert r.metrics.iou == pytest.approx(99 / 144)  # the plain score is unchanged
    ig = r.ignore_boundary
    # the void band (rows/cols 9..20 minus 11..18) holds the halo and the object's outer ring
    assert ig.pooled.tp == 63 and ig.pooled.fp == 0 and ig.pooled.fn == 1
    assert ig.pooled.total == N * N - N - ring(12, 8)
    assert ig.iou == pytest.approx(63 / 64) and ig.precision == 1.0 and ig.recall == pytest.approx(63 / 64)
    assert ig.pooled_iou == pytest.approx(63 / 64)
    d = r.to_dict()
    assert d["ignore_boundary"]["px"] == 0 and d["ignore_boundary"]["iou"] == ig.iou
    assert d["iou"] == r.metrics.iou
    assert d["breakdown"]["boundary_px"] == 0 and d["breakdown"]["fp_boundary"] == pytest.approx(44 / 144)
    assert d["breakdown"]["fn_far"] == pytest.approx(1 / 144)
    with pytest.raises(ConfigError):
        evaluate(Fixed(pred), iter(frames), ignore_boundary=-1)
    with pytest.raises(ConfigError):
        evaluate(Fixed(pred), iter(frames), boundary_px=-1)


def test_ignore_boundary_when_every_pixel_is_void():
    """A frame whose valid pixels all lie in the void band has no void-band score, only the plain one."""
    label = np.zeros((4, 4), np.uint8)
    label[:2] = 1
    frames = [Frame(depth=np.full((4, 4), 0.3, np.float32), stamp_ns=0, label=label)]
    r = evaluate(Fixed(label > 0), iter(frames), ignore_boundary=1)
    assert r.metrics.iou == 1.0 and r.ignore_boundary is None
    assert r.to_dict()["ignore_boundary"] == {"px": 1, "frames": 0}
