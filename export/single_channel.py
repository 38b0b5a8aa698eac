"""Single-channel conversion: the paper's three input channels are copies of one depth frame.

Paper V.d: the network was fed the depth frame replicated into three channels (to reuse an
RGB-shaped VGG). A convolution is linear in its input, so for replicated input
``sum_c W[:, c] * x == (sum_c W[:, c]) * x``: summing the first convolution's kernels over the
input axis gives a one-channel network with the same output and a third of the first layer's
multiply-adds, and the edge never builds the three copies.
"""

from __future__ import annotations

import copy

import torch
from torch import nn

from edge.errors import ModelError
from edge.meta import ModelMeta
from edge.train.model import FCN8s, count_parameters

__all__ = ["to_single_channel"]


def to_single_channel(model: FCN8s, meta: ModelMeta) -> tuple[FCN8s, ModelMeta]:
    """(one-channel copy of ``model``, its metadata). The original is left untouched.

    A model that already takes one depth channel is returned as a copy, unchanged. With cue
    channels (``meta.cues``, e.g. height above the dominant plane) only the kernels of the
    replicated depth channels are summed; the cue kernels are kept as they are, so the exported
    model takes ``1 + len(cues)`` channels: depth first, then the cues in order.
    """
    first = model.encoder.features[0]
    if not isinstance(first, nn.Conv2d):
        raise ModelError(f"expected the encoder to start with a Conv2d, found {type(first).__name__}")
    if first.in_channels != meta.net_channels:
        raise ModelError(
            f"model's first conv takes {first.in_channels} channels but its metadata says {meta.net_channels}"
        )
    out = copy.deepcopy(model).eval()
    if meta.in_channels == 1:
        return out, meta
    n_depth = meta.in_channels
    conv = nn.Conv2d(
        1 + len(meta.cues),
        first.out_channels,
        kernel_size=first.kernel_size,
        stride=first.stride,
        padding=first.padding,
        dilation=first.dilation,
        bias=first.bias is not None,
    )
    with torch.no_grad():
        w = first.weight
        conv.weight.copy_(torch.cat([w[:, :n_depth].sum(dim=1, keepdim=True), w[:, n_depth:]], dim=1))
        if first.bias is not None:
            conv.bias.copy_(first.bias)
    out.encoder.features[0] = conv
    return out, meta.with_(in_channels=1, params=count_parameters(out))
