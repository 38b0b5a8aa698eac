"""--with-preprocessing: raw depth in, probability out, equal to edge.preprocess + the model."""

from __future__ import annotations

import dataclasses

import numpy as np
import onnx
import pytest
from exportgen import blensor_frames, dead_pixel_frames, tiny_model

from edge.errors import DataError
from edge.infer import Segmenter, sigmoid
from edge.meta import ModelMeta
from edge.preprocess import valid_mask
from export.onnx_export import torch_logits
from export.preproc_graph import PROB_ATOL, check_against_python, export_with_preprocessing


@pytest.fixture(scope="module")
def graphs(edge_onnx, plain_onnx, tiny1):
    return edge_onnx, *tiny1, plain_onnx


def test_graph_io_is_raw_depth_in_probability_out(graphs):
    path, _model, meta, _d = graphs
    proto = onnx.load(str(path), load_external_data=False)
    (inp,) = proto.graph.input
    assert inp.name == "depth"
    assert [d.dim_value for d in inp.type.tensor_type.shape.dim][1:] == [171, 224]
    assert [o.name for o in proto.graph.output] == ["probability", "valid"]
    props = {p.key: p.value for p in proto.metadata_props}
    assert props["graph"] == "with-preprocessing" and props["in_channels"] == str(meta.in_channels)


def test_graph_equals_the_python_path_on_frames_with_dead_pixels(graphs):
    path, model, meta, _d = graphs
    frames = dead_pixel_frames(2) + blensor_frames(2)
    check = check_against_python(path, model, meta, frames)
    assert check.ok and check.valid_mismatch == 0 and check.max_abs_prob_diff <= PROB_ATOL
    assert check.max_abs_height_diff_m is None  # no height cue, no height output
    seg = Segmenter(path, threads=1)
    assert seg.with_preprocessing
    for d in frames[3:5]:  # the NaN/negative/inf frame and the all-invalid one, checked by hand too
        pred = seg.predict(d)
        ref = sigmoid(torch_logits(model, meta, d))
        valid = valid_mask(d)
        np.testing.assert_array_equal(pred.valid, valid)
        np.testing.assert_allclose(pred.prob, ref, atol=PROB_ATOL)
        assert (pred.mask[~valid] == 255).all() and set(np.unique(pred.mask[valid])) <= {0, 1}
    both = seg.predict(frames[0]).mask[valid_mask(frames[0])]
    assert 0 < both.mean() < 1  # both classes present: the comparison is not vacuous


def test_pixels_beyond_the_sensor_range_are_no_return_in_both_paths(graphs):
    path, model, meta, plain = graphs
    d = dead_pixel_frames(1)[0].copy()
    far = np.zeros(d.shape, bool)
    far[::17, ::13] = True  # a 16UC1 65535 read as metres, and a pixel just past the range
    d[far] = 65.535
    d[5, 7] = np.nextafter(np.float32(meta.sensor.max_range_m), np.float32(np.inf))
    far[5, 7] = True
    check = check_against_python(path, model, meta, [d])
    assert check.ok and check.valid_mismatch == 0
    for seg in (Segmenter(path, threads=1), Segmenter(plain, threads=1)):
        pred = seg.predict(d)
        assert not pred.valid[far].any() and (pred.mask[far] == 255).all()
        np.testing.assert_array_equal(pred.valid, valid_mask(d) & ~far)


def test_graph_and_plain_model_give_the_same_mask(graphs):
    path, model, meta, plain = graphs
    a, b = Segmenter(path, threads=1), Segmenter(plain, threads=1)
    for f in dead_pixel_frames(3)[:4]:
        pa, pb = a.predict(f), b.predict(f)
        np.testing.assert_allclose(pa.prob, pb.prob, atol=PROB_ATOL)
        assert np.mean(pa.mask != pb.mask) < 1e-3
    np.testing.assert_allclose(a.logits_batch(dead_pixel_frames(3)[:2]), b.logits_batch(dead_pixel_frames(3)[:2]), atol=1e-2)


def test_graph_refuses_a_frame_of_another_size(graphs):
    path, *_ = graphs
    with pytest.raises(DataError, match="exported for 171x224"):
        Segmenter(path, threads=1).predict(np.ones((100, 100), np.float32))


