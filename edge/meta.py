"""Metadata that travels with a model: sensor, preprocessing, architecture, threshold.

One frozen dataclass, `ModelMeta`, is stored in every checkpoint (``meta`` key) and in the
ONNX ``metadata_props`` (key ``depthseg``, JSON), so export, bench, tune, eval and replay all
read the same facts from the model file instead of trusting command-line flags. When a flag
contradicts the metadata the tools raise instead of silently overriding it.
"""

from __future__ import annotations

import json
import math
import numbers
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any

from edge.cues import CUES, MAX_MIN_HEIGHT_M
from edge.errors import ModelError
from edge.preprocess import STANDARDIZE_MODES
from edge.values import is_finite, show

__all__ = ["SensorSpec", "ModelMeta", "META_KEY", "fov_intrinsics", "MAX_SENSOR_SIDE", "MAX_PAD_MULTIPLE", "MIN_OBJECT_PX"]

META_KEY = "depthseg"
SCHEMA_VERSION = 1

# Bounds on what a model file may ask for. A model's metadata is input like any other: a hostile
# or damaged file must fail with one line, not make the preprocessing allocate gigabytes
# (``pad_multiple`` 65536 pads every frame to 65536 x 65536 float32 = 16 GiB).
MAX_SENSOR_SIDE = 8192  # pixels per side of the sensor frame (depth cameras: <= ~2000)
MAX_SENSOR_PIXELS = 4096 * 4096
MAX_PAD_MULTIPLE = 512  # FCN-8s needs 32; a pad beyond this is not a model's need but an attack
MAX_WIDTH = 1.0  # channel width multiplier: the paper's VGG (1) is the widest; wider would allocate GBs
MAX_PARAMS = 10**11
MAX_TEXT = 4096  # characters of a free-text field (names, policy)
MAX_NESTING = 32  # depth of the free-form ``training`` record
MAX_DISTORTION = 16  # OpenCV models have at most 14 coefficients
MIN_OBJECT_PX = 6  # the speck rule's default (edge.postprocess: why 6)


def _bad(key: str, value: Any, want: str) -> ModelError:
    return ModelError(f"model metadata '{key}' = {show(value)}: {want}")


