"""ONNX export: one self-contained file, named dynamic I/O, metadata, and agreement with PyTorch."""

from __future__ import annotations

import numpy as np
import onnx
import pytest
import torch
from exportgen import blensor_frames, dead_pixel_frames, tiny_model
from tinymodel import one_torch_thread

from edge.errors import ModelError
from edge.infer import Segmenter
from edge.meta import ModelMeta
from export.onnx_export import FLIP_TOL, LOGIT_ATOL, check_against_torch, export_onnx, torch_logits
from export.single_channel import to_single_channel


@pytest.fixture(scope="module")
def exported(plain_onnx, tiny1):
    return plain_onnx, *tiny1


def test_file_is_self_contained_with_named_dynamic_io(exported):
    path, _model, _meta = exported
    assert sorted(p.name for p in path.parent.iterdir()) == ["tiny.onnx"]  # no .onnx.data, no temp left
    proto = onnx.load(str(path), load_external_data=False)
    onnx.checker.check_model(proto, full_check=True)
    assert not any(t.data_location == onnx.TensorProto.EXTERNAL for t in proto.graph.initializer)
    assert max(o.version for o in proto.opset_import if o.domain in ("", "ai.onnx")) >= 17
    (inp,), (out,) = proto.graph.input, proto.graph.output
    assert (inp.name, out.name) == ("depth", "logits")
    dims = [d.dim_param or d.dim_value for d in inp.type.tensor_type.shape.dim]
    assert dims[1] == 1 and all(isinstance(d, str) and d for d in (dims[0], dims[2], dims[3]))


def test_metadata_round_trip(exported):
    path, _model, meta = exported
    props = {p.key: p.value for p in onnx.load(str(path), load_external_data=False).metadata_props}
    assert ModelMeta.from_onnx_props(props) == meta
    assert props["in_channels"] == "1" and props["input_size"] == "171x224" and props["precision"] == "fp32"
    assert props["params"] == str(meta.params) and float(props["threshold"]) == meta.threshold
    assert "fx=" in props["intrinsics"] and "pad to multiple of 32" in props["preprocessing"].replace("zero-pad", "pad")
    assert '"purpose": "tests"' in props["training"]
    seg = Segmenter(path, threads=1)
    assert seg.meta == meta and seg.threshold == meta.threshold and not seg.with_preprocessing


def test_onnx_matches_pytorch_on_frames_with_dead_pixels(exported):
    path, model, meta = exported
    frames = dead_pixel_frames(1) + blensor_frames(2)
    check = check_against_torch(path, model, meta, frames, "dead-pixel frames")
    assert check.ok and check.frames == len(frames)
    assert check.max_abs_diff <= LOGIT_ATOL * max(1.0, check.max_abs_logit)
    assert check.flip_fraction <= FLIP_TOL and check.batch_max_abs_diff <= check.tolerance
    assert check.max_abs_logit > 1.0


def test_other_frame_sizes_run_through_dynamic_height_and_width(exported):
    path, model, meta = exported
    d = np.random.default_rng(3).uniform(0.2, 0.4, (100, 150)).astype(np.float32)  # pads to 128 x 160
    got = Segmenter(path, threads=1).logits(d)
    assert got.shape == (100, 150)
    np.testing.assert_allclose(got, torch_logits(model, meta, d), atol=1e-4)


def test_check_fails_when_the_file_does_not_compute_the_model(exported):
    path, model, meta = exported
    other, _ = tiny_model(5, in_channels=3)
    other, _ = to_single_channel(other, meta.with_(in_channels=3))
    with torch.no_grad():
        other.classifier.bias += 0.5
    with pytest.raises(ModelError, match="differs from PyTorch beyond tolerance"):
        check_against_torch(path, other, meta, dead_pixel_frames(0)[:2])


def test_a_full_skip_model_exports_and_matches_pytorch(tmp_path):
    with one_torch_thread():
        model, meta = to_single_channel(*tiny_model(3, in_channels=3, extra_skip=True, full_skip=True))
        path = export_onnx(model, meta, tmp_path / "full.onnx")
    assert Segmenter(path, threads=1).meta.full_skip
    check = check_against_torch(path, model, meta, dead_pixel_frames(1), "dead-pixel frames")
    assert check.ok and check.max_abs_logit > 1.0
