"""Export as a library: one typed call from a checkpoint (or a random-init architecture) to a checked ONNX file.

`depthseg-export` parses its flags into `ExportOptions` and calls `export_model`;
`depthseg-bench --compare` calls `export_random` in-process.
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from edge.cliutil import require
from edge.errors import ConfigError, ModelError

__all__ = ["ExportOptions", "export_model", "export_random", "load_source", "default_out", "check_paths"]


@dataclass(frozen=True)
class ExportOptions:
    """What `export_model` does; every field is the `depthseg-export` flag of the same name."""

    model: Path | None = None  # checkpoint; None = the shipped default
    out: Path | None = None  # None = <name>-<C>ch[-pre][-int8].onnx in the current directory
    single_channel: bool = False
    int8: bool = False
    with_preprocessing: bool = False
    encoder: str | None = None  # random_init only
    width: float | None = None  # random_init only
    random_init: bool = False
    seed: int = 0
    data: Path | None = None
    calib: Path | None = None
    check_frames: int = 8
    calib_frames: int = 32
    val_frames: int = 32
    threads: int = 2
    force: bool = False
    min_object_px: int | None = None  # None = the checkpoint's speck rule (ModelMeta.min_object_px)
    min_height_m: float | None = None  # None = the checkpoint's height rule (ModelMeta.min_height_m; 0 = off)


def _split_encoder(name: str) -> tuple[str, bool]:
    return (name[:-3], True) if name.endswith("_bn") else (name, False)


def load_source(opts: ExportOptions):
    """(model, meta, short name) from a checkpoint or a random-init architecture.

    Raises:
        ConfigError: options that contradict each other.
        ModelError: the checkpoint is missing or unreadable.
    """
    import torch

    from edge.meta import ModelMeta
    from edge.train.model import build_model, count_parameters

    if opts.random_init:
        if opts.model is not None:
            raise ConfigError("`random_init` builds a new untrained model; drop `model` (or drop `random_init`)")
        enc, bn = _split_encoder(opts.encoder or "vgg16")
        width = 1.0 if opts.width is None else float(opts.width)
        meta = ModelMeta(
            encoder=enc,
            width=width,
            batch_norm=bn,
            in_channels=3,
            training={"weights": "random-init", "seed": opts.seed, "note": "untrained; for speed comparisons only"},
        )
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(opts.seed)
            model = build_model(meta).eval()
        meta = meta.with_(params=count_parameters(model))
        return model, meta, f"{enc}{'_bn' if bn else ''}-w{width:g}-random"
    if opts.encoder is not None or opts.width is not None:
        raise ConfigError("`encoder`/`width` describe a new architecture and need `random_init`; a checkpoint carries its own")
    from edge import defaults
    from edge.train.checkpoint import load_checkpoint

    path = opts.model or defaults.DEFAULT_CHECKPOINT
    if not Path(path).exists():
        hint = "train one with depthseg-train" if opts.model else "pass `model` CKPT, or `random_init` for a speed test"
        raise ModelError(f"{path}: no such checkpoint; {hint}")
    model, meta, _blob = load_checkpoint(path)
    return model, meta.with_(params=count_parameters(model)), Path(path).stem


def check_paths(opts: ExportOptions) -> None:
    """Inputs readable regular files (no FIFO: it would hang), ``out`` never an input (`edge.io.paths`)."""
    from edge import defaults
    from edge.io.paths import check_input_file, check_outputs

    model = None
    if not opts.random_init:
        model = opts.model if opts.model is not None else defaults.DEFAULT_CHECKPOINT
        if opts.model is not None and Path(opts.model).exists():  # missing: `load_source` says how to get one
            check_input_file(opts.model, "model")
    for name in ("data", "calib"):
        if getattr(opts, name) is not None:
            check_input_file(getattr(opts, name), name, allow_dir=True)
    check_outputs({"out": opts.out}, {"model": model, "data": opts.data, "calib": opts.calib})


def default_out(name: str, channels: int, opts: ExportOptions) -> Path:
    return Path(f"{name}-{channels}ch{'-pre' if opts.with_preprocessing else ''}{'-int8' if opts.int8 else ''}.onnx")


def export_model(opts: ExportOptions) -> dict[str, Any]:
    """Export, check (and optionally quantise) one model; the file appears only when every check passed.

    Args:
        opts: what to export and how (`ExportOptions`).

    Returns:
        The report ``depthseg-export --json`` prints: ``out``, ``meta``, ``check``, ``int8``,
        ``size_bytes``, ``precision``, ``graph``, ``opset``, ``inputs``, ``outputs``.

    Raises:
        ConfigError: contradictory or out-of-range options.
        ModelError: missing checkpoint, failed numerical check, or an int8 model that loses too much IoU.
    """
    for name in ("check_frames", "calib_frames", "val_frames", "threads"):
        if getattr(opts, name) < 1:
            raise ConfigError(f"`{name}` must be >= 1, got {getattr(opts, name)}")
    check_paths(opts)
    require("train", ("torch", "onnx", "onnxscript"), "export")
    import torch

    from edge.io.paths import check_outputs
    from edge.sampleframes import sample_frames
    from export.onnx_export import check_against_torch, export_onnx
    from export.preproc_graph import check_against_python, export_with_preprocessing
    from export.single_channel import to_single_channel

    torch.set_num_threads(opts.threads)  # the reference forward passes: never more threads than asked
    model, meta, name = load_source(opts)
    if opts.min_object_px is not None:
        meta = meta.with_(min_object_px=opts.min_object_px)  # checked like any metadata (ModelError)
    if opts.min_height_m is not None:
        meta = meta.with_(min_height_m=opts.min_height_m)
    source_channels = meta.in_channels
    if opts.single_channel:
        model, meta = to_single_channel(model, meta)
    out = opts.out or default_out(name, meta.in_channels, opts)
    if opts.out is None:  # the default name: checked now it is known
        check_outputs({"out": out}, {"model": opts.model, "data": opts.data, "calib": opts.calib})
    if out.exists() and out.is_dir():
        raise ConfigError(f"`out` {out} is a directory; give a file name ending in .onnx")
    out.parent.mkdir(parents=True, exist_ok=True)
    check_frames = sample_frames(opts.data, opts.check_frames, opts.seed)
    extra = {"exported_from": name, "single_channel": f"{opts.single_channel} (source had {source_channels} channels)"}
    report: dict[str, Any] = {"out": str(out), "meta": meta.to_dict()}
    with tempfile.TemporaryDirectory(dir=out.parent, prefix=".depthseg-export-") as td:
        fp32 = Path(td) / "fp32.onnx"
        if opts.with_preprocessing:
            export_with_preprocessing(model, meta, fp32, extra)
            check = check_against_python(fp32, model, meta, check_frames.depth, check_frames.source, opts.threads)
        else:
            export_onnx(model, meta, fp32, extra_props=extra)
            check = check_against_torch(fp32, model, meta, check_frames.depth, check_frames.source, opts.threads)
        report["check"] = check.to_dict() | {"summary": check.summary()}
        final = fp32
        report["int8"] = None
        if opts.int8:
            final = _int8(opts, fp32, Path(td) / "int8.onnx", report)
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


def _int8(opts: ExportOptions, fp32: Path, q: Path, report: dict[str, Any]) -> Path:
    import onnx

    from edge.sampleframes import sample_frames
    from export.onnx_export import set_metadata, write_onnx
    from export.quantize import iou_report, quantize_int8, refuse_message

    if opts.calib is not None:
        calib = sample_frames(opts.calib, opts.calib_frames, opts.seed)
        val = sample_frames(opts.data, opts.val_frames, opts.seed, skip=0 if opts.data is not None else 10_000)
    else:
        calib = sample_frames(opts.data, opts.calib_frames, opts.seed)
        val = sample_frames(opts.data, opts.val_frames, opts.seed, skip=opts.calib_frames)
    quantize_int8(fp32, q, calib)
    rep = iou_report(fp32, q, val, threads=opts.threads)
    report["int8"] = rep.to_dict() | {"summary": rep.summary(), "layers_summary": rep.layers_summary(), "forced": False}
    if not rep.ok:
        if not opts.force:
            raise ModelError(refuse_message(rep))
        report["int8"]["forced"] = True
    proto = onnx.load(str(q), load_external_data=False)
    check = {k: v for k, v in rep.to_dict().items() if k != "layers"} | {"forced": report["int8"]["forced"]}
    set_metadata(proto, {"int8_check": json.dumps(check, sort_keys=True), "int8_layers": json.dumps(rep.layers, sort_keys=True)})
    write_onnx(proto, q)
    return q


def export_random(
    encoder: str, out: Path, width: float = 1.0, single_channel: bool = False, int8: bool = False, threads: int = 2
) -> Path:
    """An untrained architecture exported and checked like any model (for speed comparisons only).

    Args:
        encoder: registry name, e.g. ``vgg16`` or ``vgg11_bn``.
        out: the .onnx file to write.
        width: channel width multiplier.
        single_channel: sum the first conv over its input channels.
        int8: also quantise (kept even when the random weights lose IoU: only speed matters here).
        threads: threads for the checks.

    Returns:
        ``out``.
    """
    opts = ExportOptions(random_init=True, encoder=encoder, width=float(width), out=Path(out), check_frames=2,
                         threads=threads, single_channel=single_channel, int8=int8, force=int8,
                         calib_frames=8, val_frames=4)
    return Path(export_model(opts)["out"])
