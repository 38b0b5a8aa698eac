"""Static int8 quantisation (QDQ, per-channel) of an exported model, and what it costs in IoU.

Why these choices:
- QDQ + per-channel weights is what onnxruntime's CPU kernels fuse into QLinearConv;
  activations are uint8 and weights int8 (U8S8): with int8 activations (S8S8) onnxruntime leaves
  some convolutions in fp32 here (PITFALLS).
- Calibration uses simulated frames through `edge.preprocess` (or raw frames for a
  --with-preprocessing graph): ranges must come from what the sensor produces.
- onnxruntime's CPU provider has no int8 ConvTranspose: the decoder's five deconvolutions stay
  fp32 between DequantizeLinear/QuantizeLinear pairs. `int8_layers` reads the *optimised* graph
  to say what really runs in int8 instead of trusting the quantiser's intent.
- The IoU on labelled validation frames is measured for both files through `Segmenter` (the
  edge path); more than ``MAX_IOU_DROP`` points lost is refused unless forced.
"""

from __future__ import annotations

import contextlib
import logging
import tempfile
from collections import Counter
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from edge.errors import DataError, ModelError, first_line
from edge.infer import Segmenter, session_options
from edge.preprocess import preprocess_for
from edge.sampleframes import FrameSample

__all__ = [
    "MAX_IOU_DROP",
    "QUANT_OPS",
    "Int8Report",
    "quantize_int8",
    "int8_layers",
    "iou_report",
    "pooled_iou",
    "refuse_message",
]

MAX_IOU_DROP = 0.5  # IoU points (percent) the int8 model may lose against fp32 before we refuse
# Network ops only: a --with-preprocessing graph's float64 statistics must stay untouched.
QUANT_OPS = ["Conv", "ConvTranspose", "MaxPool", "Add", "Relu", "BatchNormalization"]
_COMPUTE = {"Conv", "ConvTranspose", "FusedConv", "QLinearConv", "ConvInteger", "MatMul", "Gemm",
            "QLinearMatMul", "MatMulInteger", "QLinearAdd", "Add"}


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """The quantiser logs warnings on the root logger; library code does not print."""
    root = logging.getLogger()
    level = root.level
    root.setLevel(logging.ERROR)
    try:
        yield
    finally:
        root.setLevel(level)


def _feeds(seg: Segmenter, frames: list[np.ndarray]) -> list[dict[str, np.ndarray]]:
    if seg.with_preprocessing:
        return [{seg.input_name: np.ascontiguousarray(d, dtype=np.float32)[None]} for d in frames]
    m = seg.meta
    return [{seg.input_name: preprocess_for(d, m).x[None]} for d in frames]


def quantize_int8(fp32_path: str | Path, out: str | Path, calib: FrameSample, per_channel: bool = True) -> Path:
    """Write the int8 QDQ model of ``fp32_path`` to ``out`` (metadata carried over, precision int8)."""
    import onnx
    from onnxruntime.quantization import CalibrationDataReader, QuantFormat, QuantType, quantize_static
    from onnxruntime.quantization.shape_inference import quant_pre_process

    from export.onnx_export import set_metadata, write_onnx

    if len(calib) == 0:
        raise DataError("int8 calibration needs at least one frame")
    seg = Segmenter(fp32_path, threads=1)
    feeds = _feeds(seg, calib.depth)

    class Reader(CalibrationDataReader):
        def __init__(self) -> None:
            self._it = iter(feeds)

        def get_next(self) -> dict[str, np.ndarray] | None:
            return next(self._it, None)

    with tempfile.TemporaryDirectory(prefix="depthseg-int8-") as td, _quiet():
        pre = Path(td) / "pre.onnx"
        q = Path(td) / "q.onnx"
        try:
            quant_pre_process(str(fp32_path), str(pre), skip_symbolic_shape=True)
            quantize_static(
                str(pre),
                str(q),
                Reader(),
                quant_format=QuantFormat.QDQ,
                per_channel=per_channel,
                activation_type=QuantType.QUInt8,
                weight_type=QuantType.QInt8,
                op_types_to_quantize=QUANT_OPS,
            )
        except Exception as exc:  # noqa: BLE001 - the quantiser raises many types
            raise ModelError(f"int8 quantisation failed ({type(exc).__name__}: {first_line(exc, 200)})") from None
        proto = onnx.load(str(q))
    props = dict(seg.props)
    props.update(
        {
            "precision": "int8",
            "quantization": f"onnxruntime static QDQ, U8S8, per_channel={per_channel}, "
            f"MinMax calibration on {calib.source}",
        }
    )
    set_metadata(proto, props)
    return write_onnx(proto, out)


