"""One entry point for every model file a user can hand to eval and tune.

Why: evaluation and threshold tuning only need an `edge.infer.Predictor` ("depth frame in,
per-pixel logits out" plus the model's metadata); they should not care whether the weights are
an ONNX export (the edge path: `edge.infer.Segmenter`) or a torch checkpoint straight out of
training (`edge.train.predict.TorchPredictor`). torch is imported only for a checkpoint, so
evaluating an ONNX model never loads it.
"""

from __future__ import annotations

from pathlib import Path

from edge.defaults import SUFFIXES, resolve_model
from edge.errors import ModelError
from edge.infer import Predictor, Segmenter

__all__ = ["Predictor", "load_predictor"]


def load_predictor(path: str | Path | None = None, threads: int = 2) -> Predictor:
    """A `Predictor` for ``path``: .onnx via onnxruntime, .pt/.pth via torch.

    Args:
        path: the model file; None = the shipped default: its ONNX file (no torch needed), else
            its checkpoint.
        threads: inference threads.

    Raises:
        ModelError: missing, unreadable or of an unknown type.
    """
    p = resolve_model(path, kinds=("onnx", "pt"))
    suffix = p.suffix.lower()
    if suffix in SUFFIXES["onnx"]:
        return Segmenter(p, threads=threads)
    if suffix in SUFFIXES["pt"]:
        from edge.cliutil import require

        require("train", ("torch",), f"the checkpoint {p.name}")
        from edge.train.predict import TorchPredictor

        return TorchPredictor(p, threads=threads)
    raise ModelError(
        f"{p}: unknown model type '{suffix or '(no suffix)'}'; expected one of "
        f"{', '.join(SUFFIXES['onnx'] + SUFFIXES['pt'])}"
    )
