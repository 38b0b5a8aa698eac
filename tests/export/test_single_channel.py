"""Single-channel conversion: same logits for replicated input (paper V.d), fewer weights."""

from __future__ import annotations

import pytest
import torch
from exportgen import tiny_model

from edge.errors import ModelError
from edge.preprocess import preprocess
from edge.sampleframes import synthetic_frames
from export.single_channel import to_single_channel

ATOL = 1e-4  # logits of magnitude ~10: float32 rounding of the first conv's 3-term sum, carried through 14 layers


@pytest.mark.parametrize("seed", [0, 1])
def test_replicated_input_gives_the_same_logits(seed):
    model, meta = tiny_model(seed, in_channels=3)
    one, meta1 = to_single_channel(model, meta)
    x1 = torch.from_numpy(preprocess(synthetic_frames(1, seed).depth[0], channels=1).x[None])
    x3 = x1.expand(-1, 3, -1, -1).contiguous()
    with torch.no_grad():
        ref, got = model(x3), one(x1)
    assert got.shape == ref.shape == (1, 1, 192, 224)
    assert ref.abs().max() > 1.0  # non-trivial output
    torch.testing.assert_close(got, ref, atol=ATOL, rtol=1e-5)
    assert meta1.in_channels == 1 and meta.in_channels == 3
    first = model.encoder.features[0]
    assert meta1.params == meta.params - first.out_channels * 2 * 9  # two input channels' 3x3 kernels gone


def test_original_model_is_untouched_and_one_channel_is_a_noop():
    model, meta = tiny_model(0, in_channels=3)
    w = model.encoder.features[0].weight.clone()
    one, meta1 = to_single_channel(model, meta)
    assert torch.equal(model.encoder.features[0].weight, w)
    again, meta2 = to_single_channel(one, meta1)
    assert again is not one and meta2 == meta1
    assert torch.equal(again.encoder.features[0].weight, one.encoder.features[0].weight)


def test_metadata_that_contradicts_the_weights_is_refused():
    model, meta = tiny_model(0, in_channels=3)
    with pytest.raises(ModelError, match="3 channels but its metadata says 1"):
        to_single_channel(model, meta.with_(in_channels=1))


def test_a_full_skip_model_converts_with_the_same_logits():
    model, meta = tiny_model(2, in_channels=3, extra_skip=True, full_skip=True)
    one, meta1 = to_single_channel(model, meta)
    x1 = torch.from_numpy(preprocess(synthetic_frames(1, 2).depth[0], channels=1).x[None])
    with torch.no_grad():
        ref, got = model(x1.expand(-1, 3, -1, -1).contiguous()), one(x1)
    torch.testing.assert_close(got, ref, atol=ATOL, rtol=1e-5)
    assert meta1.full_skip and one.full_skip
