"""Fixtures for the replay tests; the generators live in replaygen.py (importable by name)."""

from __future__ import annotations

import pytest
from replaygen import FakeSegmenter


@pytest.fixture
def fake() -> FakeSegmenter:
    return FakeSegmenter()
