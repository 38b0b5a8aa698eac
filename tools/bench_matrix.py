#!/usr/bin/env python
"""One benchmark run for BENCHMARKS.md: architectures x channels x precision x threads.

Rows: the paper's VGG16 FCN-8s (random init, width 1), VGG11 FCN-8s (random init, width 1) and
the shipped default (edge/models/default.pt; or a random-init stand-in while it does not
exist), each three-channel and single-channel, fp32 and int8; columns: 1 and 2 onnxruntime
threads. All models are exported first (``depthseg-export`` in subprocesses, so no torch in this
process), then timed together in ONE interleaved round-robin run (`edge.bench.bench_models`),
so machine noise hits every cell alike and the speed-ups within the table are comparable.

    .venv/bin/python tools/bench_matrix.py --json-out bench_matrix.json > table.md

Markdown goes to stdout, the full results (every percentile, export reports) to --json-out.
Random-init int8 models are kept with --force: their IoU is meaningless, their speed is not.
"""

from __future__ import annotations

import argparse
import json
import platform
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from edge.cliutil import progress, run  # noqa: E402
from edge.errors import ConfigError, ModelError  # noqa: E402

PROG = "bench_matrix"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--default", type=Path, default=None, help="trained checkpoint for the 'shipped default' rows "
                   "(default: edge/models/default.pt)")
    p.add_argument("--standin", default=None, metavar="ENC:WIDTH",
                   help="when the default checkpoint is missing, time this random-init architecture in its place "
                        "(e.g. vgg11_bn:0.25); the table says so")
    p.add_argument("--also", action="append", default=[], metavar="ENC:WIDTH", help="extra random-init architecture rows")
    p.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="onnxruntime thread counts (default 1 2)")
    p.add_argument("--runs", type=int, default=100, help="timed runs per model (default 100)")
    p.add_argument("--warmup", type=int, default=10, help="warm-up runs per model (default 10)")
    p.add_argument("--data", type=Path, default=None, help="simulated MCAP for frames, calibration and int8 validation")
    p.add_argument("--keep", type=Path, default=None, help="keep the exported models in this directory")
    p.add_argument("--reuse", action="store_true", help="with --keep: reuse models already exported there by an earlier run")
    p.add_argument("--json-out", type=Path, default=Path("bench_matrix.json"), help="full results (default bench_matrix.json)")
    return p


def _arch(spec: str) -> tuple[str, float]:
    enc, _, w = spec.partition(":")
    try:
        return enc, float(w) if w else 1.0
    except ValueError:
        raise ConfigError(f"{spec}: expected ENCODER:WIDTH, e.g. vgg11_bn:0.25") from None


def _export(out: Path, src: list[str], channels: int, int8: bool, random_init: bool, data: Path | None) -> dict[str, Any]:
    cmd = [sys.executable, "-m", "export.cli", *src, "--out", str(out), "--json", "--check-frames", "4"]
    if channels == 1:
        cmd.append("--single-channel")
    if data is not None:
        cmd += ["--data", str(data)]
    if int8:
        cmd.append("--int8")
        if random_init:
            cmd += ["--force", "--calib-frames", "16", "--val-frames", "8"]
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    if proc.returncode != 0:
        tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        return {"ok": False, "error": tail, "command": shlex.join(cmd[1:])}
    return {"ok": True, "report": json.loads(proc.stdout), "command": shlex.join(cmd[1:])}


def plan(args: argparse.Namespace) -> list[dict[str, Any]]:
    from edge.defaults import DEFAULT_CHECKPOINT

    archs: list[dict[str, Any]] = [
        {"key": "paper", "label": "paper VGG16 FCN-8s (random init, width 1)", "src": ["--random-init", "--encoder", "vgg16",
                                                                                      "--width", "1"], "random": True},
        {"key": "vgg11", "label": "VGG11 FCN-8s (random init, width 1)", "src": ["--random-init", "--encoder", "vgg11",
                                                                                "--width", "1"], "random": True},
    ]
    ckpt = args.default or DEFAULT_CHECKPOINT
    if ckpt.exists():
        archs.append({"key": "default", "label": f"shipped default ({ckpt.name})", "src": ["--model", str(ckpt)], "random": False})
    elif args.standin:
        enc, w = _arch(args.standin)
        archs.append({"key": "default", "label": f"stand-in for the default: {enc} w{w:g} (random init; {ckpt.name} missing)",
                      "src": ["--random-init", "--encoder", enc, "--width", repr(w)], "random": True})
    else:
        raise ModelError(f"{ckpt}: no such checkpoint; train it, or pass --standin ENC:WIDTH to time an untrained stand-in")
    for i, spec in enumerate(args.also):
        enc, w = _arch(spec)
        archs.append({"key": f"also{i}", "label": f"{enc} w{w:g} (random init)",
                      "src": ["--random-init", "--encoder", enc, "--width", repr(w)], "random": True})
    return archs


