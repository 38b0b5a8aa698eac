"""FCN-8s with a VGG encoder, exactly the paper's Table II layout at width 1.0.

Decoder: five ConvTranspose2d (3x3, stride 2, padding 1, output_padding 1), each followed by
ReLU then BatchNorm, channels 512-512-256-128-64-32 (times the width); pool4 is added after the
first deconvolution and pool3 after the second (FCN-8s); a 1x1 conv gives one logit channel.
No sigmoid: the loss is BCEWithLogits and prediction applies the sigmoid (paper III.C, III.E).
``extra_skip`` adds pool2 after the third and pool1 after the fourth deconvolution (paper V.d).
``full_skip`` adds the encoder's full-resolution ``conv1`` map, through a 1x1 projection, after
the last deconvolution. Why: every other path to the classifier passes a stride-2 or coarser
map, so an object boundary can only be placed to about a pixel, and outside the simulator the
model paints a 1-2 px halo around objects (issue 9); this path carries the exact edge.
"""

from __future__ import annotations

import torch
from torch import nn

from edge.errors import ConfigError, ModelError
from edge.meta import ModelMeta
from edge.train.encoders import create_encoder, scaled

__all__ = ["FCN8s", "build_model", "count_parameters", "load_vgg_weights", "freeze_encoder"]


class FCN8s(nn.Module):
    def __init__(self, encoder: nn.Module, width: float = 1.0, extra_skip: bool = False, full_skip: bool = False) -> None:
        super().__init__()
        self.encoder = encoder
        self.extra_skip = extra_skip
        self.full_skip = full_skip
        ch = encoder.out_channels
        c5 = ch["pool5"]
        dec = [scaled(c, width) for c in (512, 256, 128, 64, 32)]
        if dec[0] != ch["pool4"] or dec[1] != ch["pool3"]:
            raise ConfigError(f"encoder pools {ch} do not match decoder channels {dec}")
        ins = [c5] + dec[:-1]
        self.deconvs = nn.ModuleList(
            nn.ConvTranspose2d(i, o, kernel_size=3, stride=2, padding=1, output_padding=1) for i, o in zip(ins, dec)
        )
        self.relu = nn.ReLU(inplace=True)
        self.bns = nn.ModuleList(nn.BatchNorm2d(o) for o in dec)
        self.classifier = nn.Conv2d(dec[-1], 1, kernel_size=1)
        if full_skip:
            self.full_proj = nn.Conv2d(ch["conv1"], dec[-1], kernel_size=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(*self.decode(x))

    def decode(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        """Everything up to the linear head: (the last deconvolution after its ReLU, the conv1 map).

        Why split here: what follows (the last BatchNorm, the full-resolution projection, the
        add and the 1x1 classifier) is affine, so the export folds it into one linear map per
        input (`export.fold`); the conv1 map is None without ``full_skip``.
        """
        h, w = x.shape[-2:]
        if h % 32 or w % 32:
            hp, wp = -(-h // 32) * 32, -(-w // 32) * 32
            raise ModelError(f"input H, W must be multiples of 32, got ({h}, {w}); pad to ({hp}, {wp})")
        f = self.encoder(x)
        skips = {0: "pool4", 1: "pool3"}
        if self.extra_skip:
            skips.update({2: "pool2", 3: "pool1"})
        s = f["pool5"]
        last = len(self.deconvs) - 1
        for i, (deconv, bn) in enumerate(zip(self.deconvs, self.bns)):
            s = self.relu(deconv(s))
            if i == last:
                break
            s = bn(s)
            if i in skips:
                s = s + f[skips[i]]
        return s, (f["conv1"] if self.full_skip else None)

    def head(self, r: torch.Tensor, conv1: torch.Tensor | None) -> torch.Tensor:
        """Logits from `decode`'s two maps: last BatchNorm, (+ projected conv1), 1x1 classifier."""
        s = self.bns[-1](r)
        if conv1 is not None:
            s = s + self.full_proj(conv1)
        return self.classifier(s)


def count_parameters(model: nn.Module, trainable_only: bool = False) -> int:
    return sum(p.numel() for p in model.parameters() if p.requires_grad or not trainable_only)


def build_model(meta: ModelMeta) -> FCN8s:
    """The network a ``ModelMeta`` describes (weights freshly initialised: Kaiming, PyTorch default)."""
    name = meta.encoder + ("_bn" if meta.batch_norm and not meta.encoder.endswith("_bn") else "")
    enc = create_encoder(name, in_channels=meta.net_channels, width=meta.width)
    return FCN8s(enc, width=meta.width, extra_skip=meta.extra_skip, full_skip=meta.full_skip)


def freeze_encoder(model: FCN8s) -> None:
    """The paper's setting: the pretrained encoder is a fixed feature extractor."""
    for p in model.encoder.parameters():
        p.requires_grad_(False)


def load_vgg_weights(model: FCN8s, path: str) -> None:
    """Load a local torchvision VGG ``state_dict`` (``features.*`` keys) into the encoder.

    A 1-channel model receives the RGB first conv summed over its input channels (same trick as
    the single-channel export); a width other than 1.0 cannot take ImageNet weights.
    """
    try:
        sd = torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise ModelError(f"{path}: no such encoder weights file") from None
    except Exception as exc:  # noqa: BLE001 - any unpickling failure is a bad file for the user
        raise ModelError(f"{path}: not a readable torch state_dict ({type(exc).__name__}: {exc})") from None
    if isinstance(sd, dict) and "state_dict" in sd and isinstance(sd["state_dict"], dict):
        sd = sd["state_dict"]
    feats = {k[len("features."):]: v for k, v in sd.items() if k.startswith("features.")}
    if not feats:
        raise ModelError(f"{path}: no 'features.*' keys; expected a torchvision VGG state_dict")
    own = model.encoder.features.state_dict()
    w0 = feats.get("0.weight")
    if w0 is not None and own["0.weight"].shape[1] == 1 and w0.shape[1] == 3:
        feats["0.weight"] = w0.sum(dim=1, keepdim=True)
    bad = {k: (tuple(v.shape), tuple(own[k].shape)) for k, v in feats.items() if k in own and own[k].shape != v.shape}
    missing = sorted(set(own) - set(feats))
    if bad or missing:
        raise ModelError(
            f"{path}: does not fit this encoder (shape mismatches {dict(list(bad.items())[:3])}, "
            f"missing {missing[:3]}); use `width` 1.0 and the matching VGG depth/batch-norm variant"
        )
    model.encoder.features.load_state_dict(feats, strict=True)