def test_three_channel_graph_equals_the_python_path(tmp_path):
    model, meta = tiny_model(1, in_channels=3)
    path = export_with_preprocessing(model, meta, tmp_path / "edge3.onnx")
    assert Segmenter(path, threads=1).meta.in_channels == 3
    check = check_against_python(path, model, meta, dead_pixel_frames(4)[2:5])
    assert check.ok and check.max_abs_prob_diff <= PROB_ATOL


# -- robust standardisation and the height cue (issue 9 models) -------------------------------

ROBUST_HEIGHT = {"standardize": "robust", "cues": ("height",)}


def _cue_model(seed: int = 3, **kw):
    """`exportgen.tiny_model` with ``kw`` (standardize, cues), converted to one depth channel."""
    from export.single_channel import to_single_channel

    return to_single_channel(*tiny_model(seed, **kw))


def _hard_frames() -> list[np.ndarray]:
    """Frames for every branch: few or no grid points (full-frame statistics, median plane),
    collinear grid points (no usable hypothesis), far and saturated pixels, heavy noise."""
    from edge.sampleframes import synthetic_frames

    rng = np.random.default_rng(11)
    base = synthetic_frames(1, 9).depth[0]
    out = []
    f = np.zeros_like(base)
    f[1::12] = base[1::12]  # no grid point valid, many pixels: full-frame statistics and median
    out.append(f)
    f = np.zeros_like(base)
    f[0, :] = base[0, :]  # one grid row: every triplet is collinear
    out.append(f)
    f = np.zeros_like(base)
    f[80:87, 100:107] = base[80:87, 100:107]  # four grid points
    out.append(f)
    f = np.zeros_like(base)
    f[1::2, 1::2] = base[1::2, 1::2]  # even number of valid pixels, none on the grid
    out.append(f)
    f = base.copy()
    f[rng.random(f.shape) < 0.02] = 65.535  # saturated 16-bit pixels
    out.append(f)
    f = base + rng.normal(0, 0.01, base.shape).astype(np.float32)
    out.append(f)
    f = base.copy()
    f[rng.random(f.shape) < 0.95] = 0.0  # 5 % valid
    out.append(f)
    f = base.copy()
    rows, cols = np.mgrid[0 : f.shape[0], 0 : f.shape[1]]
    f[rows < 0.8 * cols - 20] += 0.45  # a table edge, the floor 45 cm below: planes in front count against
    out.append(f)
    return out


@pytest.fixture(scope="module")
def cue_frames():
    from edge.sampleframes import synthetic_frames

    return synthetic_frames(6, 21).depth + dead_pixel_frames(5) + _hard_frames() + blensor_frames(2)


@pytest.mark.parametrize("standardize", ["valid-pixels", "robust"])
@pytest.mark.parametrize("cues", [(), ("height",), ("height", "steepness")])
@pytest.mark.parametrize("channels", [1, 3])
def test_preprocessing_module_equals_edge_preprocess(standardize, cues, channels, cue_frames):
    """The torch module itself (no export): bit-identical to numpy on every branch, in a batch."""
    import torch

    from edge.preprocess import preprocess_for
    from export.preproc_graph import PreprocGraph

    meta = ModelMeta(encoder="vgg11", width=0.125, batch_norm=True, in_channels=channels,
                     standardize=standardize, cues=cues)
    with torch.no_grad():
        x, valid = PreprocGraph(meta)(torch.from_numpy(np.stack(cue_frames)))
    for i, f in enumerate(cue_frames):
        ref = preprocess_for(f, meta)
        np.testing.assert_array_equal(valid[i].numpy(), ref.valid)
        assert x.shape[1:] == ref.x.shape
        np.testing.assert_array_equal(x[i].numpy(), ref.x, err_msg=f"frame {i}")


