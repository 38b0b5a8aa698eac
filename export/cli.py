"""``depthseg-export``: a checkpoint (or a random-init architecture) -> one checked ONNX file."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from edge.cliutil import add_min_height_arg, add_version, print_json, run

PROG = "depthseg-export"

DESCRIPTION = """\
Export a depthseg model to ONNX for the edge (onnxruntime, no torch), and prove the file
computes what PyTorch computes.

The file is self-contained (weights inside, no .onnx.data), opset 18, input `depth`
[N, C, H, W] (dynamic N, H, W), output `logits` [N, 1, H, W], and carries the model metadata
(sensor intrinsics, preprocessing, threshold, input size, encoder, width, parameter count,
training recipe) in metadata_props. After writing, the file is run through the edge inference
path and PyTorch on the same frames (simulated frames from --data, else seeded synthetic frames
with dead pixels); the export fails when the logits differ by more than 1e-3 x max(1, max|logit|)
or more than 0.1 % of valid pixels change class.
"""

EPILOG = """\
examples:
  depthseg-export --single-channel --out edge/models/default.onnx
  depthseg-export --single-channel --int8 --data out/sim --out model-int8.onnx
  depthseg-export --single-channel --with-preprocessing --out model-edge.onnx
  depthseg-export --encoder vgg16 --width 1 --random-init --out paper-vgg16.onnx   # speed comparisons only
"""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG, description=DESCRIPTION, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_version(p, PROG)
    p.add_argument("--model", type=Path, default=None, help="checkpoint (.pt) to export (default: the shipped edge/models/default.pt)")
    p.add_argument("--single-channel", action="store_true",
                   help="sum the first conv's kernels over its input channels: same output for the paper's replicated input, one channel in")
    p.add_argument("--out", type=Path, default=None,
                   help="output .onnx (default: <name>-<C>ch[-pre][-int8].onnx in the current directory)")
    p.add_argument("--int8", action="store_true",
                   help="static int8 quantisation (QDQ, per-channel, calibrated on frames); refused when IoU drops > 0.5 points")
    p.add_argument("--with-preprocessing", action="store_true",
                   help="self-contained graph: raw depth [N,171,224] metres in, object probability [N,171,224] (+ valid mask) out")
    p.add_argument("--encoder", default=None, help="with --random-init: encoder name, e.g. vgg16 (the paper) or vgg11_bn")
    p.add_argument("--width", type=float, default=None, help="with --random-init: channel width multiplier (1.0 = the paper)")
    p.add_argument("--random-init", action="store_true", help="untrained weights: for speed comparisons only (the metadata says so)")
    p.add_argument("--seed", type=int, default=0, help="seed of --random-init weights and of synthetic check frames (default 0)")
    p.add_argument("--data", type=Path, default=None,
                   help="simulated MCAP file or directory (depthseg-sim output) for the checks, calibration and int8 validation")
    p.add_argument("--calib", type=Path, default=None, help="separate MCAP frames for int8 calibration (default: the first frames of --data)")
    p.add_argument("--check-frames", type=int, default=8, help="frames for the numerical check (default 8)")
    p.add_argument("--calib-frames", type=int, default=32, help="frames for int8 calibration (default 32)")
    p.add_argument("--val-frames", type=int, default=32, help="labelled frames for the int8 IoU check (default 32)")
    p.add_argument("--threads", type=int, default=2, help="onnxruntime threads for the checks (default 2)")
    p.add_argument("--min-object-px", type=int, default=None, metavar="PX",
                   help="store this speck rule in the exported model: object components under PX pixels become "
                        "background (default: the checkpoint's, 6 px unless it says otherwise; 0 = off)")
    add_min_height_arg(p, store=True)
    p.add_argument("--force", action="store_true", help="keep an int8 model even when it loses more than 0.5 IoU points")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    return p


def _print_text(rep: dict[str, Any]) -> None:
    m = rep["meta"]
    enc = m["encoder"] + ("_bn" if m["batch_norm"] else "")
    print(
        f"wrote {rep['out']} ({rep['size_bytes'] / 1e6:.2f} MB, {rep['precision']}, {rep['graph']}, opset {rep['opset']}, "
        f"{enc} width {m['width']:g}, {m['in_channels']} channel(s), {m['params']:,} params, "
        f"inputs {rep['inputs']}, outputs {rep['outputs']})"
    )
    print(rep["check"]["summary"])
    if rep["int8"]:
        print(rep["int8"]["summary"] + (" [kept: --force]" if rep["int8"]["forced"] else ""))
        print(rep["int8"]["layers_summary"])


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)

    def body() -> int:
        from export.api import ExportOptions, export_model

        opts = vars(args).copy()
        opts.pop("json")
        rep = export_model(ExportOptions(**opts))
        if args.json:
            print_json(rep)
        else:
            _print_text(rep)
        return 0

    return run(PROG, body, parser)


if __name__ == "__main__":
    raise SystemExit(main())
