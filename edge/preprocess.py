"""The one preprocessing implementation: training, evaluation, export and replay all call it.

Why each step (paper III.D and Fig. 6):
- ToF drivers mark pixels that did not return as 0 (REP 118 allows NaN); negative and inf
  values also appear after filtering. All of them are *invalid* and must not bias statistics.
- Standardising with the mean and std of the valid pixels only keeps dead corners from
  dragging the statistics, and makes the input independent of camera height.
- Invalid pixels become 0 (the mean) after standardisation, so they look like "average" depth.
- VGG pools five times, so H and W are zero-padded to multiples of 32 (171 x 224 -> 192 x 224);
  padding goes bottom/right so cropping the output back is a slice.

Numpy only: this module is on the edge path and must not import torch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from edge.errors import DataError

__all__ = [
    "Preprocessed",
    "valid_mask",
    "standardize",
    "padded_shape",
    "pad",
    "preprocess",
    "preprocess_batch",
    "STD_FLOOR",
]

STD_FLOOR = 1e-6  # metres; a frame of one constant valid depth still standardises to zeros


@dataclass(frozen=True)
class Preprocessed:
    """Network input for one frame plus what is needed to map the output back."""

    x: np.ndarray  # float32 [C, Hp, Wp]
    valid: np.ndarray  # bool [H, W]: pixels whose prediction means something
    mean: float
    std: float

    @property
    def shape(self) -> tuple[int, int]:
        return self.valid.shape  # type: ignore[return-value]


def _as_frame(depth: np.ndarray) -> np.ndarray:
    depth = np.asarray(depth)
    if depth.ndim == 3 and depth.shape[0] == 1:
        depth = depth[0]
    if depth.ndim != 2:
        raise DataError(f"a depth frame must be 2-D (H x W), got shape {tuple(depth.shape)}")
    if depth.shape[0] < 1 or depth.shape[1] < 1:
        raise DataError(f"a depth frame must not be empty, got shape {tuple(depth.shape)}")
    if not np.issubdtype(depth.dtype, np.number):
        raise DataError(f"a depth frame must be numeric, got dtype {depth.dtype}")
    return depth


def valid_mask(depth: np.ndarray) -> np.ndarray:
    """True where the sensor returned a usable range: finite and > 0."""
    depth = _as_frame(depth)
    with np.errstate(invalid="ignore"):
        return np.isfinite(depth) & (depth > 0)


def standardize(depth: np.ndarray, valid: np.ndarray | None = None) -> tuple[np.ndarray, float, float]:
    """(standardised float32 frame with invalid = 0, mean, std) over the valid pixels only."""
    depth = _as_frame(depth)
    if valid is None:
        valid = valid_mask(depth)
    out = np.zeros(depth.shape, dtype=np.float32)
    n = int(valid.sum())
    if n == 0:
        return out, 0.0, 1.0
    vals = depth[valid].astype(np.float64)
    mean = float(vals.mean())
    std = max(float(vals.std()), STD_FLOOR)
    out[valid] = ((vals - mean) / std).astype(np.float32)
    return out, mean, std


def padded_shape(height: int, width: int, multiple: int = 32) -> tuple[int, int]:
    """Smallest (H', W') >= (H, W) divisible by ``multiple``."""
    return (-(-height // multiple) * multiple, -(-width // multiple) * multiple)


def pad(x: np.ndarray, multiple: int = 32) -> np.ndarray:
    """Zero-pad the last two axes at the bottom/right to multiples of ``multiple``."""
    h, w = x.shape[-2:]
    hp, wp = padded_shape(h, w, multiple)
    if (hp, wp) == (h, w):
        return x
    widths = [(0, 0)] * (x.ndim - 2) + [(0, hp - h), (0, wp - w)]
    return np.pad(x, widths)


def preprocess(depth: np.ndarray, channels: int = 1, multiple: int = 32) -> Preprocessed:
    """Raw depth (metres, any invalid marker) -> padded, standardised [C, Hp, Wp] float32."""
    if channels not in (1, 3):
        raise DataError(f"channels must be 1 or 3, got {channels}")
    depth = _as_frame(depth)
    valid = valid_mask(depth)
    z, mean, std = standardize(depth, valid)
    x = pad(z, multiple)[None]
    if channels == 3:
        x = np.repeat(x, 3, axis=0)
    return Preprocessed(x=np.ascontiguousarray(x, dtype=np.float32), valid=valid, mean=mean, std=std)


def preprocess_batch(frames: list[np.ndarray], channels: int = 1, multiple: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """Stack frames of one size: (x [N, C, Hp, Wp], valid [N, H, W])."""
    items = [preprocess(f, channels, multiple) for f in frames]
    shapes = {it.shape for it in items}
    if len(shapes) != 1:
        raise DataError(f"frames in a batch must share one size, got {sorted(shapes)}")
    return np.stack([it.x for it in items]), np.stack([it.valid for it in items])