def test_robust_height_graph_matches_numpy_in_onnxruntime(tmp_path, cue_frames):
    """The exported preprocessing in onnxruntime: depth channel and height cue vs edge.preprocess."""
    import onnxruntime as ort

    from edge.cues import fit_dominant_plane
    from edge.preprocess import preprocess_for
    from export.preproc_graph import HEIGHT_ATOL_CM, export_preprocessing

    meta = ModelMeta(encoder="vgg11", width=0.125, batch_norm=True, in_channels=1, **ROBUST_HEIGHT)
    path = export_preprocessing(meta, tmp_path / "pre.onnx")
    ops = {n.op_type for n in onnx.load(str(path)).graph.node}
    assert {"TopK", "ArgMax", "If"} <= ops and "Loop" not in ops
    so = ort.SessionOptions()
    so.intra_op_num_threads = 1
    sess = ort.InferenceSession(str(path), so, providers=["CPUExecutionProvider"])
    x, valid = sess.run(None, {"depth": np.stack(cue_frames)})
    kinds = set()
    for i, f in enumerate(cue_frames):
        ref = preprocess_for(f, meta)
        np.testing.assert_array_equal(valid[i], ref.valid)
        np.testing.assert_allclose(x[i, 0], ref.x[0], rtol=0, atol=1e-6, err_msg=f"depth channel, frame {i}")
        np.testing.assert_allclose(x[i, 1], ref.x[1], rtol=0, atol=HEIGHT_ATOL_CM, err_msg=f"height cue, frame {i}")
        fit = fit_dominant_plane(f, ref.valid)
        kinds.add("plane" if fit.ok else "fallback")
    assert kinds == {"plane", "fallback"}  # both the RANSAC and the If branch were exercised
    one, _ = sess.run(None, {"depth": cue_frames[0][None]})  # batch of one: the same numbers
    np.testing.assert_array_equal(one[0], x[0])


def test_steepness_graph_matches_numpy_in_onnxruntime(tmp_path, cue_frames):
    """The steepness cue exported: the same float32 operations as `edge.cues.steepness_cue` in onnxruntime."""
    import onnxruntime as ort

    from edge.preprocess import preprocess_for
    from export.preproc_graph import export_preprocessing

    meta = ModelMeta(encoder="vgg11", width=0.125, batch_norm=True, in_channels=1, standardize="robust",
                     cues=("steepness",))
    path = export_preprocessing(meta, tmp_path / "pre.onnx")
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    x, _ = sess.run(None, {"depth": np.stack(cue_frames)})
    steep = 0
    for i, f in enumerate(cue_frames):
        ref = preprocess_for(f, meta)
        np.testing.assert_array_equal(x[i, 1], ref.x[1], err_msg=f"steepness, frame {i}")
        steep += int((ref.x[1] > 0.5).sum())
    assert steep > 100  # the frames have steep surfaces, not only zeros


@pytest.fixture(scope="module")
def robust_height(tmp_path_factory):
    from tinymodel import one_torch_thread

    from export.onnx_export import export_onnx

    with one_torch_thread():  # module fixtures run before the autouse one
        model, meta = _cue_model(**ROBUST_HEIGHT)
        d = tmp_path_factory.mktemp("cues")
        return model, meta, export_with_preprocessing(model, meta, d / "pre.onnx"), export_onnx(model, meta, d / "plain.onnx")


def test_robust_height_model_with_preprocessing_equals_the_python_path(robust_height, cue_frames):
    model, meta, path, plain = robust_height
    assert meta.in_channels == 1 and meta.net_channels == 2
    seg, ref = Segmenter(path, threads=1), Segmenter(plain, threads=1)
    assert seg.with_preprocessing and seg.meta.cues == ("height",) and seg.meta.standardize == "robust"
    agree, n_valid, both = 0, 0, []
    for f in cue_frames:
        a, b = seg.predict(f), ref.predict(f)
        np.testing.assert_array_equal(a.valid, b.valid)
        agree += int(np.count_nonzero((a.mask == b.mask) & b.valid))
        n_valid += int(b.valid.sum())
        both.append(b.mask[b.valid].mean() if b.valid.any() else 0.5)
        np.testing.assert_allclose(a.prob, sigmoid(torch_logits(model, meta, f)), atol=PROB_ATOL)
    assert agree / n_valid >= 0.999
    assert 0 < np.mean(both) < 1  # both classes present: the comparison is not vacuous
    check = check_against_python(path, model, meta, cue_frames[:4], threads=1)
    assert check.ok and check.valid_mismatch == 0
    assert check.max_abs_height_diff_m is not None and "max |height diff|" in check.summary()


