"""export.fold: the affine head as two matrix products computes what the trained layers compute."""

from __future__ import annotations

import onnx
import pytest
import torch
from tinymodel import tiny_model

from edge.errors import ModelError
from edge.train.model import FCN8s
from export.fold import FoldedFCN8s, fold_head, folded
from export.onnx_export import export_onnx


def _with_moved_head_statistics(model: FCN8s, seed: int) -> FCN8s:
    """The last BatchNorm with non-trivial scale, shift, mean and variance (what the fold must absorb)."""
    g = torch.Generator().manual_seed(seed)
    bn = model.bns[-1]
    with torch.no_grad():
        n = bn.num_features
        bn.weight.copy_(torch.rand(n, generator=g) * 2 + 0.2)
        bn.bias.copy_(torch.randn(n, generator=g))
        bn.running_mean.copy_(torch.randn(n, generator=g))
        bn.running_var.copy_(torch.rand(n, generator=g) * 3 + 0.05)
    return model


@pytest.mark.parametrize("skips", [{}, {"extra_skip": True}, {"extra_skip": True, "full_skip": True}])
def test_the_folded_head_gives_the_trained_logits(skips):
    model, _meta = tiny_model(2, in_channels=1, **skips)
    model = _with_moved_head_statistics(model, 4)
    x = torch.randn(2, 1, 64, 96, generator=torch.Generator().manual_seed(0))
    with torch.no_grad():
        want = model(x)
        got = FoldedFCN8s(model)(x)
    assert got.shape == want.shape == (2, 1, 64, 96)
    assert float(want.abs().max()) > 1.0  # not a vacuous comparison of near-zero maps
    torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-5)
    with torch.no_grad():
        assert torch.equal(model(x), want)  # the fold works on its own copy


def test_fold_head_absorbs_the_projection_only_with_the_full_skip():
    plain, _ = tiny_model(2, in_channels=1)
    full, _ = tiny_model(2, in_channels=1, full_skip=True)
    a, b, c = fold_head(plain)
    assert a.shape == (1, plain.classifier.in_channels) and b is None and c.shape == (1, 1)
    a, b, c = fold_head(full)
    assert b is not None and b.shape == (1, full.encoder.out_channels["conv1"])


def test_a_classifier_with_more_than_one_output_is_refused():
    model, _ = tiny_model(2, in_channels=1)
    model.classifier = torch.nn.Conv2d(model.classifier.in_channels, 2, kernel_size=1)
    with pytest.raises(ModelError, match="one output"):
        fold_head(model)
    assert folded(torch.nn.Identity()).__class__ is torch.nn.Identity  # anything else passes through


def _ops(path) -> list[str]:
    return [n.op_type for n in onnx.load(str(path)).graph.node]


def test_the_exported_graph_carries_the_fold_and_no_dead_layers(tmp_path):
    model, meta = tiny_model(3, in_channels=1, extra_skip=True, full_skip=True)
    fold = _ops(export_onnx(model, meta, tmp_path / "folded.onnx"))
    plain = _ops(export_onnx(model, meta, tmp_path / "plain.onnx", fold=False))
    encoder_convs = sum(isinstance(m, torch.nn.Conv2d) for m in model.encoder.modules())
    assert fold.count("MatMul") == 2 and plain.count("MatMul") == 0
    # as trained: encoder convs + projection + classifier; folded: the encoder convs alone
    assert plain.count("Conv") == encoder_convs + 2 and fold.count("Conv") == encoder_convs
    assert fold.count("BatchNormalization") == plain.count("BatchNormalization") - 1
