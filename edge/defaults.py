"""Where the shipped default model lives; every command uses it when ``--model`` is omitted."""

from __future__ import annotations

from pathlib import Path

__all__ = ["MODELS_DIR", "DEFAULT_CHECKPOINT", "DEFAULT_ONNX", "default_model"]

MODELS_DIR = Path(__file__).resolve().parent / "models"
DEFAULT_CHECKPOINT = MODELS_DIR / "default.pt"  # torch checkpoint, 3-channel (paper input)
DEFAULT_ONNX = MODELS_DIR / "default.onnx"  # single-channel fp32 export of the same weights


def default_model(kind: str = "onnx") -> Path:
    """Path of the shipped model of ``kind`` ('onnx' for the edge path, 'pt' for torch tools)."""
    from edge.errors import ModelError

    p = DEFAULT_ONNX if kind == "onnx" else DEFAULT_CHECKPOINT
    if not p.exists():
        raise ModelError(f"the shipped default model {p} is missing; rebuild it with tools/train_default.sh")
    return p
