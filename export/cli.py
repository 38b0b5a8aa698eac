"""``depthseg-export``: a checkpoint (or a random-init architecture) -> one checked ONNX file."""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path
from typing import Any

from edge.cliutil import print_json, run
from edge.errors import ConfigError, ModelError

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
    p.add_argument("--force", action="store_true", help="keep an int8 model even when it loses more than 0.5 IoU points")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    return p


def _split_encoder(name: str) -> tuple[str, bool]:
    return (name[:-3], True) if name.endswith("_bn") else (name, False)


def load_source(args: argparse.Namespace):
    """(model, meta, short name) from a checkpoint or a random-init architecture."""
    import torch

    from edge.meta import ModelMeta
    from edge.model import build_model, count_parameters

    if args.random_init:
        if args.model is not None:
            raise ConfigError("--random-init builds a new untrained model; drop --model (or drop --random-init)")
        enc, bn = _split_encoder(args.encoder or "vgg16")
        width = 1.0 if args.width is None else float(args.width)
        meta = ModelMeta(
            encoder=enc,
            width=width,
            batch_norm=bn,
            in_channels=3,
            training={"weights": "random-init", "seed": args.seed, "note": "untrained; for speed comparisons only"},
        )
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(args.seed)
            model = build_model(meta).eval()
        meta = meta.with_(params=count_parameters(model))
        return model, meta, f"{enc}{'_bn' if bn else ''}-w{width:g}-random"
    if args.encoder is not None or args.width is not None:
        raise ConfigError("--encoder/--width describe a new architecture and need --random-init; a checkpoint carries its own")
    from edge.checkpoint import load_checkpoint
    from edge.defaults import DEFAULT_CHECKPOINT

    path = args.model or DEFAULT_CHECKPOINT
    if not Path(path).exists():
        hint = "train one with depthseg-train" if args.model else "pass --model CKPT, or --random-init for a speed test"
        raise ModelError(f"{path}: no such checkpoint; {hint}")
    model, meta, _blob = load_checkpoint(path)
    return model, meta.with_(params=count_parameters(model)), Path(path).stem


def default_out(name: str, channels: int, args: argparse.Namespace) -> Path:
    return Path(f"{name}-{channels}ch{'-pre' if args.with_preprocessing else ''}{'-int8' if args.int8 else ''}.onnx")


def export_model(args: argparse.Namespace) -> dict[str, Any]:
    """Run the whole export; returns the report (what the CLI prints)."""
    from edge.sampleframes import sample_frames
    from export.onnx_export import check_against_torch, export_onnx
    from export.preproc_graph import check_against_python, export_with_preprocessing
    from export.single_channel import to_single_channel

    for flag in ("check_frames", "calib_frames", "val_frames", "threads"):
        if getattr(args, flag) < 1:
            raise ConfigError(f"--{flag.replace('_', '-')} must be >= 1, got {getattr(args, flag)}")
    import torch

    torch.set_num_threads(args.threads)  # the reference forward passes: never more threads than asked
    model, meta, name = load_source(args)
    source_channels = meta.in_channels
    if args.single_channel:
        model, meta = to_single_channel(model, meta)
    out = args.out or default_out(name, meta.in_channels, args)
    if out.exists() and out.is_dir():
        raise ConfigError(f"--out {out} is a directory; give a file name ending in .onnx")
    out.parent.mkdir(parents=True, exist_ok=True)
    check_frames = sample_frames(args.data, args.check_frames, args.seed)
    extra = {"exported_from": name, "single_channel": f"{args.single_channel} (source had {source_channels} channels)"}
    report: dict[str, Any] = {"out": str(out), "meta": meta.to_dict()}
    with tempfile.TemporaryDirectory(dir=out.parent, prefix=".depthseg-export-") as td:
        fp32 = Path(td) / "fp32.onnx"
        if args.with_preprocessing:
            export_with_preprocessing(model, meta, fp32, extra)
            check = check_against_python(fp32, model, meta, check_frames.depth, check_frames.source, args.threads)
        else:
            export_onnx(model, meta, fp32, extra_props=extra)
            check = check_against_torch(fp32, model, meta, check_frames.depth, check_frames.source, args.threads)
        report["check"] = check.to_dict() | {"summary": check.summary()}
        final = fp32
        report["int8"] = None
        if args.int8:
            final = _int8(args, fp32, Path(td) / "int8.onnx", report)
        os.replace(final, out)
    import onnx

    proto = onnx.load(str(out), load_external_data=False)
    props = {p.key: p.value for p in proto.metadata_props}
    report.update(
        {
            "size_bytes": out.stat().st_size,
            "precision": props.get("precision", "fp32"),
            "graph": props.get("graph", "logits"),
            "opset": max(o.version for o in proto.opset_import if o.domain in ("", "ai.onnx")),
            "inputs": [i.name for i in proto.graph.input],
            "outputs": [o.name for o in proto.graph.output],
        }
    )
    return report


def _int8(args: argparse.Namespace, fp32: Path, q: Path, report: dict[str, Any]) -> Path:
    import onnx

    from edge.sampleframes import sample_frames
    from export.onnx_export import set_metadata, write_onnx
    from export.quantize import iou_report, quantize_int8, refuse_message

    if args.calib is not None:
        calib = sample_frames(args.calib, args.calib_frames, args.seed)
        val = sample_frames(args.data, args.val_frames, args.seed, skip=0 if args.data is not None else 10_000)
    else:
        calib = sample_frames(args.data, args.calib_frames, args.seed)
        val = sample_frames(args.data, args.val_frames, args.seed, skip=args.calib_frames)
    quantize_int8(fp32, q, calib)
    rep = iou_report(fp32, q, val, threads=args.threads)
    report["int8"] = rep.to_dict() | {"summary": rep.summary(), "layers_summary": rep.layers_summary(), "forced": False}
    if not rep.ok:
        if not args.force:
            raise ModelError(refuse_message(rep))
        report["int8"]["forced"] = True
    proto = onnx.load(str(q), load_external_data=False)
    check = {k: v for k, v in rep.to_dict().items() if k != "layers"} | {"forced": report["int8"]["forced"]}
    set_metadata(proto, {"int8_check": json.dumps(check, sort_keys=True), "int8_layers": json.dumps(rep.layers, sort_keys=True)})
    write_onnx(proto, q)
    return q


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
    args = build_parser().parse_args(argv)

    def body() -> int:
        rep = export_model(args)
        if args.json:
            print_json(rep)
        else:
            _print_text(rep)
        return 0

    return run(PROG, body)


if __name__ == "__main__":
    raise SystemExit(main())
