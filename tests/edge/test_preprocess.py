"""The one preprocessing: valid-pixel standardisation, invalid -> 0, zero padding, channels."""

from __future__ import annotations

import numpy as np
import pytest

from edge.errors import DataError
from edge.preprocess import padded_shape, preprocess, preprocess_batch, standardize, valid_mask


def frame(h=171, w=224, seed=0):
    rng = np.random.default_rng(seed)
    d = rng.uniform(0.2, 0.4, (h, w)).astype(np.float32)
    d[:5, :5] = 0.0
    d[-5:, -5:] = np.nan
    d[10, :20] = -0.3
    d[20, :7] = np.inf
    d[21, :3] = -np.inf
    return d


def test_valid_mask_marks_zero_negative_nan_inf():
    d = frame()
    v = valid_mask(d)
    assert not v[:5, :5].any() and not v[-5:, -5:].any() and not v[10, :20].any()
    assert not v[20, :7].any() and not v[21, :3].any()
    assert v.sum() == d.size - 25 - 25 - 20 - 7 - 3


def test_a_range_makes_farther_pixels_invalid_and_preprocess_for_uses_the_sensors():
    from edge.meta import ModelMeta
    from edge.preprocess import preprocess_for, valid_for

    d = frame()
    d[30, :4] = [4.0, 4.0001, 65.535, 1e30]
    assert valid_mask(d)[30, :4].all()  # the plain rule: any positive finite number
    assert valid_mask(d, 4.0)[30, :4].tolist() == [True, False, False, False]
    meta = ModelMeta(encoder="vgg11", in_channels=1)
    pre = preprocess_for(d, meta)
    assert meta.sensor.max_range_m == 4.0
    assert pre.valid[30, :4].tolist() == [True, False, False, False]
    np.testing.assert_array_equal(valid_for(d, meta), pre.valid)  # the one rule, for callers without x
    assert (pre.x[0, 30, 1:4] == 0).all()  # no return -> 0, like a dead pixel


def test_valid_pixels_have_mean_zero_std_one_and_invalid_become_zero():
    d = frame()
    p = preprocess(d, channels=1)
    v = p.valid
    x = p.x[0, :171, :224]
    assert x[v].mean() == pytest.approx(0.0, abs=1e-5)
    assert x[v].std() == pytest.approx(1.0, abs=1e-4)
    assert np.all(x[~v] == 0.0)
    assert np.isfinite(p.x).all()
    assert p.mean == pytest.approx(float(d[v].astype(np.float64).mean()))
    assert p.std == pytest.approx(float(d[v].astype(np.float64).std()))


def test_statistics_ignore_invalid_values():
    a = frame()
    b = a.copy()
    b[:5, :5] = -5.0  # another invalid marker instead of 0: must not change the statistics
    b[-5:, -5:] = np.inf
    pa, pb = preprocess(a), preprocess(b)
    assert np.array_equal(pa.x, pb.x) and pa.mean == pb.mean and pa.std == pb.std


def test_padding_to_192x224_is_zero_at_bottom_right():
    p = preprocess(frame(), channels=1)
    assert p.x.shape == (1, 192, 224) and p.x.dtype == np.float32
    assert p.shape == (171, 224)
    assert np.all(p.x[:, 171:, :] == 0.0)
    assert padded_shape(171, 224) == (192, 224)
    assert padded_shape(64, 96) == (64, 96)
    assert padded_shape(1, 33) == (32, 64)
    q = preprocess(frame(40, 50), channels=1)
    assert q.x.shape == (1, 64, 64)
    assert np.all(q.x[:, 40:, :] == 0) and np.all(q.x[:, :, 50:] == 0)
    r = preprocess(frame(30, 20), channels=3, multiple=8)  # another multiple: the frame sits top-left
    assert r.x.shape == (3, 32, 24) and not r.x[:, 30:, :].any() and not r.x[:, :, 20:].any()


def test_all_invalid_frame_gives_zeros():
    d = np.zeros((171, 224), np.float32)
    d[0] = np.nan
    p = preprocess(d, channels=3)
    assert not p.valid.any()
    assert np.all(p.x == 0.0) and p.mean == 0.0 and p.std == 1.0


def test_constant_frame_standardises_to_zero():
    p = preprocess(np.full((32, 32), 0.3, np.float32))
    assert np.all(p.x == 0.0)


def test_three_channel_replication():
    d = frame(seed=3)
    p1, p3 = preprocess(d, channels=1), preprocess(d, channels=3)
    assert p3.x.shape == (3, 192, 224)
    for c in range(3):
        assert np.array_equal(p3.x[c], p1.x[0])


def test_standardize_matches_preprocess():
    d = frame(seed=4)
    z, m, s = standardize(d)
    p = preprocess(d)
    assert np.array_equal(p.x[0, :171], z) and (m, s) == (p.mean, p.std)


def test_batch_and_bad_input():
    x, v = preprocess_batch([frame(seed=1), frame(seed=2)], channels=1)
    assert x.shape == (2, 1, 192, 224) and v.shape == (2, 171, 224)
    with pytest.raises(DataError, match="share one size"):
        preprocess_batch([frame(), frame(64, 96)])
    with pytest.raises(DataError, match="2-D"):
        preprocess(np.zeros((2, 3, 4)))
    with pytest.raises(DataError, match="channels"):
        preprocess(frame(), channels=2)
    with pytest.raises(DataError, match="numeric"):
        preprocess(np.array([["a"]]))
    # 1 x H x W is accepted as a single frame
    assert preprocess(frame()[None]).x.shape == (1, 192, 224)
