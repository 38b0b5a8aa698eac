"""edge.infer.Segmenter: the torch-free ONNX engine (hand-built models; real exports in tests/export)."""

from __future__ import annotations

import numpy as np
import pytest
from onnxgen import linear_model, raw_model

from edge.errors import ConfigError, DataError, ModelError
from edge.infer import UNKNOWN, Segmenter, sigmoid
from edge.postprocess import remove_specks
from edge.preprocess import preprocess, valid_mask
from edge.sampleframes import synthetic_frames


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    d = tmp_path_factory.mktemp("infer")
    return {
        "plain": linear_model(d / "plain.onnx", threshold=0.4),
        "three": linear_model(d / "three.onnx", channels=3),
        "raw": raw_model(d / "raw.onnx"),
        "dir": d,
    }


@pytest.fixture(scope="module")
def frames():
    fs = synthetic_frames(3, 7).depth
    f = fs[0].copy()
    f[5:9, 40:80] = np.nan
    f[60, 10:30] = -1.0
    f[70, 10:30] = np.inf
    return [f] + fs[1:]


def test_predict_gives_probability_mask_and_unknown_for_invalid_pixels(models, frames):
    seg = Segmenter(models["plain"], threads=1)
    assert seg.threshold == 0.4 and not seg.with_preprocessing and seg.precision == "fp32"
    assert seg.min_object_px == 6
    removed = 0
    for d in frames:
        p = seg.predict(d)
        valid = valid_mask(d)
        assert p.prob.dtype == np.float32 and p.prob.shape == d.shape and p.mask.dtype == np.uint8
        assert 0.0 <= p.prob.min() and p.prob.max() <= 1.0
        np.testing.assert_array_equal(p.valid, valid)
        assert (p.mask[~valid] == UNKNOWN).all()
        # the threshold rule, then the speck rule (edge.postprocess) with the model's 6 px
        expected = remove_specks((p.prob >= 0.4) & valid, seg.min_object_px)
        removed += int((expected != ((p.prob >= 0.4) & valid)).sum())
        np.testing.assert_array_equal(p.mask[valid], expected[valid].astype(np.uint8))
        bare = Segmenter(models["plain"], threads=1, min_object_px=0).predict(d)
        np.testing.assert_array_equal(bare.mask[valid], (p.prob[valid] >= 0.4).astype(np.uint8))
        assert 0 < p.mask[valid].mean() < 1  # both classes: the checks above are not vacuous
        np.testing.assert_allclose(p.prob, sigmoid(seg.logits(d)), atol=1e-6)
        assert set(p.timings) == {"pre", "infer", "post", "total"} and min(p.timings.values()) >= 0
        assert p.timings["total"] >= p.timings["infer"]
    assert removed > 0  # the speck rule had specks to remove: the comparison above is not vacuous


def test_logits_follow_edge_preprocess(models, frames):
    seg = Segmenter(models["plain"], threads=1)
    d = frames[0]
    pre = preprocess(d)
    expected = -4.0 * pre.x[0, : d.shape[0], : d.shape[1]]
    np.testing.assert_allclose(seg.logits(d), expected, atol=1e-5)
    batch = seg.logits_batch(frames)
    assert batch.shape == (3, *d.shape)
    for b, f in zip(batch, frames):
        np.testing.assert_allclose(b, seg.logits(f), atol=1e-6)


def test_threshold_argument_overrides_the_metadata(models, frames):
    low, high = Segmenter(models["plain"], threads=1, threshold=0.1), Segmenter(models["plain"], threads=1, threshold=0.9)
    assert high.threshold == 0.9 and high.meta.threshold == 0.4
    a, b = low.predict(frames[1]).mask, high.predict(frames[1]).mask
    assert (a == 1).sum() > (b == 1).sum()
    with pytest.raises(ConfigError, match=r"threshold must lie in \(0, 1\)"):
        Segmenter(models["plain"], threshold=1.0)


def test_three_channel_model_gets_three_channels(models, frames):
    one, three = Segmenter(models["plain"], threads=1), Segmenter(models["three"], threads=1)
    assert three.meta.in_channels == 3
    np.testing.assert_allclose(three.logits(frames[0]), one.logits(frames[0]), atol=1e-5)


def test_with_preprocessing_model_takes_raw_depth(models, frames):
    seg = Segmenter(models["raw"], threads=1)
    assert seg.with_preprocessing
    d = frames[0]
    p = seg.predict(d)
    valid = valid_mask(d)
    np.testing.assert_array_equal(p.valid, valid)
    with np.errstate(invalid="ignore"):
        expected = 1.0 / (1.0 + np.exp(-40.0 * (0.3 - np.where(valid, d, 0.3))))
    np.testing.assert_allclose(p.prob, expected, atol=1e-6)
    assert (p.mask[~valid] == UNKNOWN).all() and 0 < p.mask[valid].mean() < 1
    np.testing.assert_allclose(sigmoid(seg.logits(d)), p.prob, atol=1e-5)
    assert seg.logits_batch(frames[:2]).shape == (2, *d.shape)
    with pytest.raises(DataError, match="exported for 171x224"):
        seg.predict(d[:100])


def test_bad_frames_are_refused(models):
    seg = Segmenter(models["plain"], threads=1)
    with pytest.raises(DataError, match="2-D"):
        seg.predict(np.zeros((2, 3, 4), np.float32))
    with pytest.raises(DataError, match="at least one frame"):
        seg.logits_batch([])


@pytest.mark.parametrize(
    "make, needle",
    [
        (lambda d: d / "missing.onnx", "no such model file"),
        (lambda d: d, "is a directory"),
        (lambda d: (d / "garbage.onnx").write_bytes(b"\x08\x07 not protobuf" * 20) and d / "garbage.onnx",
         "not a readable ONNX model"),
        (lambda d: (d / "empty.onnx").write_bytes(b"") or d / "empty.onnx", "not a readable ONNX model"),
        (lambda d: linear_model(d / "nometa.onnx", with_meta=False), "no 'depthseg' metadata"),
        (lambda d: linear_model(d / "mismatch.onnx", channels=3, meta_channels=1), "3 channels but its metadata says 1"),
    ],
    ids=["missing", "directory", "garbage", "empty", "no-metadata", "channel-mismatch"],
)
def test_bad_model_files_give_one_line_errors(tmp_path, make, needle):
    path = make(tmp_path)
    with pytest.raises(ModelError) as exc:
        Segmenter(path, threads=1)
    msg = str(exc.value)
    assert needle in msg and "\n" not in msg and str(path.name) in msg


def test_truncated_model_file_is_refused(models, tmp_path):
    data = models["plain"].read_bytes()
    cut = tmp_path / "cut.onnx"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(ModelError, match="not a readable ONNX model|no 'depthseg' metadata"):
        Segmenter(cut, threads=1)


def test_segmenter_marks_objects_and_unknown_in_both_graph_kinds(models, frames):
    """(The torch-free run of the same is tests/test_torch_free.py.)"""
    p = Segmenter(models["plain"], threads=1).predict(frames[0])
    raw = Segmenter(models["raw"], threads=1).predict(frames[0])
    invalid = int((~valid_mask(frames[0])).sum())
    assert int((p.mask == 1).sum()) > 0 and int((p.mask == 255).sum()) == invalid == int((raw.mask == 255).sum())


def test_a_negative_speck_size_is_refused_before_any_frame(models):
    with pytest.raises(ConfigError, match="min_object_px"):
        Segmenter(models["plain"], threads=1, min_object_px=-1)
