"""PyTorch -> ONNX for the edge, and the proof that the file computes what PyTorch computes.

What the file must be (the edge loads nothing else): one self-contained ``.onnx`` (the dynamo
exporter writes weights to a side ``.onnx.data`` file unless ``external_data=False``), opset
>= 17, input ``depth`` [N, C, H, W] with dynamic N, H and W (multiples of 32), output
``logits`` [N, 1, H, W], and the `ModelMeta` in ``metadata_props`` so every tool reads channels,
padding, threshold, sensor and training recipe from the model itself.

The check runs the exported file through `edge.infer.Segmenter` (the real edge path) and
PyTorch on the same frames and fails above a stated tolerance:
max |logit difference| <= LOGIT_ATOL * max(1, max |logit|), and the share of valid pixels
whose mask flips at the model's threshold <= FLIP_TOL.
"""

from __future__ import annotations

import contextlib
import io
import logging
import warnings
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from edge.errors import ModelError, first_line
from edge.infer import INPUT_NAME, OUTPUT_LOGITS
from edge.io import atomic_path, atomic_write
from edge.meta import ModelMeta
from edge.metrics import predict_mask
from edge.preprocess import padded_shape, preprocess, preprocess_for
from edge.train.model import FCN8s
from export.fold import folded

__all__ = [
    "OPSET",
    "LOGIT_ATOL",
    "FLIP_TOL",
    "ExportCheck",
    "export_onnx",
    "write_onnx",
    "set_metadata",
    "check_against_torch",
    "quiet_export",
    "export_props",
    "torch_logits",
]

OPSET = 18
LOGIT_ATOL = 1e-3  # relative to max(1, max |logit|): float32 reassociation, BN folding
FLIP_TOL = 1e-3  # at most 0.1 % of valid pixels may change class at the threshold


@contextlib.contextmanager
def quiet_export() -> Iterator[None]:
    """Silence the exporter's progress prints and warnings: library code does not print."""
    loggers = [logging.getLogger(n) for n in ("torch.onnx", "torch.export", "torch._dynamo", "onnxscript")]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.ERROR)
    try:
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
            warnings.simplefilter("ignore")
            yield
    finally:
        for lg, lv in zip(loggers, levels):
            lg.setLevel(lv)


def set_metadata(model_proto, props: dict[str, str]) -> None:
    """Replace ``metadata_props`` entries with ``props`` (other keys kept).

    Every write also stamps ``depthseg_version`` and ``git_commit`` (`edge.provenance`): the code
    that wrote the file, read at run time.
    """
    from edge.provenance import provenance

    props = {**provenance(), **props}
    keep = [(p.key, p.value) for p in model_proto.metadata_props if p.key not in props]
    del model_proto.metadata_props[:]
    for k, v in keep + sorted(props.items()):
        entry = model_proto.metadata_props.add()
        entry.key, entry.value = k, str(v)


def write_onnx(model_proto, out: str | Path) -> Path:
    """Check and write one self-contained file atomically (temp file, then rename)."""
    import onnx

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        onnx.checker.check_model(model_proto, full_check=True)
    except Exception as exc:  # noqa: BLE001 - checker raises several types
        raise ModelError(f"exported graph fails onnx.checker: {first_line(exc, 200)}") from None
    with atomic_write(out) as tmp:
        onnx.save_model(model_proto, str(tmp), save_as_external_data=False)
    return out


def export_props(meta: ModelMeta, extra: dict[str, str] | None) -> dict[str, str]:
    props = meta.onnx_props()
    props.update({"precision": "fp32", "graph": "logits", "opset": str(OPSET), "torch": torch.__version__})
    props.update(extra or {})
    return props


