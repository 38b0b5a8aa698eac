"""--with-preprocessing: raw depth in, probability out, equal to edge.preprocess + the model."""

from __future__ import annotations

import numpy as np
import onnx
import pytest
from exportgen import blensor_frames, dead_pixel_frames, tiny_model

from edge.errors import DataError
from edge.infer import Segmenter, sigmoid
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
