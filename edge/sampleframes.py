"""Frames for export checks, int8 calibration and benchmarks.

Why a module of its own: export, quantisation and the benchmark all need a handful of realistic
frames. Simulated frames from ``depthseg-sim`` MCAP are the real thing; when none are at hand a
seeded synthetic frame (tilted table, boxes and domes, range-dependent noise, dead corners,
dead and NaN pixels) still exercises every branch of the preprocessing and a realistic share of
invalid pixels. Callers always get back a description of which source they got, so reports can
say it.

Numpy + mcap only (edge path).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import islice
from pathlib import Path

import numpy as np

from edge.errors import ConfigError, DataError
from edge.io import iter_frames
from edge.meta import SensorSpec

__all__ = ["FrameSample", "synthetic_frame", "synthetic_frames", "load_frames", "sample_frames"]


@dataclass(frozen=True)
class FrameSample:
    """Depth frames (float32 H x W, metres, invalid 0/NaN) with labels where known."""

    depth: list[np.ndarray]
    label: list[np.ndarray | None]
    source: str  # human-readable: where the frames came from

    def __len__(self) -> int:
        return len(self.depth)

    @property
    def labelled(self) -> bool:
        return bool(self.depth) and all(lab is not None for lab in self.label)


def synthetic_frame(rng: np.random.Generator, sensor: SensorSpec | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(depth float32 H x W, label uint8 H x W) of a table seen from 20-40 cm with a few objects.

    Not a sensor model (that is ``sim``): just enough structure and invalid pixels that a
    benchmark or a numerical check sees what a real frame looks like to the preprocessing.
    """
    s = sensor or SensorSpec()
    h, w = s.height, s.width
    xn = ((np.arange(w) - s.cx) / s.fx)[None, :]
    yn = ((np.arange(h) - s.cy) / s.fy)[:, None]
    height = rng.uniform(0.20, 0.40)
    a, b = rng.uniform(-0.12, 0.12, size=2)  # table tilt (plane normal (a, b, 1))
    table = height / (a * xn + b * yn + 1.0)
    depth = np.broadcast_to(table, (h, w)).copy()
    label = np.zeros((h, w), np.uint8)
    uu, vv = np.meshgrid(np.arange(w), np.arange(h))
    for _ in range(int(rng.integers(1, 6))):
        uc, vc = rng.uniform(0.15, 0.85) * w, rng.uniform(0.15, 0.85) * h
        ru, rv = rng.uniform(6, 32, size=2)
        top = table[int(vc), int(uc)] - rng.uniform(0.015, 0.10)
        if rng.random() < 0.5:  # box: flat top
            inside = (np.abs(uu - uc) <= ru) & (np.abs(vv - vc) <= rv)
            z = np.full((h, w), top)
        else:  # dome: ball or lying cylinder end
            r2 = ((uu - uc) / ru) ** 2 + ((vv - vc) / rv) ** 2
            inside = r2 <= 1.0
            z = top + (1.0 - np.sqrt(np.clip(1.0 - r2, 0.0, 1.0))) * 0.5 * (table - top)
        closer = inside & (z < depth)
        depth[closer] = z[closer]
        label[closer] = 1
    depth += rng.normal(0.0, 1.0, size=(h, w)) * (0.0008 + 0.004 * depth)
    # Dead corners (lens falloff, ~3 % of a real frame), scattered dead pixels, a few NaN.
    r = np.sqrt(((uu - s.cx) / (w / 2)) ** 2 + ((vv - s.cy) / (h / 2)) ** 2)
    depth[r > 1.26] = 0.0
    depth[rng.random((h, w)) < 0.004] = 0.0
    depth[rng.random((h, w)) < 0.001] = np.nan
    return depth.astype(np.float32), label


def synthetic_frames(n: int, seed: int = 0, sensor: SensorSpec | None = None) -> FrameSample:
    if n < 1:
        raise ConfigError(f"need at least one frame, got {n}")
    rng = np.random.default_rng(seed)
    pairs = [synthetic_frame(rng, sensor) for _ in range(n)]
    return FrameSample(
        depth=[p[0] for p in pairs],
        label=[p[1] for p in pairs],
        source=f"{n} synthetic frames (seed {seed}; pass `data` DIR for simulated frames)",
    )


def load_frames(path: str | Path, n: int, skip: int = 0) -> FrameSample:
    """Frames ``skip`` .. ``skip + n`` of an MCAP file or directory, streamed (never all loaded)."""
    if n < 1:
        raise ConfigError(f"need at least one frame, got {n}")
    frames = list(islice(iter_frames(path), skip, skip + n))
    if not frames:
        raise DataError(f"{path}: no depth frames after skipping {skip}; generate more with depthseg-sim")
    return FrameSample(
        depth=[f.depth for f in frames],
        label=[f.label for f in frames],
        source=f"{len(frames)} frames of {path}" + (f" (after the first {skip})" if skip else ""),
    )


def sample_frames(data: str | Path | None, n: int, seed: int = 0, skip: int = 0) -> FrameSample:
    """Simulated frames from ``data`` when given, else seeded synthetic ones (``skip`` shifts the seed)."""
    if data is not None:
        return load_frames(data, n, skip)
    return synthetic_frames(n, seed + skip)
