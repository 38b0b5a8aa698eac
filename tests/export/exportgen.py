"""Tiny models and frames for the export tests (importable by name, like replay's replaygen).

An untrained FCN-8s gives near-constant logits far from the threshold, which would make mask
comparisons vacuous. `tiny_model` therefore sets the batch-norm statistics from a few
synthetic frames (train-mode forward pass, cumulative average): the logits then straddle 0,
so masks contain both classes and flips at the threshold are possible.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch import nn

from edge.meta import ModelMeta
from edge.preprocess import preprocess_batch_for
from edge.sampleframes import synthetic_frames
from edge.train.model import FCN8s, build_model, count_parameters

SHARED = Path(__file__).resolve().parents[2].parent / "shared" / "data"


def tiny_model(seed: int = 0, in_channels: int = 3, width: float = 0.125, **meta_kw) -> tuple[FCN8s, ModelMeta]:
    """A tiny vgg11_bn with batch-norm statistics from frames through its own preprocessing;
    ``meta_kw`` sets further `ModelMeta` fields (e.g. standardize, cues)."""
    meta = ModelMeta(encoder="vgg11", width=width, batch_norm=True, in_channels=in_channels,
                     training={"weights": "random-init + batch-norm statistics", "seed": seed, "purpose": "tests"},
                     **meta_kw)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        model = build_model(meta)
    for m in model.modules():
        if isinstance(m, nn.BatchNorm2d):
            m.reset_running_stats()
            m.momentum = None
    x, _ = preprocess_batch_for(synthetic_frames(4, seed + 100).depth, meta)
    model.train()
    with torch.no_grad():
        model(torch.from_numpy(x))
    model.eval()
    return model, meta.with_(params=count_parameters(model))


def dead_pixel_frames(seed: int = 0) -> list[np.ndarray]:
    """Synthetic frames plus every kind of invalid pixel: 0, NaN, negative, +-inf, all invalid."""
    frames = synthetic_frames(3, seed).depth
    f = frames[0].copy()
    f[10:20, 30:60] = np.nan
    f[50:55, 100:140] = -0.2
    f[100, 5:25] = np.inf
    f[120, 5:25] = -np.inf
    f[:, :3] = 0.0
    frames.append(f)
    frames.append(np.zeros_like(f))  # nothing valid
    frames.append(np.full_like(f, np.nan))
    c = np.full_like(f, 0.3)  # one constant depth: std floored
    c[0, 0] = 0.0
    frames.append(c)
    return frames


def blensor_frames(n: int = 3) -> list[np.ndarray]:
    """The seed paper's simulated frames (radial range, 171 x 224) when ../shared is present."""
    out = []
    for i in range(n):
        p = SHARED / "blensor" / f"scan_{i}.npy"
        if p.exists():
            out.append(np.load(p)[0].reshape(224, 171).T.astype(np.float32).copy())
    return out
