"""The one preprocessing implementation: training, evaluation, export and replay all call it.

Why each step (paper III.D and Fig. 6):
- ToF drivers mark pixels that did not return as 0 (REP 118 allows NaN); negative and inf
  values also appear after filtering. All of them are *invalid* and must not bias statistics;
  so are pixels beyond the model's sensor range (`preprocess_for`: a 16UC1 65535 is no return).
- Standardising with the mean and std of the valid pixels only keeps dead corners from
  dragging the statistics, and makes the input independent of camera height.
- Invalid pixels become 0 (the mean) after standardisation, so they look like "average" depth.
- ``standardize="robust"`` (models since issue 9): the mean and std come from the valid pixels
  between their 1st and 99th percentile and the result is clipped to +-``ROBUST_CLIP``, so a few
  far or saturated pixels cannot swing the whole frame (`edge.cues.robust_mean_std`).
- ``cues``: extra channels after the depth channels; ``"height"`` is centimetres above the
  dominant plane (`edge.cues.height_cue`); ``"steepness"`` is 1 - the cosine of the surface's
  angle to the optical axis (`edge.cues.steepness_cue`, needs the camera's intrinsics).
- VGG pools five times, so H and W are zero-padded to multiples of 32 (171 x 224 -> 192 x 224);
  padding goes bottom/right so cropping the output back is a slice.

Numpy only: this module is on the edge path and must not import torch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from edge.cues import CUES, height_cue, robust_mean_std, steepness_cue, zero_where_invalid
from edge.errors import DataError

if TYPE_CHECKING:
    from edge.meta import SensorSpec

__all__ = [
    "Preprocessed",
    "valid_mask",
    "valid_for",
    "standardize",
    "padded_shape",
    "preprocess",
    "input_options",
    "preprocess_batch",
    "preprocess_for",
    "preprocess_batch_for",
    "STD_FLOOR",
    "STANDARDIZE_MODES",
    "ROBUST_CLIP",
]

STD_FLOOR = 1e-6  # metres; a frame of one constant valid depth still standardises to zeros
STANDARDIZE_MODES = ("valid-pixels", "robust")
ROBUST_CLIP = 8.0  # standardised units; the far floor past a table edge stays within it


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


def valid_mask(depth: np.ndarray, max_range_m: float = math.inf) -> np.ndarray:
    """True where the sensor returned a usable range: finite, > 0 and not beyond ``max_range_m``.

    Why the range: a 16UC1 driver marks saturated pixels 65535 mm; read as 65.5 m they are valid
    numbers no ToF camera returns, and 40 of them moved the model's mask by 1 % (issue 9). The
    model's input treats anything beyond its sensor's range (``ModelMeta.sensor.max_range_m``)
    as no return; scoring keeps the plain rule (its labels decide what counts).
    """
    depth = _as_frame(depth)
    with np.errstate(invalid="ignore"):
        ok = depth > 0  # False for NaN and -inf
        if math.isfinite(max_range_m):
            ok &= depth <= np.float32(max_range_m)  # False for NaN and +inf: no isfinite pass needed
            return ok
        return ok & np.isfinite(depth)


def valid_for(depth: np.ndarray, meta) -> np.ndarray:
    """The pixels a model reads as returns: `valid_mask` within its sensor's range (`ModelMeta`)."""
    return valid_mask(depth, meta.sensor.max_range_m)


def standardize(
    depth: np.ndarray, valid: np.ndarray | None = None, mode: str = "valid-pixels"
) -> tuple[np.ndarray, float, float]:
    """(standardised float32 frame with invalid = 0, mean, std) over the valid pixels only.

    Args:
        depth: [H, W] depth in metres.
        valid: precomputed `valid_mask` (computed when None).
        mode: ``"valid-pixels"`` (mean/std of all valid pixels, the paper's) or ``"robust"``
            (trimmed statistics, output clipped to +-ROBUST_CLIP).
    """
    depth = _as_frame(depth)
    if mode not in STANDARDIZE_MODES:
        raise DataError(f"unknown standardisation '{mode}'; choose from {list(STANDARDIZE_MODES)}")
    if valid is None:
        valid = valid_mask(depth)
    if mode == "robust":
        # whole-array arithmetic (same float64 values as a gather) is 2x faster than masking:
        # this runs on every frame at the edge
        mean, std = robust_mean_std(depth, valid, STD_FLOOR)
        t = depth.astype(np.float64)
        with np.errstate(invalid="ignore", over="ignore"):
            t -= mean
            t /= std
        np.clip(t, -ROBUST_CLIP, ROBUST_CLIP, out=t)
        return zero_where_invalid(t.astype(np.float32), valid), mean, std
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


