"""Batch norms over few channels on an NCHW copy while the rest of the network trains channels-last.

Why: training keeps weights and inputs channels-last (NHWC, `TrainConfig.memory_format`), which
made the compact models' convolutions 1.4-2.3x faster. PyTorch's CPU batch norm is the exception
at full resolution: with 4 or 8 channels its channels-last kernel took 1.9-5.5x as long as on the
same tensor in NCHW (2026-12-07, AMD EPYC, 2 threads, [16, C, 192, 224], forward and backward),
and the default model's two full-resolution batch norms (the encoder's first, 8 channels; the
decoder's last, 4) were ~36 % of a training step. Normalising an NCHW copy and handing back a
channels-last result costs two copies each way and still made a step x0.84-0.89 as long
(BENCHMARKS.md "where a training step goes"; a recipe with it: "candidate nb8, results").

The arithmetic is the same batch norm, but its sums run in another order, so the weights agree
with a plain channels-last run to float rounding, not bit for bit; that is why it is an option
(``depthseg-train --nchw-bn-channels 8``) and not yet the default recipe. Inference never sees it:
checkpoints hold the plain modules' state.
"""

from __future__ import annotations

import torch
from torch import nn

__all__ = ["NCHWBatchNorm2d", "nchw_batch_norms"]


class NCHWBatchNorm2d(nn.BatchNorm2d):
    """`nn.BatchNorm2d` that, while training, normalises an NCHW copy of a channels-last input.

    Outside training (validation, export) or for any other layout it is the plain batch norm.
    """

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.training and x.dim() == 4 and not x.is_contiguous() and x.is_contiguous(memory_format=torch.channels_last):
            return super().forward(x.contiguous()).contiguous(memory_format=torch.channels_last)
        return super().forward(x)


def nchw_batch_norms(model: nn.Module, max_channels: int) -> int:
    """Make every plain `nn.BatchNorm2d` of ``model`` over at most ``max_channels`` channels an
    `NCHWBatchNorm2d`, in place; returns how many.

    The modules change class only (``__class__``), so their parameters, buffers, state-dict keys and
    the references an optimizer or a weight average already holds stay what they were.

    Args:
        model: the network to train.
        max_channels: the largest channel count treated (0 = none).
    """
    n = 0
    for m in model.modules():
        if type(m) is nn.BatchNorm2d and m.num_features <= max_channels:
            m.__class__ = NCHWBatchNorm2d
            n += 1
    return n
