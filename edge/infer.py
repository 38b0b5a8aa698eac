"""ONNX Runtime inference on raw depth frames: the engine replay, tune, eval and bench share.

Why this shape:
- The model file is the single source of truth: `ModelMeta` (channels, padding, threshold,
  sensor) is read from its ``metadata_props``, so a caller cannot feed a single-channel model
  three channels or use a threshold the model was not tuned for without saying so.
- Preprocessing is `edge.preprocess` (the one implementation), so what runs here is what
  training and evaluation saw. Models exported ``--with-preprocessing`` do it in the graph
  and take the raw frame; both kinds give the same `Prediction`.
- Threads are always explicit (intra-op = ``threads``, inter-op 1, sequential): the onnxruntime
  default follows the host's cores, not the container's, and oversubscribes a small CPU.
- Per-frame Python work is a few vector operations; the session and its options are built once.

Torch-free: numpy + onnxruntime only. Never import torch here, not even indirectly.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Protocol

import numpy as np

from edge.cues import HEIGHT_SCALE
from edge.defaults import resolve_model
from edge.errors import ConfigError, DataError, ModelError
from edge.io.paths import check_input_file
from edge.meta import ModelMeta
from edge.metrics import UNKNOWN, logit, segmentation_mask, sigmoid
from edge.postprocess import check_min_height, check_min_px, describe_height_rule, support_height
from edge.preprocess import preprocess_batch_for, preprocess_for, valid_for

__all__ = [
    "check_logits",
    "checked_logits",
    "Prediction",
    "Predictor",
    "Segmenter",
    "session_options",
    "sigmoid",
    "UNKNOWN",
    "INPUT_NAME",
    "OUTPUT_LOGITS",
    "OUTPUT_PROB",
    "OUTPUT_VALID",
    "OUTPUT_HEIGHT",
]

INPUT_NAME = "depth"
OUTPUT_LOGITS = "logits"
OUTPUT_PROB = "probability"
OUTPUT_VALID = "valid"
OUTPUT_HEIGHT = "height"  # --with-preprocessing graphs of models with the height cue: metres above the support


class Predictor(Protocol):
    """What eval and tune need of a model: metadata, a name, and float32 H x W logits of a frame.

    `Segmenter` (ONNX) and `edge.train.predict.TorchPredictor` (checkpoint) are the two kinds.
    """

    meta: ModelMeta
    name: str

    def logits(self, depth: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class Prediction:
    """One frame's result. ``mask``: 0 background, 1 object, 255 unknown (invalid pixel).

    ``prob`` (float32 H x W object probability) is computed when first read: the mask comes from
    the logits, and a robot that only reads the mask should not pay the sigmoid (80 us a frame
    here, in the whole-frame latency).
    """

    mask: np.ndarray  # uint8 H x W
    valid: np.ndarray  # bool H x W
    timings: dict[str, float]  # ms: pre, infer, post, total
    logits: np.ndarray  # float32 H x W; the mask is `edge.metrics.segmentation_mask` of these
    graph_prob: np.ndarray | None = field(default=None, repr=False)  # a --with-preprocessing graph's own output
    height_m: np.ndarray | None = field(default=None, repr=False)  # metres above the support, when the height rule is on

    @cached_property
    def prob(self) -> np.ndarray:
        return self.graph_prob if self.graph_prob is not None else sigmoid(self.logits)


def session_options(threads: int = 2, spin: bool = False, optimized_model_path: str | None = None):
    """onnxruntime options for one edge session (see the module docstring for why)."""
    import onnxruntime as ort

    if int(threads) < 1:
        raise ConfigError(f"threads must be >= 1, got {threads}")
    so = ort.SessionOptions()
    so.intra_op_num_threads = int(threads)
    so.inter_op_num_threads = 1
    so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    # Spinning keeps worker threads busy-waiting between kernels. On a CPU shared with other
    # work (the robot's other nodes; here, training) it cost 3-4x in whole-frame latency
    # (2.8 ms vs 10.3 ms p50, vgg11_bn w0.125, 2 threads), so it is off unless asked for.
    so.add_session_config_entry("session.intra_op.allow_spinning", "1" if spin else "0")
    so.log_severity_level = 3  # errors only: library code does not print
    if optimized_model_path:
        so.optimized_model_filepath = str(optimized_model_path)
    return so


def check_logits(logits: np.ndarray, name: str) -> np.ndarray:
    """``logits`` if every value is finite; else a `ModelError` naming the model.

    Why: NaN compares false with every threshold, so a broken model (NaN weights, an overflow
    in the graph) would otherwise score as "no objects" and publish empty masks with exit 0.
    Cost: one vectorised pass, ~6 us for a 224 x 171 frame (a float64 sum, finite exactly when
    every value is, took 20 us on a 2-core AMD EPYC).
    """
    a = np.asarray(logits)
    if not np.isfinite(a).all():
        nan = int(np.isnan(a).sum())
        inf = int(np.isinf(a).sum())
        raise ModelError(
            f"{name}: the model produced non-finite logits ({nan} NaN, {inf} infinite of {a.size} values); "
            "the model file is broken (retrain or re-export it)"
        )
    return a


def checked_logits(predictor: Predictor, depth: np.ndarray) -> np.ndarray:
    """``predictor.logits(depth)`` with the checks every consumer of an arbitrary predictor needs.

    eval and tune accept any `Predictor` (ONNX, checkpoint, a user's own): its logits must have the
    frame's shape and be finite (`check_logits`), else a `ModelError` naming the predictor.

    Args:
        predictor: anything with ``logits(depth)`` and, ideally, a ``name``.
        depth: one H x W depth frame.
    """
    name = str(getattr(predictor, "name", "model"))
    logits = np.asarray(predictor.logits(depth))
    if logits.shape != np.shape(depth):
        raise ModelError(f"{name}: returned logits of shape {logits.shape} for a {np.shape(depth)} frame")
    return check_logits(logits, name)



def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text[:200] + ("..." if len(text) > 200 else "")


class Segmenter:
    """Object/table segmentation of raw depth frames with an exported ONNX model.

    ``threshold``, ``min_object_px`` and ``min_height_m`` override the ones stored in the model
    (for experiments, or to choose what "object" means near the table: ``min_object_px`` 0 keeps
    every object pixel, ``min_height_m`` 0.01 makes object pixels under 10 mm above the support
    table, `edge.postprocess`); ``spin`` lets
    onnxruntime's worker threads busy-wait between kernels: it can shave a little latency on
    cores nobody else uses, and costs a lot on shared ones (see `session_options`).
    """

    def __init__(
        self,
        model_path: str | Path | None = None,
        threads: int = 2,
        threshold: float | None = None,
        providers: Sequence[str] = ("CPUExecutionProvider",),
        spin: bool = False,
        min_object_px: int | None = None,
        min_height_m: float | None = None,
    ) -> None:
        import onnxruntime as ort

        path = resolve_model(model_path, kinds=("onnx",))
        check_input_file(path, "model")  # a FIFO would block onnxruntime's read forever
        try:
            self.session = ort.InferenceSession(
                str(path), sess_options=session_options(threads, spin), providers=list(providers)
            )
        except Exception as exc:  # noqa: BLE001 - onnxruntime raises many types for one cause: a bad file
            raise ModelError(
                f"{path}: not a readable ONNX model ({type(exc).__name__}: {_one_line(exc)}); re-export it with depthseg-export"
            ) from None
        self.path = path
        self.name = str(path)
        self.threads = int(threads)
        self.props: dict[str, str] = dict(self.session.get_modelmeta().custom_metadata_map)
        try:
            self.meta = ModelMeta.from_onnx_props(self.props)
        except ModelError as exc:
            raise ModelError(f"{path}: {exc}") from None
        self.threshold = self.meta.threshold if threshold is None else float(threshold)
        if not 0.0 < self.threshold < 1.0:
            raise ConfigError(f"threshold must lie in (0, 1), got {self.threshold}")
        self.min_object_px = check_min_px(self.meta.min_object_px if min_object_px is None else min_object_px)
        self.min_height_m = check_min_height(self.meta.min_height_m if min_height_m is None else min_height_m)
        inputs, outputs = self.session.get_inputs(), self.session.get_outputs()
        if len(inputs) != 1:
            raise ModelError(f"{path}: expected one input '{INPUT_NAME}', found {[i.name for i in inputs]}")
        self.input_name = inputs[0].name
        names = [o.name for o in outputs]
        self.with_preprocessing = OUTPUT_PROB in names or self.props.get("graph") == "with-preprocessing"
        self._out_main = OUTPUT_PROB if OUTPUT_PROB in names else names[0]
        self._out_names = [self._out_main] + [n for n in (OUTPUT_VALID, OUTPUT_HEIGHT) if n in names]
        shape = inputs[0].shape
        if self.with_preprocessing:
            if len(shape) != 3:
                raise ModelError(f"{path}: a with-preprocessing model (raw depth in) takes [N, H, W], input is {shape}")
            self._frame_shape = tuple(d if isinstance(d, int) else None for d in shape[1:])
        else:
            if len(shape) != 4:
                raise ModelError(f"{path}: expected input [N, C, H, W], found {shape}")
            if isinstance(shape[1], int) and shape[1] != self.meta.net_channels:
                raise ModelError(
                    f"{path}: input has {shape[1]} channels but its metadata says {self.meta.net_channels}; re-export it"
                )
            self._frame_shape = (None, None)
        self.precision = self.props.get("precision", "fp32")

    def __repr__(self) -> str:
        m = self.meta
        kind = "with-preprocessing" if self.with_preprocessing else "logits"
        return (
            f"Segmenter({str(self.path)!r}, {m.encoder} width {m.width:g}, {m.in_channels}ch, {self.precision}, "
            f"{kind}, threshold {self.threshold:g}, "
            + (f"{describe_height_rule(self.min_height_m)}, " if self.min_height_m else "")
            + f"threads {self.threads})"
        )

    # -- internals -------------------------------------------------------------------------
    def _check_frame(self, depth: np.ndarray) -> np.ndarray:
        d = np.asarray(depth)
        if d.ndim == 3 and d.shape[0] == 1:
            d = d[0]
        if d.ndim != 2:
            raise DataError(f"a depth frame must be 2-D (H x W), got shape {tuple(d.shape)}")
        fh, fw = self._frame_shape
        if (fh is not None and d.shape[0] != fh) or (fw is not None and d.shape[1] != fw):
            raise DataError(
                f"frame is {d.shape[0]}x{d.shape[1]} but {self.path.name} was exported for {fh}x{fw}; "
                "export a plain (logits) model for other sizes"
            )
        return d

    def _run_raw(self, frames: np.ndarray) -> list[np.ndarray]:
        """frames float32 [N, H, W] through a --with-preprocessing model -> [prob, (valid)]."""
        return self.session.run(self._out_names, {self.input_name: frames})

    # -- public API ------------------------------------------------------------------------
    def logits(self, depth: np.ndarray) -> np.ndarray:
        """Float32 H x W logits of one frame (for a probability model: the logit of its output)."""
        d = self._check_frame(depth)
        h, w = d.shape
        if self.with_preprocessing:
            p = self._run_raw(np.ascontiguousarray(d, dtype=np.float32)[None])[0][0]
            return logit(check_logits(np.asarray(p, dtype=np.float32), self.name))
        pre = preprocess_for(d, self.meta)
        out = self.session.run([self._out_main], {self.input_name: pre.x[None]})[0]
        return check_logits(np.ascontiguousarray(out[0, 0, :h, :w]), self.name)

    def logits_batch(self, frames: Sequence[np.ndarray]) -> np.ndarray:
        """Float32 [N, H, W] logits of frames of one size, in one session run."""
        if len(frames) == 0:
            raise DataError("logits_batch needs at least one frame")
        ds = [self._check_frame(f) for f in frames]
        h, w = ds[0].shape
        if self.with_preprocessing:
            x = np.stack([np.asarray(d, dtype=np.float32) for d in ds])
            return logit(check_logits(np.asarray(self._run_raw(x)[0], dtype=np.float32), self.name))
        x, _valid = preprocess_batch_for(ds, self.meta)
        out = self.session.run([self._out_main], {self.input_name: x})[0]
        return check_logits(np.ascontiguousarray(out[:, 0, :h, :w]), self.name)

    def predict(self, depth: np.ndarray, threshold: float | None = None) -> Prediction:
        """Raw depth (metres; 0/NaN/negative/inf invalid) in, probability and mask out.

        Args:
            depth: one H x W frame, metres.
            threshold: decision boundary for this call (default: the segmenter's).

        Returns:
            A `Prediction`; ``mask`` is 0 background, 1 object, `UNKNOWN` invalid.
        """
        t0 = time.perf_counter()
        d = self._check_frame(depth)
        h, w = d.shape
        if self.with_preprocessing:
            x = np.ascontiguousarray(d, dtype=np.float32)[None]
            t1 = time.perf_counter()
            outs = self._run_raw(x)
            t2 = time.perf_counter()
            graph_prob = check_logits(outs[0][0], self.name)
            logits = logit(np.asarray(graph_prob, dtype=np.float32))
            got = dict(zip(self._out_names, outs))
            valid = got[OUTPUT_VALID][0].astype(bool, copy=False) if OUTPUT_VALID in got else valid_for(d, self.meta)
            height = None
            if self.min_height_m > 0:
                # the graph's own height output is the plane its network saw (no second fit);
                # graphs without it (no height cue, older exports) get the numpy fit
                height = self._graph_height(got[OUTPUT_HEIGHT][0], d.shape) if OUTPUT_HEIGHT in got else support_height(d, valid)
        else:
            pre = preprocess_for(d, self.meta)
            valid = pre.valid
            t1 = time.perf_counter()
            out = self.session.run([self._out_main], {self.input_name: pre.x[None]})[0]
            t2 = time.perf_counter()
            logits = check_logits(out[0, 0, :h, :w], self.name)
            graph_prob = None
            height = self._height(d, pre) if self.min_height_m > 0 else None
        # The one threshold rule (edge.metrics): logits against logit(threshold), as eval, tune and
        # replay decide (float32 probabilities cannot separate thresholds near 1, 0.9999); then specks.
        mask = segmentation_mask(
            logits, valid, self.threshold if threshold is None else float(threshold), self.min_object_px,
            height, self.min_height_m,
        )
        t3 = time.perf_counter()
        timings = {
            "pre": (t1 - t0) * 1e3,
            "infer": (t2 - t1) * 1e3,
            "post": (t3 - t2) * 1e3,
            "total": (t3 - t0) * 1e3,
        }
        return Prediction(mask=mask, valid=valid, timings=timings, logits=logits, graph_prob=graph_prob, height_m=height)

    @property
    def has_height_output(self) -> bool:
        """True for a --with-preprocessing graph that returns the height its network saw (``height``)."""
        return OUTPUT_HEIGHT in self._out_names

    def graph_height(self, depth: np.ndarray) -> np.ndarray | None:
        """Metres above the support from the graph's ``height`` output for one frame; None without that output.

        For checks that compare the graph's heights with the numpy fit or with another file
        (`export.preproc_graph.check_against_python`, `export.quantize.iou_report`).
        """
        if not self.has_height_output:
            return None
        d = self._check_frame(depth)
        (h,) = self.session.run([OUTPUT_HEIGHT], {self.input_name: np.ascontiguousarray(d, dtype=np.float32)[None]})
        return self._graph_height(h[0], d.shape)

    def _graph_height(self, height: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
        """A graph's ``height`` output, if it is a finite float map of the frame's shape (else `ModelError`)."""
        h = np.asarray(height)
        if h.shape != tuple(shape) or h.dtype.kind != "f" or not np.isfinite(h).all():
            raise ModelError(
                f"{self.name}: its '{OUTPUT_HEIGHT}' output is not a finite float map of the frame's size "
                f"(shape {h.shape}, dtype {h.dtype}); the model file is broken (re-export it)"
            )
        return h

    def _height(self, depth: np.ndarray, pre) -> np.ndarray:
        """Metres above the support for the height rule: the model's own height cue when it has
        one (the same plane, no second fit), else `edge.postprocess.support_height`."""
        if "height" in self.meta.cues:
            h, w = depth.shape
            return pre.x[self.meta.in_channels + self.meta.cues.index("height"), :h, :w] / np.float32(HEIGHT_SCALE)
        return support_height(depth, pre.valid)