def preprocess(
    depth: np.ndarray,
    channels: int = 1,
    multiple: int = 32,
    *,
    standardize_mode: str = "valid-pixels",
    cues: tuple[str, ...] = (),
    max_range_m: float = math.inf,
    sensor: SensorSpec | None = None,
) -> Preprocessed:
    """Raw depth (metres, any invalid marker) -> padded network input [C, Hp, Wp] float32.

    Args:
        depth: [H, W] (or [1, H, W]) Z in metres; 0, negative, NaN and inf are invalid.
        channels: copies of the standardised depth (1, or 3 as the paper feeds a VGG).
        multiple: pad H and W up to multiples of this.
        standardize_mode: see `standardize`.
        cues: extra channels after the depth copies, from `edge.cues.CUES`.
        max_range_m: pixels farther than this are invalid (see `valid_mask`).
        sensor: the camera (`edge.meta.SensorSpec`), needed by the ``steepness`` cue only.

    Returns:
        `Preprocessed` with ``x`` of ``channels + len(cues)`` channels.
    """
    if channels not in (1, 3):
        raise DataError(f"channels must be 1 or 3, got {channels}")
    bad = [c for c in cues if c not in CUES]
    if bad:
        raise DataError(f"unknown input cue(s) {bad}; known: {list(CUES)}")
    depth = _as_frame(depth)
    valid = valid_mask(depth, max_range_m)
    h, w = depth.shape
    x = np.zeros((channels + len(cues), *padded_shape(h, w, multiple)), dtype=np.float32)  # padding stays 0
    z, mean, std = standardize(depth, valid, standardize_mode)
    x[:channels, :h, :w] = z
    for i, cue in enumerate(cues):
        if cue == "height":
            x[channels + i, :h, :w] = height_cue(depth, valid)
        elif cue == "steepness":
            if sensor is None:
                raise DataError("the 'steepness' cue needs the camera's intrinsics; pass sensor= (the model's ModelMeta.sensor)")
            x[channels + i, :h, :w] = steepness_cue(depth, valid, sensor.intrinsics_for_size(h, w))
    return Preprocessed(x=x, valid=valid, mean=mean, std=std)


def input_options(meta) -> dict:
    """Everything a model's `edge.meta.ModelMeta` says about its input, as `preprocess` arguments.

    Args:
        meta: the model's metadata (`edge.meta.ModelMeta`).
    """
    return {"channels": meta.in_channels, "multiple": meta.pad_multiple, "standardize_mode": meta.standardize,
            "cues": tuple(meta.cues), "max_range_m": meta.sensor.max_range_m, "sensor": meta.sensor}


def preprocess_for(depth: np.ndarray, meta) -> Preprocessed:
    """`preprocess` with everything a model's `edge.meta.ModelMeta` says about its input."""
    return preprocess(depth, **input_options(meta))


def preprocess_batch_for(frames: list[np.ndarray], meta) -> tuple[np.ndarray, np.ndarray]:
    """`preprocess_batch` with everything a model's `edge.meta.ModelMeta` says about its input."""
    return preprocess_batch(frames, **input_options(meta))


def preprocess_batch(
    frames: list[np.ndarray],
    channels: int = 1,
    multiple: int = 32,
    *,
    standardize_mode: str = "valid-pixels",
    cues: tuple[str, ...] = (),
    max_range_m: float = math.inf,
    sensor: SensorSpec | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Stack frames of one size: (x [N, C, Hp, Wp], valid [N, H, W])."""
    items = [preprocess(f, channels, multiple, standardize_mode=standardize_mode, cues=cues, max_range_m=max_range_m,
                        sensor=sensor) for f in frames]
    shapes = {it.shape for it in items}
    if len(shapes) != 1:
        raise DataError(f"frames in a batch must share one size, got {sorted(shapes)}")
    return np.stack([it.x for it in items]), np.stack([it.valid for it in items])
