"""Shared fixtures for every test package.

- ``scene``: the one synthetic scene generator (`replaygen.scene`: a table at 0.3 m, a box,
  dead corners and dead pixels, deterministic per frame index).
- ``linear_onnx``: the one hand-built ONNX (`onnxgen.linear_model`, no torch needed).
- ``tiny_pt`` / ``tiny_onnx``: the one tiny trained-format model: a random-init FCN-8s
  (vgg11_bn, width 0.125, 3 channels, 48 x 64 sensor) as a checkpoint, and its single-channel
  ONNX export, built once per session (an export costs seconds).

Generators live in importable modules beside this file (``onnxgen``, ``replaygen``), so tests
can also call them with other parameters.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from edge.meta import ModelMeta, SensorSpec, fov_intrinsics

TINY_H, TINY_W = 48, 64
TINY_SENSOR = SensorSpec(width=TINY_W, height=TINY_H, **dict(zip(("fx", "fy", "cx", "cy"),
                                                               fov_intrinsics(TINY_W, TINY_H, 62.0, 45.0))))
TINY_META = ModelMeta(encoder="vgg11", width=0.125, batch_norm=True, sensor=TINY_SENSOR)


@pytest.fixture(scope="session")
def scene():
    """``scene(i, h=24, w=32) -> (depth float32 metres with 0 = invalid, label uint8)``."""
    from replaygen import scene as make

    return make


@pytest.fixture(scope="session")
def linear_onnx(tmp_path_factory) -> Path:
    """logits = -40 * standardised depth - 20; single channel, depthseg metadata, threshold 0.5."""
    from onnxgen import linear_model

    return linear_model(tmp_path_factory.mktemp("onnx") / "linear.onnx", k=40.0, bias=-20.0)


def export_checkpoint(pt: Path, out: Path) -> Path:
    """Single-channel ONNX export of a checkpoint, as ``depthseg-export --single-channel`` does."""
    from edge.train.checkpoint import load_checkpoint
    from export.onnx_export import export_onnx
    from export.single_channel import to_single_channel

    model, meta, _ = load_checkpoint(pt)
    return export_onnx(*to_single_channel(model, meta), out)


@pytest.fixture(scope="session")
def tiny_pt(tmp_path_factory) -> Path:
    torch = pytest.importorskip("torch")
    from edge.train.checkpoint import save_checkpoint
    from edge.train.model import build_model

    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(0)
        model = build_model(TINY_META).eval()
    return save_checkpoint(tmp_path_factory.mktemp("tiny_model") / "tiny.pt", model, TINY_META)


@pytest.fixture(scope="session")
def tiny_onnx(tiny_pt, tmp_path_factory) -> Path:
    torch = pytest.importorskip("torch")
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return export_checkpoint(tiny_pt, tmp_path_factory.mktemp("tiny_onnx") / "tiny.onnx")
    finally:
        torch.set_num_threads(n)