def int8_layers(path: str | Path) -> dict[str, dict[str, int]]:
    """Compute ops of the graph onnxruntime actually runs, grouped by precision.

    ``{"int8": {"QLinearConv": 9, ...}, "fp32": {"ConvTranspose": 5, ...}, "qdq": {...}}``.
    """
    import onnx
    import onnxruntime as ort

    with tempfile.TemporaryDirectory(prefix="depthseg-opt-") as td:
        opt = Path(td) / "optimized.onnx"
        so = session_options(1, optimized_model_path=str(opt))
        ort.InferenceSession(str(path), so, providers=["CPUExecutionProvider"])
        graph = onnx.load(str(opt), load_external_data=False).graph
    out: dict[str, Counter] = {"int8": Counter(), "fp32": Counter(), "qdq": Counter()}
    for node in graph.node:
        op = node.op_type
        if op in ("QuantizeLinear", "DequantizeLinear"):
            out["qdq"][op] += 1
        elif op.startswith("QLinear") or op.endswith("Integer"):
            out["int8"][op] += 1
        elif op in _COMPUTE or node.domain == "com.microsoft.nchwc" and op == "Conv":
            out["fp32"][op] += 1
    return {k: dict(sorted(v.items())) for k, v in out.items()}


def pooled_iou(masks: list[np.ndarray], labels: list[np.ndarray], valids: list[np.ndarray]) -> float:
    """Object IoU over all valid pixels of all frames pooled (one ratio, not a mean of ratios)."""
    inter = union = 0
    for m, lab, v in zip(masks, labels, valids):
        p = (m == 1) & v
        t = (lab > 0) & v
        inter += int(np.count_nonzero(p & t))
        union += int(np.count_nonzero(p | t))
    return 1.0 if union == 0 else inter / union


@dataclass(frozen=True)
class Int8Report:
    frames: int
    source: str
    iou_fp32: float  # percent
    iou_int8: float  # percent
    agreement_iou: float  # percent: int8 object mask vs fp32 object mask
    max_abs_prob_diff: float
    max_drop: float = MAX_IOU_DROP
    layers: dict[str, dict[str, int]] = field(default_factory=dict)
    # a --with-preprocessing graph's `height` output, int8 vs fp32 file (None without one). Its path
    # holds no quantised op (QUANT_OPS), so anything but 0 means the quantiser reached the cue
    max_abs_height_diff_m: float | None = None

    @property
    def drop(self) -> float:
        return self.iou_fp32 - self.iou_int8

    @property
    def ok(self) -> bool:
        return self.drop <= self.max_drop and not self.max_abs_height_diff_m

    def to_dict(self) -> dict:
        return asdict(self) | {"drop": self.drop, "ok": self.ok}

    def summary(self) -> str:
        return (
            f"int8 vs fp32 on {self.source}: IoU {self.iou_fp32:.2f} -> {self.iou_int8:.2f} "
            f"({-self.drop:+.2f} points; limit -{self.max_drop:.1f}), int8/fp32 mask agreement IoU "
            f"{self.agreement_iou:.2f} %, max |prob diff| {self.max_abs_prob_diff:.3f}"
            + ("" if self.max_abs_height_diff_m is None else f", max |height diff| {self.max_abs_height_diff_m:.2e} m (must be 0)")
        )

    def layers_summary(self) -> str:
        def fmt(c: dict[str, int]) -> str:
            return ", ".join(f"{v} {k}" for k, v in c.items()) or "none"

        return f"runs in int8: {fmt(self.layers.get('int8', {}))}; stays fp32: {fmt(self.layers.get('fp32', {}))}"


def iou_report(fp32_path: str | Path, int8_path: str | Path, val: FrameSample, threads: int = 2) -> Int8Report:
    """IoU of both models against the labels of ``val`` (labelled frames required)."""
    if not val.labelled:
        raise DataError(f"int8 validation needs labelled frames; {val.source} has none (simulated MCAP has /pico_flexx/labels)")
    a = Segmenter(fp32_path, threads=threads)
    b = Segmenter(int8_path, threads=threads, threshold=a.threshold)
    pa = [a.predict(d) for d in val.depth]
    pb = [b.predict(d) for d in val.depth]
    valids = [p.valid for p in pa]
    labels = [lab for lab in val.label if lab is not None]
    return Int8Report(
        frames=len(val),
        source=val.source,
        iou_fp32=100.0 * pooled_iou([p.mask for p in pa], labels, valids),
        iou_int8=100.0 * pooled_iou([p.mask for p in pb], labels, valids),
        agreement_iou=100.0 * pooled_iou([p.mask for p in pb], [p.mask == 1 for p in pa], valids),
        max_abs_prob_diff=float(max(np.max(np.abs(x.prob - y.prob)) for x, y in zip(pa, pb))),
        layers=int8_layers(int8_path),
        max_abs_height_diff_m=_height_diff(a, b, val.depth),
    )


def _height_diff(a: Segmenter, b: Segmenter, frames: list[np.ndarray]) -> float | None:
    """Largest |difference| of two --with-preprocessing graphs' ``height`` outputs; None if either has none."""
    if not (a.has_height_output and b.has_height_output):
        return None
    return max((float(np.max(np.abs(a.graph_height(d) - b.graph_height(d)))) for d in frames), default=0.0)


def refuse_message(report: Int8Report) -> str:
    if report.max_abs_height_diff_m:
        return (
            f"int8 quantisation changed the graph's height output by up to {report.max_abs_height_diff_m:.2e} m on "
            f"{report.source}; not written. Report it as a bug, or pass `force` to keep it"
        )
    return (
        f"int8 model loses {report.drop:.2f} IoU points against fp32 (limit {report.max_drop:.1f}) on {report.source}; "
        "not written. Calibrate on more frames (`calib` DIR) or pass `force` to keep it"
    )

