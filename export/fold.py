"""The network's affine head folded into two matrix products for the edge graph.

Why: after the last deconvolution's ReLU everything is affine per pixel: its BatchNorm, the 1x1
projection of the full-resolution conv1 map (``full_skip``), the add, and the 1x1 classifier
with one output channel. Exported as written, onnxruntime runs each at full resolution, and on
AVX-512 CPUs its blocked (NCHWc) convolutions pad the one logit channel to a block of 16, so
this tail took ~20 % of the shipped model's inference on an Intel Xeon (BENCHMARKS.md). Folded,

    logits = A @ relu(deconv5) + B @ conv1 + c        (A: 1 x C5, B: 1 x C1, per pixel)

is two small ``MatMul`` over the flattened maps: the same function (float64 folding, float32
weights; the export's check against the unfolded PyTorch model proves it on every export).

Only the graph changes: checkpoints, training and `ModelMeta` know nothing of this.
"""

from __future__ import annotations

import copy

import torch
from torch import nn

from edge.errors import ModelError
from edge.train.model import FCN8s

__all__ = ["FoldedFCN8s", "fold_head", "folded"]


def fold_head(model: FCN8s) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor]:
    """(A [1, C5], B [1, C1] or None, c [1, 1]) such that head(r, conv1) == A r + B conv1 + c per pixel.

    Args:
        model: an `FCN8s` whose BatchNorms use running statistics (eval mode is implied: the
            fold is of the inference function).

    Raises:
        ModelError: a classifier with more than one output or not 1 x 1 (nothing else is folded).
    """
    cls = model.classifier
    if cls.out_channels != 1 or cls.kernel_size != (1, 1) or cls.groups != 1:
        raise ModelError(f"the head fold needs a 1x1 classifier with one output, found {cls}")
    bn = model.bns[-1]
    with torch.no_grad():
        wc = cls.weight.double().reshape(1, -1)  # 1 x C5
        bc = cls.bias.double() if cls.bias is not None else torch.zeros(1, dtype=torch.float64)
        scale = bn.weight.double() / torch.sqrt(bn.running_var.double() + bn.eps)
        shift = bn.bias.double() - bn.running_mean.double() * scale
        a = wc * scale[None, :]
        c = wc @ shift + bc
        b = None
        if model.full_skip:
            proj = model.full_proj
            wp = proj.weight.double().reshape(proj.out_channels, -1)  # C5 x C1
            b = wc @ wp
            if proj.bias is not None:
                c = c + wc @ proj.bias.double()
    return a.float(), (None if b is None else b.float()), c.float().reshape(1, 1)


class FoldedFCN8s(nn.Module):
    """An `FCN8s` (a private copy, eval mode) whose head is `fold_head`'s two matrix products."""

    def __init__(self, model: FCN8s) -> None:
        super().__init__()
        self.net = copy.deepcopy(model).eval()
        a, b, c = fold_head(self.net)
        self.register_buffer("head_a", a)
        self.register_buffer("head_c", c)
        self.has_b = b is not None
        self.register_buffer("head_b", b if b is not None else torch.zeros(1, 0))
        # the folded parts are not run; drop them so the exported file carries no dead weights
        self.net.classifier = nn.Identity()
        self.net.bns[-1] = nn.Identity()
        if self.has_b:
            self.net.full_proj = nn.Identity()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        r, conv1 = self.net.decode(x)
        out = self.head_a @ r.flatten(2)  # [N, 1, H*W]
        if self.has_b:
            out = out + self.head_b @ conv1.flatten(2)
        out = out + self.head_c
        return out.unflatten(2, r.shape[2:])


def folded(model: nn.Module) -> nn.Module:
    """``model`` with its head folded when it is an `FCN8s`; any other module as it is."""
    return FoldedFCN8s(model) if isinstance(model, FCN8s) else model
