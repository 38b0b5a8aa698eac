"""The training losses: masked BCE (the paper's), an optional per-frame soft Jaccard term and
optional boundary weights.

Both count valid, unpadded pixels only (the ``mask`` of `edge.train.data.make_batch`).
`edge.train.distributed.Dist.loss` combines them for one process or a DDP rank.
"""

from __future__ import annotations

import torch
from torch import nn

__all__ = ["masked_bce", "soft_jaccard", "boundary_band", "boundary_band_by_pooling", "BOUNDARY_PX"]

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

    How: the band is where the square window around a pixel (cut at the frame's border) holds both
    object and table. For 0/1 targets (every label here) that is counted with box sums of two
    cumulative sums, which are exact in float32 (whole numbers far below 2**24) and give the same
    band as the dilation minus the erosion by max pooling, bit for bit (tested), 3-4x faster: the
    two max pools over a full-resolution batch were ~7 % of a training step on the 2-core AMD EPYC
    (BENCHMARKS.md "the boundary band by box sums"). Other targets take the max pools.

    Args:
        target: [B, 1, H, W] 1 = object.
        px: half-width of the band in pixels (>= 1).
    """
    px = int(px)
    if bool(((target != 0) & (target != 1)).any()):
        return boundary_band_by_pooling(target, px)
    box, count = _box_sums(target, px)
    return (box > 0).to(target.dtype) - (box >= count).to(target.dtype)


def boundary_band_by_pooling(target: torch.Tensor, px: int = BOUNDARY_PX) -> torch.Tensor:
    """Dilation minus erosion of ``target`` by a (2 px + 1) square, by max pooling: `boundary_band`'s rule
    for targets other than 0/1, and its way for every target before 2026-12-07 (kept to compare).

    Args:
        target: [B, 1, H, W], any values.
        px: half-width of the band in pixels (>= 1).
    """
    k = 2 * px + 1
    dilated = nn.functional.max_pool2d(target, k, stride=1, padding=px)
    eroded = 1.0 - nn.functional.max_pool2d(1.0 - target, k, stride=1, padding=px)
    return dilated - eroded


def _box_sums(target: torch.Tensor, px: int) -> tuple[torch.Tensor, torch.Tensor]:
    """(sum of ``target`` over each pixel's (2 px + 1) square cut at the border, the square's pixel count)."""
    h, w = target.shape[-2:]
    rows, cols = torch.arange(h, device=target.device), torch.arange(w, device=target.device)
    top, bottom = (rows - px).clamp(0, h), (rows + px + 1).clamp(0, h)
    left, right = (cols - px).clamp(0, w), (cols + px + 1).clamp(0, w)
    s = nn.functional.pad(target.cumsum(-2), (0, 0, 1, 0))  # s[i] = sum of rows < i
    s = s[..., bottom, :] - s[..., top, :]
    s = nn.functional.pad(s.cumsum(-1), (1, 0))
    box = s[..., right] - s[..., left]
    count = ((bottom - top)[:, None] * (right - left)[None, :]).to(target.dtype)
    return box, count
