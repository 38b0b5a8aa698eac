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
from tinymodel import TINY_META, export_checkpoint


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
