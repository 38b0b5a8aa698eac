"""A self-contained edge model: raw depth in, object probability out, nothing else needed.

Why: a C++ robot should need only onnxruntime. The wrapper below restates `edge.preprocess`
in tensor operations (it is the only other place that does, and a test proves the two agree):
invalid = not finite or <= 0; mean and std over the valid pixels (float64, like numpy; std
floored at ``STD_FLOOR``; no valid pixel -> mean 0, all zeros); invalid -> 0; zero-pad
bottom/right to multiples of ``pad_multiple``; the network; crop; sigmoid.

Graph I/O: input ``depth`` float32 [N, H, W] (metres, the sensor's H x W), outputs
``probability`` float32 [N, H, W] and ``valid`` bool [N, H, W] (so the caller can mark invalid
pixels unknown without recomputing it). The frame size is fixed by the sensor in the metadata.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from edge.errors import ModelError
from edge.frames import atomic_path
from edge.infer import INPUT_NAME, OUTPUT_PROB, OUTPUT_VALID, sigmoid
from edge.meta import ModelMeta
from edge.model import FCN8s
from edge.preprocess import STD_FLOOR, padded_shape
from export.onnx_export import OPSET, export_props, quiet_export, set_metadata, torch_logits, write_onnx

__all__ = ["EdgeGraph", "export_with_preprocessing", "check_against_python", "PROB_ATOL", "PreprocCheck"]

PROB_ATOL = 1e-4  # probability; float32 network arithmetic in two runtimes


class EdgeGraph(nn.Module):
    """Preprocessing + FCN-8s + crop + sigmoid as one module (see the module docstring)."""

    def __init__(self, model: FCN8s, meta: ModelMeta) -> None:
        super().__init__()
        self.model = model.eval()
        self.channels = meta.in_channels
        self.h, self.w = meta.sensor.height, meta.sensor.width
        self.hp, self.wp = padded_shape(self.h, self.w, meta.pad_multiple)

    def forward(self, depth: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        valid = torch.isfinite(depth) & (depth > 0)
        d = torch.where(valid, depth, torch.zeros_like(depth)).to(torch.float64)
        v = valid.to(torch.float64)
        n = torch.clamp(v.sum(dim=(1, 2), keepdim=True), min=1.0)
        mean = d.sum(dim=(1, 2), keepdim=True) / n
        var = (((d - mean) * v) ** 2).sum(dim=(1, 2), keepdim=True) / n
        std = torch.clamp(torch.sqrt(var), min=STD_FLOOR)
        z = torch.where(valid, (d - mean) / std, torch.zeros_like(d)).to(torch.float32)
        x = F.pad(z, (0, self.wp - self.w, 0, self.hp - self.h)).unsqueeze(1)
        if self.channels == 3:
            x = x.expand(-1, 3, -1, -1)
        logits = self.model(x)[:, 0, : self.h, : self.w]
        return torch.sigmoid(logits), valid


def export_with_preprocessing(
    model: FCN8s, meta: ModelMeta, out: str | Path, extra_props: dict[str, str] | None = None
) -> Path:
    """Export `EdgeGraph` to one self-contained file with the model's metadata."""
    import onnx

    graph = EdgeGraph(model, meta).eval()
    example = torch.full((1, meta.sensor.height, meta.sensor.width), 0.3)
    raw = atomic_path(Path(out)).with_suffix(".raw.onnx")
    try:
        with quiet_export(), torch.no_grad():
            torch.onnx.export(
                graph,
                (example,),
                str(raw),
                input_names=[INPUT_NAME],
                output_names=[OUTPUT_PROB, OUTPUT_VALID],
                opset_version=OPSET,
                dynamo=True,
                external_data=False,
                dynamic_shapes=({0: torch.export.Dim("batch", min=1, max=1024)},),
                optimize=True,
            )
        proto = onnx.load(str(raw), load_external_data=False)
    except Exception as exc:  # noqa: BLE001 - exporter failures come in many types
        raise ModelError(f"torch.onnx.export failed ({type(exc).__name__}: {str(exc).splitlines()[0][:200]})") from None
    finally:
        raw.unlink(missing_ok=True)
        Path(str(raw) + ".data").unlink(missing_ok=True)
    s = meta.sensor
    proto.doc_string = (
        f"depthseg edge model: raw depth [N,{s.height},{s.width}] metres (0/NaN/neg/inf invalid) -> "
        f"probability [N,{s.height},{s.width}], valid [N,{s.height},{s.width}]"
    )
    props = {"graph": "with-preprocessing"} | (extra_props or {})
    set_metadata(proto, export_props(meta, props))
    return write_onnx(proto, out)


@dataclass(frozen=True)
class PreprocCheck:
    frames: int
    source: str
    max_abs_prob_diff: float
    tolerance: float
    valid_mismatch: int
    flip_fraction: float

    @property
    def ok(self) -> bool:
        return self.max_abs_prob_diff <= self.tolerance and self.valid_mismatch == 0

    def to_dict(self) -> dict:
        return asdict(self) | {"ok": self.ok}

    def summary(self) -> str:
        return (
            f"check vs the Python path (edge.preprocess + PyTorch) on {self.source}: max |prob diff| "
            f"{self.max_abs_prob_diff:.2e} (tolerance {self.tolerance:.0e}), valid-mask mismatches {self.valid_mismatch}, "
            f"mask flips {100 * self.flip_fraction:.4f} % of valid pixels"
        )


def check_against_python(
    onnx_path: str | Path, model: FCN8s, meta: ModelMeta, frames: list[np.ndarray], source: str = "", threads: int = 2
) -> PreprocCheck:
    """Run the self-contained file through `Segmenter` and compare with the Python path; raise above tolerance."""
    from edge.infer import Segmenter
    from edge.preprocess import valid_mask

    seg = Segmenter(onnx_path, threads=threads)
    worst, mism, flips, n_valid = 0.0, 0, 0, 0
    for d in frames:
        pred = seg.predict(d)
        ref_p = sigmoid(torch_logits(model, meta, d))
        ref_v = valid_mask(d)
        worst = max(worst, float(np.max(np.abs(pred.prob - ref_p))))
        mism += int(np.count_nonzero(pred.valid != ref_v))
        flips += int(np.count_nonzero(((pred.prob >= seg.threshold) != (ref_p >= seg.threshold)) & ref_v))
        n_valid += int(ref_v.sum())
    check = PreprocCheck(
        frames=len(frames),
        source=source or f"{len(frames)} frames",
        max_abs_prob_diff=worst,
        tolerance=PROB_ATOL,
        valid_mismatch=mism,
        flip_fraction=flips / max(n_valid, 1),
    )
    if not check.ok:
        raise ModelError(f"{onnx_path}: self-contained graph differs from the Python path: {check.summary()}")
    return check
