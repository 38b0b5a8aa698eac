"""One small interface over every model file a user can hand to eval and tune.

Why: evaluation and threshold tuning only need "depth frame in, per-pixel logits out" plus the
model's metadata; they should not care whether the weights are an ONNX export (the edge path,
onnxruntime) or a torch checkpoint (straight out of training). torch is imported only inside the
checkpoint branch, so evaluating an ONNX model never loads it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from edge.errors import ModelError
from edge.meta import ModelMeta

__all__ = ["Predictor", "OnnxPredictor", "TorchPredictor", "load_predictor", "resolve_model_path"]

ONNX_SUFFIXES = (".onnx",)
TORCH_SUFFIXES = (".pt", ".pth")


class Predictor:
    """Depth frame (H x W metres, any invalid marker) -> float32 H x W object logits."""

    meta: ModelMeta
    name: str

    def logits(self, depth: np.ndarray) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"


class OnnxPredictor(Predictor):
    """An exported model run by onnxruntime through `edge.infer.Segmenter` (the edge path)."""

    def __init__(self, path: Path, threads: int = 2) -> None:
        from edge.infer import Segmenter

        self._seg = Segmenter(model_path=path, threads=threads)
        self.meta = self._seg.meta
        self.name = str(path)

    def logits(self, depth: np.ndarray) -> np.ndarray:
        return np.asarray(self._seg.logits(depth), dtype=np.float32)


class TorchPredictor(Predictor):
    """A training checkpoint run by torch on the CPU, with the shared preprocessing."""

    def __init__(self, path: Path, threads: int = 2) -> None:
        import torch

        from edge.checkpoint import load_checkpoint

        # torch's thread count is process-wide; eval/tune are single-model processes.
        torch.set_num_threads(max(1, int(threads)))
        self._torch = torch
        self.model, self.meta, _ = load_checkpoint(path)
        self.name = str(path)

    def logits(self, depth: np.ndarray) -> np.ndarray:
        from edge.preprocess import preprocess_for

        pre = preprocess_for(depth, self.meta)
        h, w = pre.shape
        with self._torch.inference_mode():
            out = self.model(self._torch.from_numpy(pre.x[None]))
        return out[0, 0, :h, :w].numpy().astype(np.float32, copy=True)


def resolve_model_path(path: str | Path | None) -> Path:
    """The model file to use: ``path``, or the shipped default (checkpoint first, then ONNX)."""
    from edge import defaults

    if path is None:
        for p in (defaults.DEFAULT_CHECKPOINT, defaults.DEFAULT_ONNX):
            if Path(p).exists():
                return Path(p)
        raise ModelError(
            f"no --model given and the shipped default model is missing ({defaults.DEFAULT_CHECKPOINT} "
            f"or {defaults.DEFAULT_ONNX}); pass --model FILE or rebuild it with tools/train_default.sh"
        )
    p = Path(path)
    if not p.exists():
        raise ModelError(f"{p}: no such model file")
    if p.is_dir():
        raise ModelError(f"{p}: is a directory, expected a .onnx or .pt model file")
    return p


def load_predictor(path: str | Path | None = None, threads: int = 2) -> Predictor:
    """A `Predictor` for ``path`` (.onnx via onnxruntime, .pt/.pth via torch; None = the default)."""
    p = resolve_model_path(path)
    suffix = p.suffix.lower()
    if suffix in ONNX_SUFFIXES:
        return OnnxPredictor(p, threads=threads)
    if suffix in TORCH_SUFFIXES:
        return TorchPredictor(p, threads=threads)
    raise ModelError(
        f"{p}: unknown model type '{suffix or '(no suffix)'}'; expected one of "
        f"{', '.join(ONNX_SUFFIXES + TORCH_SUFFIXES)}"
    )
