"""Fixtures for the replay tests; the generators live in replaygen.py (importable by name)."""

from __future__ import annotations

from pathlib import Path

import pytest
from replaygen import FakeSegmenter, make_linear_onnx


@pytest.fixture
def fake() -> FakeSegmenter:
    return FakeSegmenter()


@pytest.fixture(scope="session")
def linear_onnx(tmp_path_factory) -> Path:
    return make_linear_onnx(tmp_path_factory.mktemp("onnx") / "linear.onnx")
