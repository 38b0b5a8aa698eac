"""The training losses: masked BCE (the paper's) and an optional per-frame soft Jaccard term.

Both count valid, unpadded pixels only (the ``mask`` of `edge.train.data.make_batch`).
`edge.train.distributed.Dist.loss` combines them for one process or a DDP rank.
"""

from __future__ import annotations

import torch
from torch import nn

__all__ = ["masked_bce", "soft_jaccard"]


def masked_bce(logits: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """BCEWithLogits averaged over valid, unpadded pixels only (paper III.E.b)."""
    loss = nn.functional.binary_cross_entropy_with_logits(logits, target, reduction="none")
    return (loss * mask).sum() / mask.sum().clamp_min(1.0)


def soft_jaccard(logits: torch.Tensor, target: torch.Tensor, mask: torch.Tensor, smooth: float = 1.0) -> torch.Tensor:
    """Per-frame ``1 - soft IoU`` of the object class over the valid pixels, shape [B].

    Why: the score users read is the per-frame IoU (the paper's), where a small object's 2 px
    halo or a few stray pixels on an empty table cost as much as a large object's whole outline;
    masked BCE weighs every pixel alike, so large objects and the table dominate it. ``smooth``
    (in pixels) keeps empty frames defined: there the term is ``s / (s + smooth)`` for ``s``
    object probability summed over the frame, i.e. stray object pixels are punished.

    Args:
        logits: [B, 1, H, W] raw scores.
        target: [B, 1, H, W] 1 = object.
        mask: [B, 1, H, W] 1 = valid, unpadded pixel (the rest never counts).
        smooth: added to intersection and union.
    """
    p = torch.sigmoid(logits) * mask
    t = target * mask
    inter = (p * t).sum(dim=(1, 2, 3))
    union = (p + t).sum(dim=(1, 2, 3)) - inter
    return 1.0 - (inter + smooth) / (union + smooth)