def _md(res: dict[str, Any], args: argparse.Namespace) -> str:
    cpu = res["cpu"]
    threads = args.threads
    by = {(m["arch"], m["in_channels"], m["precision"], m["threads"]): m for m in res["models"]}
    lines = [
        f"CPU: {cpu['model']} ({cpu['usable_cpus']} usable CPUs), ISA: {' '.join(cpu['isa'])}; onnxruntime "
        f"{res['runtime']['onnxruntime']}, inter-op 1, sequential, thread spinning off; Python {platform.python_version()}.",
        f"Frames: {res['frames']}. {res['runs']} timed runs per cell after {res['warmup']} warm-up, all "
        f"{len(res['models'])} cells interleaved round-robin in one run.",
        "",
        "Whole frame = raw depth in, mask out (preprocessing + inference + postprocessing), p50 ms; "
        "(inference only in brackets); speed-up = the paper's 3-channel fp32 whole-frame p50 at the same thread count / this one.",
        "",
    ]
    head = ["model", "ch", "prec", "params", "MB"]
    for t in threads:
        head += [f"{t} thr frame p50 (inf)", f"{t} thr p99", f"{t} thr speed-up"]
    lines.append("| " + " | ".join(head) + " |")
    lines.append("|" + "|".join(["---"] * len(head)) + "|")
    for arch in res["archs"]:
        for ch in (3, 1):
            for prec in ("fp32", "int8"):
                cells = [by.get((arch["key"], ch, prec, t)) for t in threads]
                first = next((c for c in cells if c), None)
                if first is None:
                    err = res["export_errors"].get(f"{arch['key']}-{ch}ch-{prec}", "not exported")
                    lines.append(f"| {arch['label']} | {ch} | {prec} | - | - | " + " | ".join(["-"] * 3 * len(threads))
                                 + f" |  <!-- {err} -->")
                    continue
                row = [arch["label"], str(ch), prec, f"{first['params']:,}", f"{first['size_mb']:.2f}"]
                for t, c in zip(threads, cells):
                    base = by.get(("paper", 3, "fp32", t))
                    if c is None:
                        row += ["-", "-", "-"]
                        continue
                    sp = base["whole_frame_p50_ms"] / c["whole_frame_p50_ms"] if base else float("nan")
                    row += [f"{c['whole_frame_p50_ms']:.2f} ({c['p50_ms']:.2f})", f"{c['whole_frame_p99_ms']:.2f}", f"{sp:.1f}x"]
                lines.append("| " + " | ".join(row) + " |")
    int8 = [m for m in res["models"] if m["precision"] == "int8"]
    if int8 and "avx512_vnni" in cpu["isa"]:
        lines += ["", "int8: this CPU has AVX-512 VNNI, so int8 gains here are larger than on a typical AVX2 edge CPU. "
                  "onnxruntime's CPU provider runs ConvTranspose in fp32, so the decoder's five deconvolutions are not int8."]
    lines += ["", f"Produced by: `.venv/bin/python tools/bench_matrix.py {shlex.join(sys.argv[1:])}`"]
    return "\n".join(lines)


def matrix(args: argparse.Namespace) -> dict[str, Any]:
    from edge.bench import ModelSpec, bench_models, cpu_info, peak_rss_mb, runtime_info
    from edge.sampleframes import sample_frames

    if any(t < 1 for t in args.threads) or args.runs < 1:
        raise ConfigError("--threads values and --runs must be >= 1")
    archs = plan(args)
    frames = sample_frames(args.data, 8, 0)
    with tempfile.TemporaryDirectory(prefix="depthseg-matrix-") as td:
        outdir = (args.keep or Path(td)).resolve()
        outdir.mkdir(parents=True, exist_ok=True)
        data = args.data.resolve() if args.data is not None else None
        exports, errors, specs = {}, {}, []
        jobs = [(a, ch, prec) for a in archs for ch in (3, 1) for prec in ("fp32", "int8")]
        for a, ch, prec in progress(jobs, desc="export"):
            name = f"{a['key']}-{ch}ch-{prec}"
            out = outdir / f"{name}.onnx"
            if args.reuse and out.exists() and (outdir / f"{name}.json").exists():
                r = json.loads((outdir / f"{name}.json").read_text())
            else:
                r = _export(out, a["src"], ch, prec == "int8", a["random"], data)
                if args.keep:
                    (outdir / f"{name}.json").write_text(json.dumps(r))
            exports[name] = r
            if not r["ok"]:
                errors[name] = r["error"]
                continue
            for t in args.threads:
                specs.append(ModelSpec(out, name=f"{name}-{t}t", threads=t, extra={"arch": a["key"], "label": a["label"]}))
        bar = progress(total=args.runs, desc="bench")
        try:
            models = bench_models(specs, frames.depth, runs=args.runs, warmup=args.warmup, on_round=lambda _r: bar.update(1))
        finally:
            bar.close()
    return {
        "cpu": cpu_info(),
        "runtime": runtime_info(),
        "threads": args.threads,
        "runs": args.runs,
        "warmup": args.warmup,
        "frames": frames.source,
        "archs": [{k: a[k] for k in ("key", "label", "src", "random")} for a in archs],
        "exports": exports,
        "export_errors": errors,
        "peak_rss_mb": peak_rss_mb(),
        "command": shlex.join([sys.argv[0], *sys.argv[1:]]),
        "models": models,
    }


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)

    def body() -> int:
        from edge.io import write_bytes_atomic

        res = matrix(args)
        write_bytes_atomic(args.json_out, json.dumps(res, indent=1, sort_keys=True, default=str).encode())
        print(_md(res, args))
        return 0

    return run(PROG, body)


if __name__ == "__main__":
    raise SystemExit(main())
