"""The training losses: masked BCE (the paper's), an optional per-frame soft Jaccard term and
optional boundary weights.

Both count valid, unpadded pixels only (the ``mask`` of `edge.train.data.make_batch`).
`edge.train.distributed.Dist.loss` combines them for one process or a DDP rank.
"""

from __future__ import annotations

import torch
from torch import nn

__all__ = ["masked_bce", "soft_jaccard", "boundary_band", "BOUNDARY_PX"]

# `boundary_band`'s half-width: 2 px on either side of an outline, where the model's errors sit (eval's
# `edge.metrics.boundary_band` counts from the boundary pixels, so its default 2 reaches one pixel farther)
BOUNDARY_PX = 2


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


def boundary_band(target: torch.Tensor, px: int = BOUNDARY_PX) -> torch.Tensor:
    """1 on pixels within ``px`` pixels (8-connected, a (2 px + 1) square) of a label boundary, on either side; else 0.

    Why: the shipped model's errors on held-out frames sit on object outlines (missed object pixels
    within 2 px of a boundary are its largest share of the union, README "Results"), where masked
    BCE spends little of its weight: most pixels are the far table and object interiors. A band
    of the label's dilation minus its erosion picks those pixels out, both sides alike, so weighting
    them does not move the decision boundary the way a class weight would (the threshold is already
    the best one, `depthseg-tune`).

    Args:
        target: [B, 1, H, W] 1 = object.
        px: half-width of the band in pixels (>= 1).
    """
    k = 2 * int(px) + 1
    dilated = nn.functional.max_pool2d(target, k, stride=1, padding=px)
    eroded = 1.0 - nn.functional.max_pool2d(1.0 - target, k, stride=1, padding=px)
    return dilated - eroded
