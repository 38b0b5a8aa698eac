"""The hand-built ONNX models with depthseg metadata (Segmenter, bench, eval, tune and replay tests).

Built with onnx.helper (no torch), so these tests run on the edge path alone and fast; the
real exported FCN-8s is covered in tests/export.
- `linear_model`: logits = -K * standardised depth + B (nearer than the frame mean = object),
  the same [N, C, H, W] -> [N, 1, H, W] contract as an exported model.
- `raw_model`: the --with-preprocessing contract: raw depth [N, H, W] -> probability, valid
  (and optionally a ``height`` output, well-formed or broken).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from edge.meta import ModelMeta

TORCH_BLOCKER = """
import sys
class _NoTorch:
    def find_spec(self, name, path=None, target=None):
        if name == "torch" or name.startswith("torch."):
            raise ImportError("torch is blocked: the edge path must not import it")
        return None
sys.meta_path.insert(0, _NoTorch())
"""


def _save(graph, meta: ModelMeta, path: Path, extra: dict[str, str] | None = None) -> Path:
    import onnx
    from onnx import helper

    m = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    m.ir_version = 9
    for k, v in {**meta.onnx_props(), **(extra or {})}.items():
        e = m.metadata_props.add()
        e.key, e.value = k, v
    onnx.checker.check_model(m)
    onnx.save(m, str(path))
    return path


def linear_model(path: Path, channels: int = 1, threshold: float = 0.5, k: float = 4.0,
                 meta_channels: int | None = None, with_meta: bool = True, bias: float = 0.0) -> Path:
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    meta = ModelMeta(encoder="vgg11", width=0.125, batch_norm=True, in_channels=meta_channels or channels,
                     threshold=threshold, training={"weights": "hand-built linear test model"})
    w = numpy_helper.from_array(np.full((1, channels, 1, 1), -k / channels, np.float32), "W")
    b = numpy_helper.from_array(np.array([bias], np.float32), "B")
    g = helper.make_graph(
        [helper.make_node("Conv", ["depth", "W", "B"], ["logits"])], "linear",
        [helper.make_tensor_value_info("depth", TensorProto.FLOAT, ["N", channels, "H", "W"])],
        [helper.make_tensor_value_info("logits", TensorProto.FLOAT, ["N", 1, "H", "W"])], [w, b],
    )
    if not with_meta:
        m = helper.make_model(g, opset_imports=[helper.make_opsetid("", 17)])
        m.ir_version = 9
        onnx.save(m, str(path))
        return path
    return _save(g, meta, path)


def raw_model(path: Path, cut: float = 0.3, height: int = 171, width: int = 224, height_output: str | None = None) -> Path:
    """probability = sigmoid(40 * (cut - depth)) on valid pixels; valid = finite and > 0.

    ``height_output``: None (no ``height`` output, like a model without the height cue),
    ``"cut"`` (metres above a flat support at ``cut``: cut - depth, 0 at invalid pixels),
    ``"nan"`` (NaN everywhere: a broken graph) or ``"row"`` (one row per frame: the wrong shape).
    """
    from onnx import TensorProto, helper, numpy_helper

    meta = ModelMeta(encoder="vgg11", width=0.125, batch_norm=True, in_channels=1)
    consts = [
        numpy_helper.from_array(np.array(0.0, np.float32), "zero"),
        numpy_helper.from_array(np.array(cut, np.float32), "cut"),
        numpy_helper.from_array(np.array(40.0, np.float32), "gain"),
    ]
    nodes = [
        helper.make_node("IsNaN", ["depth"], ["nan"]),
        helper.make_node("IsInf", ["depth"], ["inf"]),
        helper.make_node("Or", ["nan", "inf"], ["bad"]),
        helper.make_node("Not", ["bad"], ["finite"]),
        helper.make_node("Greater", ["depth", "zero"], ["pos"]),
        helper.make_node("And", ["finite", "pos"], ["valid"]),
        helper.make_node("Where", ["valid", "depth", "cut"], ["d"]),
        helper.make_node("Sub", ["cut", "d"], ["diff"]),
        helper.make_node("Mul", ["diff", "gain"], ["z"]),
        helper.make_node("Sigmoid", ["z"], ["probability"]),
    ]
    outputs = [helper.make_tensor_value_info("probability", TensorProto.FLOAT, ["N", height, width]),
               helper.make_tensor_value_info("valid", TensorProto.BOOL, ["N", height, width])]
    if height_output is not None:
        nodes += {
            "cut": [helper.make_node("Identity", ["diff"], ["height"])],
            "nan": [helper.make_node("Div", ["zero", "zero"], ["nan0"]), helper.make_node("Add", ["diff", "nan0"], ["height"])],
            "row": [helper.make_node("ReduceMax", ["diff"], ["height"], axes=[1], keepdims=1)],
        }[height_output]
        outputs.append(helper.make_tensor_value_info("height", TensorProto.FLOAT, ["N", "HH", "WW"]))
    g = helper.make_graph(nodes, "raw", [helper.make_tensor_value_info("depth", TensorProto.FLOAT, ["N", height, width])],
                          outputs, consts)
    return _save(g, meta, path, {"graph": "with-preprocessing"})
