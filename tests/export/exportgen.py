"""Frames for the export tests (importable by name, like replay's replaygen); `tiny_model` is the
shared builder of tests/tinymodel.py, re-exported here for the export tests' imports.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from tinymodel import tiny_model

from edge.sampleframes import synthetic_frames

__all__ = ["tiny_model", "dead_pixel_frames", "blensor_frames"]

SHARED = Path(__file__).resolve().parents[2].parent / "shared" / "data"


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