def _int(key: str, value: Any, lo: int, hi: int) -> int:
    """``value`` as an int in [lo, hi] (bools and floats refused: 1.5 is no pad, True no count)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise _bad(key, value, f"must be an integer in [{lo}, {hi}]")
    v = int(value)
    if not lo <= v <= hi:
        raise _bad(key, value, f"must be an integer in [{lo}, {hi}]")
    return v


def _float(key: str, value: Any, lo: float, hi: float, open_lo: bool = False, open_hi: bool = False) -> float:
    """``value`` as a finite float in the interval (strings, bools, NaN and infinities refused)."""
    a, b = "(" if open_lo else "[", ")" if open_hi else "]"
    want = f"must be a finite number in {a}{lo:g}, {hi:g}{b}"
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not is_finite(value):
        raise _bad(key, value, want)
    v = float(value)
    if not math.isfinite(v) or v < lo or v > hi or (open_lo and v == lo) or (open_hi and v == hi):
        raise _bad(key, value, want)
    return v


def _str(key: str, value: Any, choices: tuple[str, ...] | None = None) -> str:
    if not isinstance(value, str) or len(value) > MAX_TEXT:
        raise _bad(key, value, f"must be a string of at most {MAX_TEXT} characters")
    if choices is not None and value not in choices:
        raise _bad(key, value, f"must be one of {list(choices)}")
    return value


def _bool(key: str, value: Any) -> bool:
    # numpy bools come from older checkpoints; strings ("no") and numbers are refused
    if type(value).__name__ not in ("bool", "bool_"):
        raise _bad(key, value, "must be true or false")
    return bool(value)


def _nesting(value: Any, limit: int) -> int:
    """Depth of nested dicts/lists in ``value``, stopping (at limit + 1) once beyond ``limit``."""
    todo = [(value, 1)]
    deepest = 0
    while todo:
        v, d = todo.pop()
        if isinstance(v, (dict, list, tuple)):
            deepest = max(deepest, d)
            if deepest > limit:
                return deepest
            todo.extend((x, d + 1) for x in (v.values() if isinstance(v, dict) else v))
    return deepest


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

    def __post_init__(self) -> None:
        # every field checked by type and range; numbers normalised to Python int/float
        put = object.__setattr__
        put(self, "name", _str("sensor.name", self.name))
        put(self, "width", _int("sensor.width", self.width, 1, MAX_SENSOR_SIDE))
        put(self, "height", _int("sensor.height", self.height, 1, MAX_SENSOR_SIDE))
        if self.width * self.height > MAX_SENSOR_PIXELS:
            raise _bad("sensor.width", self.width, f"{self.width} x {self.height} exceeds {MAX_SENSOR_PIXELS} pixels")
        for key, lo in (("fx", 0.0), ("fy", 0.0)):
            put(self, key, _float(f"sensor.{key}", getattr(self, key), lo, 1e7, open_lo=True))
        for key in ("cx", "cy"):
            put(self, key, _float(f"sensor.{key}", getattr(self, key), -1e6, 1e6))
        dist = self.distortion
        if isinstance(dist, (str, bytes, dict)) or not hasattr(dist, "__len__") or len(dist) > MAX_DISTORTION:
            raise _bad("sensor.distortion", dist, f"must be a list of at most {MAX_DISTORTION} numbers")
        put(self, "distortion", tuple(_float("sensor.distortion", v, -1e6, 1e6) for v in dist))
        put(self, "depth", _str("sensor.depth", self.depth, ("z",)))
        put(self, "min_range_m", _float("sensor.min_range_m", self.min_range_m, 0.0, 1e3))
        put(self, "max_range_m", _float("sensor.max_range_m", self.max_range_m, 0.0, 1e3, open_lo=True))
        if self.min_range_m >= self.max_range_m:
            raise _bad("sensor.min_range_m", self.min_range_m, f"must be below max_range_m {self.max_range_m:g}")


@dataclass(frozen=True)
class ModelMeta:
    """Everything needed to run a model on a raw depth frame, and how it came to be."""

    encoder: str = "vgg16"
    width: float = 1.0
    in_channels: int = 3
    batch_norm: bool = False
    extra_skip: bool = False
    full_skip: bool = False  # the full-resolution conv1 map fused before the classifier (edge.train.model)
    pad_multiple: int = 32
    standardize: str = "valid-pixels"
    cues: tuple[str, ...] = ()  # extra input channels after the depth copies (edge.cues.CUES)
    threshold: float = 0.5
    threshold_policy: str = "default 0.5 (paper)"
    # after the threshold, object components (8-connected) under this many pixels become
    # background (edge.postprocess); 0 keeps every pixel. Models from before the rule get it too.
    min_object_px: int = MIN_OBJECT_PX
    # then, object pixels lower than this (metres) above the dominant plane become table in
    # components reaching over it (edge.postprocess.remove_low_parts); 0 = off, the simulator's meaning
    min_height_m: float = 0.0
    sensor: SensorSpec = field(default_factory=SensorSpec)
    params: int = 0
    training: dict[str, Any] = field(default_factory=dict)
    version: int = SCHEMA_VERSION

    def __post_init__(self) -> None:
        # Every field checked by type and range (a model file is untrusted input); one
        # `ModelError` naming the key and the value. Numbers are normalised to Python int/float.
        put = object.__setattr__
        put(self, "encoder", _str("encoder", self.encoder))
        if not self.encoder:
            raise _bad("encoder", self.encoder, "must name an encoder, e.g. vgg16")
        put(self, "width", _float("width", self.width, 0.0, MAX_WIDTH, open_lo=True))
        in_ch = _int("in_channels", self.in_channels, 1, 3)
        if in_ch not in (1, 3):
            raise _bad("in_channels", self.in_channels, "must be 1 or 3")
        put(self, "in_channels", in_ch)
        put(self, "batch_norm", _bool("batch_norm", self.batch_norm))
        put(self, "extra_skip", _bool("extra_skip", self.extra_skip))
        put(self, "full_skip", _bool("full_skip", self.full_skip))
        put(self, "pad_multiple", _int("pad_multiple", self.pad_multiple, 1, MAX_PAD_MULTIPLE))
        put(self, "standardize", _str("standardize", self.standardize, tuple(STANDARDIZE_MODES)))
        cues = self.cues
        if isinstance(cues, (str, bytes, dict)) or not hasattr(cues, "__iter__") or not hasattr(cues, "__len__") or len(cues) > len(CUES):
            raise _bad("cues", cues, f"must be a list of distinct names from {list(CUES)}")
        cues = tuple(cues)
        if any(not isinstance(c, str) or c not in CUES for c in cues) or len(set(cues)) != len(cues):
            raise _bad("cues", list(cues), f"must be a list of distinct names from {list(CUES)}")
        put(self, "cues", cues)
        put(self, "threshold", _float("threshold", self.threshold, 0.0, 1.0, open_lo=True, open_hi=True))
        put(self, "threshold_policy", _str("threshold_policy", self.threshold_policy))
        put(self, "min_object_px", _int("min_object_px", self.min_object_px, 0, MAX_SENSOR_PIXELS))
        put(self, "min_height_m", _float("min_height_m", self.min_height_m, 0.0, MAX_MIN_HEIGHT_M))
        if not isinstance(self.sensor, SensorSpec):
            raise _bad("sensor", self.sensor, "must be a sensor description (a JSON object)")
        put(self, "params", _int("params", self.params, 0, MAX_PARAMS))
        if not isinstance(self.training, dict):
            raise _bad("training", self.training, "must be a JSON object")
        if _nesting(self.training, MAX_NESTING) > MAX_NESTING:
            raise _bad("training", "{...}", f"is nested deeper than {MAX_NESTING} levels")
        put(self, "version", _int("version", self.version, 1, SCHEMA_VERSION))

    @property
    def net_channels(self) -> int:
        """Channels the network's first layer takes: the depth copies plus one per cue."""
        return self.in_channels + len(self.cues)

    def with_(self, **changes: Any) -> ModelMeta:
        """A copy with some fields changed (the dataclass is frozen)."""
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        if not self.full_skip:  # added later: models without it keep their metadata byte for byte
            del d["full_skip"]
        if not self.min_height_m:  # likewise: models without the height rule keep their metadata
            del d["min_height_m"]
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
        sensor = d.pop("sensor", None)
        sensor = {} if sensor is None else sensor
        if not isinstance(sensor, dict):
            raise _bad("sensor", sensor, "must be a JSON object")
        sknown = {f.name for f in fields(SensorSpec)}
        sunknown = sorted(set(sensor) - sknown)
        if sunknown:
            raise ModelError(f"unknown sensor metadata keys {sunknown}; valid: {sorted(sknown)}")
        try:
            return cls(sensor=SensorSpec(**sensor), **d)
        except TypeError as exc:
            raise ModelError(f"bad model metadata: {exc}") from None

    @classmethod
    def from_json(cls, text: str) -> ModelMeta:
        if not isinstance(text, str):
            raise ModelError(f"model metadata must be JSON text, got {type(text).__name__}")
        try:
            d = json.loads(text)
        except RecursionError:
            raise ModelError(f"model metadata is nested too deeply (more than {MAX_NESTING} levels allowed)") from None
        except ValueError as exc:  # JSONDecodeError, and integers too long to convert
            raise ModelError(f"model metadata is not valid JSON ({' '.join(str(exc).split())[:120]})") from None
        return cls.from_dict(d)

    def onnx_props(self) -> dict[str, str]:
        """Key/value pairs for ONNX ``metadata_props``: the full JSON plus flat, greppable keys."""
        s = self.sensor
        return {
            META_KEY: self.to_json(),
            "threshold": repr(float(self.threshold)),
            "threshold_policy": self.threshold_policy,
            "postprocessing": f"object (logit >= logit(threshold), valid) components, 8-connected, under "
            f"{self.min_object_px} px -> background"
            + (f"; then object pixels under {self.min_height_m * 1000:g} mm above the dominant plane -> table "
               "in components reaching over it" if self.min_height_m else ""),
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
