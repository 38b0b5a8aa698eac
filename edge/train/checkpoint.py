"""Checkpoint files: weights plus the `ModelMeta` that says how to use them.

A checkpoint is a ``torch.save`` dict::

    {"format": "depthseg-checkpoint", "version": 1, "meta": ModelMeta.to_dict(),
     "state_dict": model weights, "epoch": int, "best_val_loss": float | None,
     "history": [per-epoch dicts], "optimizer": optimizer state (training checkpoints only)}

Written atomically (temp file + rename), so an interrupted save never destroys the previous one.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from edge.errors import ConfigError, ModelError
from edge.io import atomic_write
from edge.meta import ModelMeta
from edge.train.model import FCN8s, build_model, count_parameters

__all__ = ["save_checkpoint", "load_checkpoint", "read_checkpoint", "checkpoint_meta", "CHECKPOINT_FORMAT"]

CHECKPOINT_FORMAT = "depthseg-checkpoint"


def contiguous_state(state: dict[str, Any]) -> dict[str, Any]:
    """``state`` with every tensor in the default (NCHW) layout: a model trained channels-last
    (`edge.train.loop.TrainConfig.memory_format`) is stored as any other, so code that reads a
    checkpoint never meets its training layout."""
    return {k: v.contiguous() if isinstance(v, torch.Tensor) else v for k, v in state.items()}


def save_checkpoint(path: str | Path, model: FCN8s, meta: ModelMeta, **extra: Any) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = meta.with_(params=count_parameters(model))
    from edge.provenance import provenance

    blob = {
        "format": CHECKPOINT_FORMAT, "version": 1, "meta": meta.to_dict(),
        "state_dict": contiguous_state(model.state_dict()),
        "provenance": provenance(),  # depthseg version and git commit that wrote it
    }
    blob.update(extra)
    with atomic_write(path) as tmp:
        torch.save(blob, tmp)
    return path


def read_checkpoint(path: str | Path) -> dict[str, Any]:
    """The raw checkpoint dict, after checking it is one of ours."""
    p = Path(path)
    if not p.exists():
        raise ModelError(f"{p}: no such model file")
    if p.is_dir():
        raise ModelError(f"{p}: is a directory, expected a .pt checkpoint")
    try:
        # weights_only: a checkpoint is tensors, numbers, strings and containers; unpickling
        # anything else (code) is refused, so a hostile .pt cannot run code (issue 11)
        blob = torch.load(p, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - any unpickling failure means a corrupt or unsafe file
        raise ModelError(
            f"{p}: not a readable depthseg checkpoint ({type(exc).__name__}: only weights, numbers and "
            "strings are loaded); re-train or re-export it"
        ) from None
    if not isinstance(blob, dict) or blob.get("format") != CHECKPOINT_FORMAT:
        raise ModelError(f"{p}: not a depthseg checkpoint (no '{CHECKPOINT_FORMAT}' format tag)")
    if not isinstance(blob.get("meta"), dict):
        raise ModelError(f"{p}: checkpoint has no 'meta' record (a dict of model metadata); re-train or re-export it")
    if not isinstance(blob.get("state_dict"), dict):
        raise ModelError(f"{p}: checkpoint has no 'state_dict' (a dict of weights); re-train it")
    return blob


def checkpoint_meta(path: str | Path, blob: dict[str, Any] | None = None) -> ModelMeta:
    """The checked `ModelMeta` of a checkpoint; a `ModelError` naming the file and the bad key."""
    blob = read_checkpoint(path) if blob is None else blob
    try:
        return ModelMeta.from_dict(blob["meta"])
    except ModelError as exc:
        raise ModelError(f"{path}: {exc}") from None


def load_checkpoint(path: str | Path) -> tuple[FCN8s, ModelMeta, dict[str, Any]]:
    """(model in eval mode, its metadata, the raw dict)."""
    blob = read_checkpoint(path)
    meta = checkpoint_meta(path, blob)
    try:
        model = build_model(meta)
    except ConfigError as exc:  # e.g. an encoder name this depthseg does not know
        raise ModelError(f"{path}: {exc}") from None
    try:
        model.load_state_dict(blob["state_dict"])
    except (RuntimeError, KeyError, TypeError, ValueError) as exc:
        why = " ".join(str(exc).split())[:200]
        raise ModelError(f"{path}: weights do not match the architecture in its metadata ({why})") from None
    model.eval()
    return model, meta, blob