def test_a_height_cue_graph_returns_the_heights_the_height_rule_needs(robust_height, cue_frames):
    from edge.cues import HEIGHT_SCALE
    from edge.postprocess import support_height
    from export.preproc_graph import HEIGHT_ATOL_CM

    _model, _meta, path, plain = robust_height
    proto = onnx.load(str(path), load_external_data=False)
    assert [o.name for o in proto.graph.output] == ["probability", "valid", "height"]
    seg, ref = Segmenter(path, threads=1, min_height_m=0.01), Segmenter(plain, threads=1, min_height_m=0.01)
    off = Segmenter(path, threads=1)
    agree, n_valid, removed = 0, 0, 0
    for f in cue_frames:
        a, b = seg.predict(f), ref.predict(f)
        np.testing.assert_allclose(a.height_m, support_height(f, a.valid), rtol=0, atol=HEIGHT_ATOL_CM / HEIGHT_SCALE)
        agree += int(np.count_nonzero((a.mask == b.mask) & b.valid))
        n_valid += int(b.valid.sum())
        removed += int(np.count_nonzero((off.predict(f).mask == 1) & (a.mask == 0)))
    assert agree / n_valid >= 0.999
    assert removed > 0  # the height rule changed pixels: the comparison is not vacuous


def test_unsupported_preprocessing_is_one_line_model_error(monkeypatch, tmp_path):
    import export.preproc_graph as pg
    from edge.errors import ModelError

    model, meta = tiny_model(1, in_channels=3)
    robust = meta.with_(standardize="robust")
    monkeypatch.setattr(pg, "SUPPORTED_STANDARDIZE", ("valid-pixels",))
    with pytest.raises(ModelError, match="standardize='robust'") as err:
        export_with_preprocessing(model, robust, tmp_path / "x.onnx")
    assert "\n" not in str(err.value)
    monkeypatch.setattr(pg, "SUPPORTED_CUES", ())
    with pytest.raises(ModelError, match=r"cue\(s\) \['height'\]") as err:
        export_with_preprocessing(model, meta.with_(cues=("height",)), tmp_path / "x.onnx")
    assert "\n" not in str(err.value)
    monkeypatch.undo()
    with pytest.raises(ModelError, match="first conv takes 3 channels but its metadata says 2") as err:
        pg.check_supported(meta.with_(in_channels=1, cues=("height",)), model)
    assert not (tmp_path / "x.onnx").exists()


def test_a_height_output_off_the_numpy_plane_fails_the_check():
    from export.preproc_graph import PreprocCheck

    base = dict(frames=1, source="x", max_abs_prob_diff=0.0, tolerance=PROB_ATOL, valid_mismatch=0, flip_fraction=0.0)
    assert PreprocCheck(**base).ok and PreprocCheck(**base, max_abs_height_diff_m=0.0).ok
    bad = PreprocCheck(**base, max_abs_height_diff_m=1e-3)  # 1 mm: another plane
    assert not bad.ok and "max |height diff| 1.00e-03 m" in bad.summary()


def test_int8_leaves_the_height_output_exact(robust_height, tmp_path):
    # --int8 quantises the network's input; the height output comes from the cue before it
    from edge.sampleframes import synthetic_frames
    from export import quantize

    _model, _meta, path, _plain = robust_height
    q = quantize.quantize_int8(path, tmp_path / "int8.onnx", synthetic_frames(4, 0))
    rep = quantize.iou_report(path, q, synthetic_frames(3, 50), threads=1)
    assert rep.layers["int8"].get("QLinearConv", 0) > 0  # the network did go int8
    assert rep.max_abs_height_diff_m == 0.0 and "max |height diff| 0.00e+00 m" in rep.summary()
    bad = dataclasses.replace(rep, max_abs_height_diff_m=0.004)  # the quantiser reaching the cue
    assert not bad.ok and "changed the graph's height output by up to 4.00e-03 m" in quantize.refuse_message(bad)
