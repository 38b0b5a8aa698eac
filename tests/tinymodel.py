"""The one tiny model of the tests: its builder, the shared ``tiny_pt`` / ``tiny_onnx`` constants
(tests/conftest.py) and how it is exported.

A module of its own (not conftest) so tests can import it by name: several conftest modules exist.
torch is imported inside the functions, so torch-free tests can import the constants.

An untrained FCN-8s gives near-constant logits far from the threshold, which would make mask
comparisons vacuous. `tiny_model` therefore sets the batch-norm statistics from a few synthetic
frames (train-mode forward pass, cumulative average): the logits then straddle 0, so masks
contain both classes and flips at the threshold are possible.
"""

from __future__ import annotations

import contextlib
from pathlib import Path

from edge.meta import ModelMeta, SensorSpec, fov_intrinsics

TINY_H, TINY_W = 48, 64
TINY_SENSOR = SensorSpec(width=TINY_W, height=TINY_H, **dict(zip(("fx", "fy", "cx", "cy"),
                                                               fov_intrinsics(TINY_W, TINY_H, 62.0, 45.0))))


@contextlib.contextmanager
def one_torch_thread():
    """torch single-threaded for the block (restored after): on a loaded 2-core machine its
    OpenMP workers spin and cost ~10x the CPU time for these tiny models."""
    import torch

    n = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(n)


def tiny_model(seed: int = 0, in_channels: int = 3, width: float = 0.125, **meta_kw):
    """(FCN8s in eval mode, its ModelMeta): a tiny vgg11_bn with batch-norm statistics from frames
    through its own preprocessing; ``meta_kw`` sets further `ModelMeta` fields (sensor,
    standardize, cues, ...)."""
    import torch
    from torch import nn

    from edge.preprocess import preprocess_batch_for
    from edge.sampleframes import synthetic_frames
    from edge.train.model import build_model, count_parameters

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
    x, _ = preprocess_batch_for(synthetic_frames(4, seed + 100, sensor=meta.sensor).depth, meta)
    model.train()
    with torch.no_grad():
        model(torch.from_numpy(x))
    model.eval()
    return model, meta.with_(params=count_parameters(model))


def tiny_checkpoint(out: Path) -> Path:
    """The shared tiny model (`tiny_model` seed 0, 3 channels, 48 x 64 sensor) saved as a checkpoint."""
    from edge.train.checkpoint import save_checkpoint

    model, meta = tiny_model(0, sensor=TINY_SENSOR)
    return save_checkpoint(out, model, meta)


def export_checkpoint(pt: Path, out: Path) -> Path:
    """Single-channel ONNX export of a checkpoint, as ``depthseg-export --single-channel`` does."""
    from edge.train.checkpoint import load_checkpoint
    from export.onnx_export import export_onnx
    from export.single_channel import to_single_channel

    model, meta, _ = load_checkpoint(pt)
    return export_onnx(*to_single_channel(model, meta), out)
