#!/usr/bin/env python
"""Would rewriting the decoder's ConvTranspose layers make the edge model faster? (It did not.)

ORT's profile puts the five ConvTranspose layers (3 x 3, stride 2, padding 1, output padding 1)
at ~24 % of the shipped model's inference. Each is exactly a 2 x 2 convolution computing the
four output phases as channels (zero taps where a phase has none), then DepthToSpace (CRD). This
script writes that graph, checks it gives the same logits, and times both interleaved, in turns
of 10 runs, on one random input. Kept as the record of a negative result (BENCHMARKS.md, v10).

    .venv/bin/python tools/ablation/deconv_rewrite.py [MODEL.onnx] [--blocks 60]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import onnx
from onnx import helper, numpy_helper

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from edge.infer import session_options  # noqa: E402

# (output phase, input offset) -> kernel index, for stride 2, kernel 3, padding 1
TAPS = {(0, 0): 1, (1, 0): 2, (1, 1): 0}


def _attrs(node) -> dict:
    return {a.name: helper.get_attribute_value(a) for a in node.attribute}


def _rewritable(node, inits) -> bool:
    a = _attrs(node)
    return (node.op_type == "ConvTranspose" and a.get("strides") == [2, 2] and a.get("kernel_shape") == [3, 3]
            and a.get("pads") == [1, 1, 1, 1] and a.get("output_padding") == [1, 1] and a.get("group", 1) == 1
            and a.get("dilations", [1, 1]) == [1, 1] and node.input[1] in inits)


def rewrite(model: onnx.ModelProto) -> int:
    """Replace every rewritable ConvTranspose in place; returns how many were replaced."""
    inits = {i.name: i for i in model.graph.initializer}
    nodes, done = [], 0
    for n in model.graph.node:
        if not _rewritable(n, inits):
            nodes.append(n)
            continue
        w = numpy_helper.to_array(inits[n.input[1]])  # [Cin, Cout, 3, 3]
        cin, cout = w.shape[:2]
        k = np.zeros((cout, 2, 2, cin, 2, 2), w.dtype)  # out channel, phase y, phase x, in channel, dy, dx
        for (ry, dy), ky in TAPS.items():
            for (rx, dx), kx in TAPS.items():
                k[:, ry, rx, :, dy, dx] = w[:, :, ky, kx].T
        wname = n.name + "_phases_w"
        model.graph.initializer.append(numpy_helper.from_array(k.reshape(cout * 4, cin, 2, 2), wname))
        ins = [n.input[0], wname]
        if len(n.input) > 2 and n.input[2]:
            b = numpy_helper.to_array(inits[n.input[2]])
            model.graph.initializer.append(numpy_helper.from_array(np.repeat(b, 4), n.name + "_phases_b"))
            ins.append(n.name + "_phases_b")
        mid = n.name + "_phases"
        nodes.append(helper.make_node("Conv", ins, [mid], name=mid, kernel_shape=[2, 2], pads=[0, 0, 1, 1]))
        nodes.append(helper.make_node("DepthToSpace", [mid], list(n.output), name=n.name + "_d2s", blocksize=2,
                                      mode="CRD"))
        done += 1
    del model.graph.node[:]
    model.graph.node.extend(nodes)
    used = {i for n in model.graph.node for i in n.input}
    keep = [i for i in model.graph.initializer if i.name in used]
    del model.graph.initializer[:]
    model.graph.initializer.extend(keep)
    return done


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", nargs="?", default=str(ROOT / "edge/models/default.onnx"))
    ap.add_argument("--blocks", type=int, default=60, help="turns of 10 runs per model (default 60)")
    args = ap.parse_args()
    import onnxruntime as ort

    m = onnx.load(args.model)
    n = rewrite(m)
    onnx.checker.check_model(m)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "rewritten.onnx"
        onnx.save(m, path)
        sess = [ort.InferenceSession(p, sess_options=session_options(2), providers=["CPUExecutionProvider"])
                for p in (args.model, str(path))]
    name = sess[0].get_inputs()[0].name
    c = sess[0].get_inputs()[0].shape[1]
    x = np.random.default_rng(0).standard_normal((1, c, 192, 224)).astype(np.float32)
    ya, yb = (s.run(None, {name: x})[0] for s in sess)
    print(f"{n} ConvTranspose layers rewritten; max |logit diff| {np.abs(ya - yb).max():.2e} "
          f"(logits up to {np.abs(ya).max():.1f})")
    times: list[list[float]] = [[], []]
    for blk in range(args.blocks):
        for k in (blk % 2, 1 - blk % 2):
            for _ in range(10):
                t0 = time.perf_counter()
                sess[k].run(None, {name: x})
                times[k].append((time.perf_counter() - t0) * 1e3)
    a, b = (float(np.median(t)) for t in times)
    print(f"inference p50 at 2 threads: original {a:.2f} ms, rewritten {b:.2f} ms, ratio {b / a:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
