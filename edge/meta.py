"""Metadata that travels with a model: sensor, preprocessing, architecture, threshold.

One frozen dataclass, `ModelMeta`, is stored in every checkpoint (``meta`` key) and in the
ONNX ``metadata_props`` (key ``depthseg``, JSON), so export, bench, tune, eval and replay all
read the same facts from the model file instead of trusting command-line flags. When a flag
contradicts the metadata the tools raise instead of silently overriding it.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any

from edge.cues import CUES
from edge.errors import ModelError
from edge.preprocess import STANDARDIZE_MODES

__all__ = ["SensorSpec", "ModelMeta", "META_KEY", "fov_intrinsics"]

META_KEY = "depthseg"
SCHEMA_VERSION = 1


def fov_intrinsics(width: int, height: int, hfov_deg: float, vfov_deg: float) -> tuple[float, float, float, float]:
    """Pinhole (fx, fy, cx, cy) from lens angles, as BlenSor builds its ToF camera.

    Pixel centres sit at integer coordinates, so the optical axis passes through
    ((W - 1) / 2, (H - 1) / 2).
    """
    fx = (width / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)
    fy = (height / 2.0) / math.tan(math.radians(vfov_deg) / 2.0)
    return fx, fy, (width - 1) / 2.0, (height - 1) / 2.0


_FX, _FY, _CX, _CY = fov_intrinsics(224, 171, 62.0, 45.0)


@dataclass(frozen=True)
class SensorSpec:
    """The camera a model was trained for: PMD pico flexx by default (datasheet FOV pinhole).

    ``depth`` says what a pixel holds: ``"z"`` is the distance along the optical axis in metres,
    as ROS drivers publish it; invalid pixels are 0 (or NaN, negative, inf).
    """

    name: str = "pmd-pico-flexx"
    width: int = 224
    height: int = 171
    fx: float = _FX
    fy: float = _FY
    cx: float = _CX
    cy: float = _CY
    distortion: tuple[float, ...] = ()

    def intrinsics_for_size(self, height: int, width: int) -> tuple[float, float, float, float]:
        """(fx, fy, cx, cy) of this camera for a frame resized to ``height`` x ``width``.

        The one rescaling rule (baseline, realism): the field of view is kept and pixel centres
        map to pixel centres, i.e. c' = (c + 0.5) * scale - 0.5; the native size returns the
        sensor's own values.
        """
        if (int(height), int(width)) == (self.height, self.width):
            return self.fx, self.fy, self.cx, self.cy
        sx, sy = width / self.width, height / self.height
        return self.fx * sx, self.fy * sy, (self.cx + 0.5) * sx - 0.5, (self.cy + 0.5) * sy - 0.5
    depth: str = "z"
    min_range_m: float = 0.1
    max_range_m: float = 4.0


@dataclass(frozen=True)
class ModelMeta:
    """Everything needed to run a model on a raw depth frame, and how it came to be."""

    encoder: str = "vgg16"
    width: float = 1.0
    in_channels: int = 3
    batch_norm: bool = False
    extra_skip: bool = False
    pad_multiple: int = 32
    standardize: str = "valid-pixels"
    cues: tuple[str, ...] = ()  # extra input channels after the depth copies (edge.cues.CUES)
    threshold: float = 0.5
    threshold_policy: str = "default 0.5 (paper)"
    sensor: SensorSpec = field(default_factory=SensorSpec)
    params: int = 0
    training: dict[str, Any] = field(default_factory=dict)
    version: int = SCHEMA_VERSION

    def __post_init__(self) -> None:
        if self.in_channels not in (1, 3):
            raise ModelError(f"in_channels must be 1 or 3, got {self.in_channels}")
        if not 0.0 < float(self.threshold) < 1.0:
            raise ModelError(f"threshold must lie in (0, 1), got {self.threshold}")
        if self.pad_multiple < 1:
            raise ModelError(f"pad_multiple must be >= 1, got {self.pad_multiple}")
        if self.standardize not in STANDARDIZE_MODES:
            raise ModelError(f"standardize must be one of {list(STANDARDIZE_MODES)}, got {self.standardize!r}")
        object.__setattr__(self, "cues", tuple(self.cues))
        bad = [c for c in self.cues if c not in CUES]
        if bad or len(set(self.cues)) != len(self.cues):
            raise ModelError(f"cues must be distinct names from {list(CUES)}, got {list(self.cues)}")

    @property
    def net_channels(self) -> int:
        """Channels the network's first layer takes: the depth copies plus one per cue."""
        return self.in_channels + len(self.cues)

    def with_(self, **changes: Any) -> ModelMeta:
        """A copy with some fields changed (the dataclass is frozen)."""
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["sensor"]["distortion"] = list(self.sensor.distortion)
        d["cues"] = list(self.cues)
        return d

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ModelMeta:
        if not isinstance(d, dict):
            raise ModelError(f"model metadata must be a JSON object, got {type(d).__name__}")
        d = dict(d)
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ModelError(f"unknown model metadata keys {unknown}; this depthseg knows {sorted(known)}")
        sensor = d.pop("sensor", {}) or {}
        sknown = {f.name for f in fields(SensorSpec)}
        sunknown = sorted(set(sensor) - sknown)
        if sunknown:
            raise ModelError(f"unknown sensor metadata keys {sunknown}; valid: {sorted(sknown)}")
        sensor = dict(sensor)
        if "distortion" in sensor:
            sensor["distortion"] = tuple(float(v) for v in sensor["distortion"])
        try:
            return cls(sensor=SensorSpec(**sensor), **d)
        except TypeError as exc:
            raise ModelError(f"bad model metadata: {exc}") from None

    @classmethod
    def from_json(cls, text: str) -> ModelMeta:
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ModelError(f"model metadata is not valid JSON ({exc})") from None
        return cls.from_dict(d)

    def onnx_props(self) -> dict[str, str]:
        """Key/value pairs for ONNX ``metadata_props``: the full JSON plus flat, greppable keys."""
        s = self.sensor
        return {
            META_KEY: self.to_json(),
            "threshold": repr(float(self.threshold)),
            "threshold_policy": self.threshold_policy,
            "encoder": self.encoder,
            "width": repr(float(self.width)),
            "in_channels": str(self.in_channels),
            "cues": ",".join(self.cues),
            "params": str(self.params),
            "input_size": f"{s.height}x{s.width}",
            "intrinsics": f"fx={s.fx:.4f} fy={s.fy:.4f} cx={s.cx:.4f} cy={s.cy:.4f}",
            "preprocessing": f"invalid(<=0,nan,inf)->mask; standardize={self.standardize}; "
            f"invalid->0; cues={list(self.cues)}; zero-pad to multiple of {self.pad_multiple}",
            "training": json.dumps(self.training, sort_keys=True),
        }

    @classmethod
    def from_onnx_props(cls, props: dict[str, str]) -> ModelMeta:
        if META_KEY not in props:
            raise ModelError(
                f"ONNX model has no '{META_KEY}' metadata; export it with depthseg-export"
            )
        return cls.from_json(props[META_KEY])
