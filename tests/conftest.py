"""Shared fixtures for every test package.

- ``scene``: the one synthetic scene generator (`replaygen.scene`: a table at 0.3 m, a box,
  dead corners and dead pixels, deterministic per frame index).
- ``linear_onnx``: the one hand-built ONNX (`onnxgen.linear_model`, no torch needed).
- ``tiny_pt`` / ``tiny_onnx``: the one tiny trained-format model (`tinymodel.tiny_model`: a
  random-init FCN-8s vgg11_bn, width 0.125, 3 channels, 48 x 64 sensor, batch-norm statistics
  set so its logits straddle 0) as a checkpoint, and its single-channel ONNX export, built once
  per session (an export costs seconds).

Generators live in importable modules beside this file (``onnxgen``, ``replaygen``,
``tinymodel``), so tests can also call them with other parameters, and ``toolmod.load_tool``
loads a script of ``tools/`` for its tests; a package's own fixture may
be a thin alias of a shared one (another size, a stored threshold) and says why.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from tinymodel import export_checkpoint, one_torch_thread, tiny_checkpoint


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
    pytest.importorskip("torch")
    with one_torch_thread():
        return tiny_checkpoint(tmp_path_factory.mktemp("tiny_model") / "tiny.pt")


@pytest.fixture(scope="session")
def tiny_onnx(tiny_pt, tmp_path_factory) -> Path:
    pytest.importorskip("torch")
    with one_torch_thread():
        return export_checkpoint(tiny_pt, tmp_path_factory.mktemp("tiny_onnx") / "tiny.onnx")
