"""Torch inference on a training checkpoint, with the shared preprocessing (eval and tune of a ``.pt``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from edge.meta import ModelMeta

__all__ = ["TorchPredictor"]


class TorchPredictor:
    """A training checkpoint run by torch on the CPU: an `edge.infer.Predictor` like `edge.infer.Segmenter`."""

    meta: ModelMeta
    name: str

    def __init__(self, path: str | Path, threads: int = 2) -> None:
        import torch

        from edge.train.checkpoint import load_checkpoint

        # torch's thread count is process-wide; eval/tune are single-model processes.
        torch.set_num_threads(max(1, int(threads)))
        self._torch = torch
        self.model, self.meta, _ = load_checkpoint(path)
        self.name = str(path)

    def __repr__(self) -> str:
        return f"TorchPredictor({self.name!r})"

    def logits(self, depth: np.ndarray) -> np.ndarray:
        from edge.preprocess import preprocess_for

        pre = preprocess_for(depth, self.meta)
        h, w = pre.shape
        with self._torch.inference_mode():
            out = self.model(self._torch.from_numpy(pre.x[None]))
        return out[0, 0, :h, :w].numpy().astype(np.float32, copy=True)
