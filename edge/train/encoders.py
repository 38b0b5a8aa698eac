"""Registry of VGG encoders for the FCN-8s head.

The encoder contract (every registered encoder honours it, tests check it):
- ``encoder.features`` is an ``nn.Sequential`` laid out exactly like torchvision's
  ``vgg*.features`` (same indices), so a torchvision VGG ``state_dict`` loads into it;
- ``encoder(x)`` returns ``{"conv1": ..., "pool1": ..., "pool5": ...}``: the last activation of
  the first conv block at full resolution (stride 1, the input of pool1), then the outputs of
  the five max-pools at strides 2, 4, 8, 16, 32 of the input (highest resolution first);
- ``encoder.out_channels`` maps each of those names to its channel count;
- input H and W must be multiples of 32 (the preprocessing pads to that).

A width multiplier scales every channel count, which gives compact members of the same family
(width 1.0 is the paper's network). Names: ``vgg11``, ``vgg13``, ``vgg16``, ``vgg19``, each with
an optional ``_bn`` (batch norm after every conv, as torchvision's ``vgg*_bn``).
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import nn

from edge.errors import ConfigError

__all__ = ["VGGEncoder", "register_encoder", "list_encoders", "create_encoder", "scaled", "VGG_CFGS"]

VGG_CFGS: dict[str, list[int | str]] = {
    "vgg11": [64, "M", 128, "M", 256, 256, "M", 512, 512, "M", 512, 512, "M"],
    "vgg13": [64, 64, "M", 128, 128, "M", 256, 256, "M", 512, 512, "M", 512, 512, "M"],
    "vgg16": [64, 64, "M", 128, 128, "M", 256, 256, 256, "M", 512, 512, 512, "M", 512, 512, 512, "M"],
    "vgg19": [64, 64, "M", 128, 128, "M", 256, 256, 256, 256, "M", 512, 512, 512, 512, "M",
              512, 512, 512, 512, "M"],
}


def scaled(channels: int, width: float) -> int:
    """Channel count for a width multiplier; never below 4 so tiny models still have features."""
    return max(4, int(round(channels * width)))


class VGGEncoder(nn.Module):
    """VGG ``features`` returning the five pool outputs (see the module contract)."""

    def __init__(self, cfg: list[int | str], in_channels: int = 3, width: float = 1.0, batch_norm: bool = False):
        super().__init__()
        layers: list[nn.Module] = []
        self._pool_idx: list[int] = []
        c = in_channels
        pool_channels: list[int] = []
        for v in cfg:
            if v == "M":
                layers.append(nn.MaxPool2d(kernel_size=2, stride=2))
                self._pool_idx.append(len(layers) - 1)
                pool_channels.append(c)
            else:
                out = scaled(int(v), width)
                layers.append(nn.Conv2d(c, out, kernel_size=3, padding=1))
                if batch_norm:
                    layers.append(nn.BatchNorm2d(out))
                layers.append(nn.ReLU(inplace=True))
                c = out
        self.features = nn.Sequential(*layers)
        self.out_channels = {"conv1": pool_channels[0]} | {f"pool{i + 1}": ch for i, ch in enumerate(pool_channels)}

    @property
    def first_conv(self) -> nn.Conv2d:
        return self.features[0]  # type: ignore[return-value]

    def forward(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        out: dict[str, torch.Tensor] = {}
        k = 1
        for i, layer in enumerate(self.features):
            if i == self._pool_idx[0]:
                out["conv1"] = x  # pooling is not in place, so this stays the full-resolution map
            x = layer(x)
            if i in self._pool_idx:
                out[f"pool{k}"] = x
                k += 1
        return out


EncoderBuilder = Callable[..., VGGEncoder]
_REGISTRY: dict[str, EncoderBuilder] = {}


def register_encoder(name: str) -> Callable[[EncoderBuilder], EncoderBuilder]:
    """Decorator adding a builder under ``name``; a duplicate name is a programming error."""

    def deco(fn: EncoderBuilder) -> EncoderBuilder:
        if name in _REGISTRY:
            raise ConfigError(f"encoder '{name}' is already registered")
        _REGISTRY[name] = fn
        return fn

    return deco


def _make(cfg_name: str, bn: bool) -> EncoderBuilder:
    def build(*, in_channels: int = 3, width: float = 1.0) -> VGGEncoder:
        return VGGEncoder(VGG_CFGS[cfg_name], in_channels=in_channels, width=width, batch_norm=bn)

    build.__doc__ = f"{cfg_name}{'_bn' if bn else ''} features (torchvision layout)"
    return build


for _name in VGG_CFGS:
    register_encoder(_name)(_make(_name, False))
    register_encoder(f"{_name}_bn")(_make(_name, True))


def list_encoders() -> list[str]:
    return sorted(_REGISTRY)


def create_encoder(name: str, *, in_channels: int = 3, width: float = 1.0) -> VGGEncoder:
    if name not in _REGISTRY:
        raise ConfigError(f"unknown encoder '{name}'; valid encoders: {', '.join(list_encoders())}")
    if not width > 0:
        raise ConfigError(f"width multiplier must be > 0, got {width}")
    return _REGISTRY[name](in_channels=in_channels, width=width)