def export_onnx(
    model: FCN8s,
    meta: ModelMeta,
    out: str | Path,
    *,
    dynamic_hw: bool = True,
    extra_props: dict[str, str] | None = None,
    fold: bool = True,
) -> Path:
    """Export ``model`` (any in_channels) to ``out``: named I/O, dynamic shapes, metadata.

    ``fold``: the affine head as two matrix products (`export.fold`, the same function, faster
    on the edge); False writes the layers as trained (for measuring what the fold buys).
    """
    import onnx

    model = folded(model.eval()) if fold else model.eval()
    s = meta.sensor
    hp, wp = padded_shape(s.height, s.width, meta.pad_multiple)
    # two example frames: with one, torch.export specialises the batch to 1 (the head's MatMul broadcasts)
    example = torch.zeros(2, meta.net_channels, hp, wp)
    dims: dict[int, object] = {0: torch.export.Dim("batch", min=1, max=1024)}
    if dynamic_hw:
        dims[2] = 32 * torch.export.Dim("h32", min=1, max=128)
        dims[3] = 32 * torch.export.Dim("w32", min=1, max=128)
    raw = atomic_path(Path(out)).with_suffix(".raw.onnx")
    try:
        with quiet_export(), torch.no_grad():
            torch.onnx.export(
                model,
                (example,),
                str(raw),
                input_names=[INPUT_NAME],
                output_names=[OUTPUT_LOGITS],
                opset_version=OPSET,
                dynamo=True,
                external_data=False,
                dynamic_shapes=(dims,),
                optimize=True,
            )
        proto = onnx.load(str(raw), load_external_data=False)
    except ModelError:
        raise
    except Exception as exc:  # noqa: BLE001 - exporter failures come in many types
        raise ModelError(f"torch.onnx.export failed ({type(exc).__name__}: {first_line(exc, 200)})") from None
    finally:
        raw.unlink(missing_ok=True)
        Path(str(raw) + ".data").unlink(missing_ok=True)
    proto.doc_string = "depthseg FCN-8s: depth [N,C,H,W] standardised -> logits [N,1,H,W]"
    set_metadata(proto, export_props(meta, extra_props))
    return write_onnx(proto, out)


@dataclass(frozen=True)
class ExportCheck:
    """Outcome of comparing an exported file with PyTorch on the same frames."""

    frames: int
    source: str
    max_abs_diff: float
    max_abs_logit: float
    tolerance: float
    flip_fraction: float
    flip_tolerance: float
    batch_max_abs_diff: float

    @property
    def ok(self) -> bool:
        return (
            self.max_abs_diff <= self.tolerance
            and self.batch_max_abs_diff <= self.tolerance
            and self.flip_fraction <= self.flip_tolerance
        )

    def to_dict(self) -> dict:
        return asdict(self) | {"ok": self.ok}

    def summary(self) -> str:
        return (
            f"check vs PyTorch on {self.source}: max |logit diff| {self.max_abs_diff:.2e} "
            f"(batched {self.batch_max_abs_diff:.2e}; tolerance {self.tolerance:.2e}), "
            f"mask flips {100 * self.flip_fraction:.4f} % of valid pixels (tolerance {100 * self.flip_tolerance:.2f} %)"
        )


def torch_logits(model: FCN8s, meta: ModelMeta, depth: np.ndarray) -> np.ndarray:
    """Reference: the Python path (edge.preprocess + the PyTorch model), cropped to H x W."""
    pre = preprocess_for(depth, meta)
    with torch.no_grad():
        out = model.eval()(torch.from_numpy(pre.x[None])).numpy()
    h, w = pre.shape
    return out[0, 0, :h, :w]


def check_against_torch(
    onnx_path: str | Path,
    model: FCN8s,
    meta: ModelMeta,
    frames: list[np.ndarray],
    source: str = "",
    threads: int = 2,
) -> ExportCheck:
    """Compare the exported file (through `Segmenter`, the edge path) with PyTorch; raise above tolerance."""
    from edge.infer import Segmenter

    seg = Segmenter(onnx_path, threads=threads)
    diffs, scale, flips, n_valid = [], 0.0, 0, 0
    refs = []
    for d in frames:
        ref = torch_logits(model, meta, d)
        got = seg.logits(d)
        valid = preprocess(d, 1, meta.pad_multiple).valid
        diffs.append(float(np.max(np.abs(got - ref))))
        scale = max(scale, float(np.max(np.abs(ref))))
        flips += int(np.count_nonzero((predict_mask(got, seg.threshold) != predict_mask(ref, seg.threshold)) & valid))
        n_valid += int(valid.sum())
        refs.append(ref)
    batch = seg.logits_batch(frames)
    batch_diff = float(max(np.max(np.abs(b - r)) for b, r in zip(batch, refs)))
    check = ExportCheck(
        frames=len(frames),
        source=source or f"{len(frames)} frames",
        max_abs_diff=max(diffs),
        max_abs_logit=scale,
        tolerance=LOGIT_ATOL * max(1.0, scale),
        flip_fraction=flips / max(n_valid, 1),
        flip_tolerance=FLIP_TOL,
        batch_max_abs_diff=batch_diff,
    )
    if not check.ok:
        raise ModelError(f"{onnx_path}: ONNX output differs from PyTorch beyond tolerance: {check.summary()}")
    return check
