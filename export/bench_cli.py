"""``depthseg-bench``: edge latency of exported models (onnxruntime, no torch); parses flags, calls `export.benchmark.benchmark`."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from edge.cliutil import add_min_height_arg, add_version, print_json, progress, run
from edge.postprocess import describe_height_rule

PROG = "depthseg-bench"

DESCRIPTION = """\
Measure what the robot waits for: raw depth frame in, object mask out, on this CPU with
onnxruntime at a fixed number of threads (intra-op --threads, inter-op 1, sequential).

Per model: session load, first run, then over the timed runs the inference latency
(p50/p90/p99/mean/min/max ms), the whole-frame latency (preprocessing + inference +
postprocessing, raw depth -> mask) and frames/s (1000 / mean whole-frame ms), each stage timed
separately, model size, precision, and memory. Several models are timed round-robin in one
run, in turns of --block consecutive frames, so machine noise hits all alike while each model
keeps warm caches as it would running alone; the table gives each model's ratio to the first.
Frames: the first --frames frames of --data (simulated MCAP), else seeded synthetic frames
(table, objects, dead corners, dead and NaN pixels).
"""

EPILOG = """\
examples:
  depthseg-bench --threads 2                                   # the shipped default model
  depthseg-bench --threads 2 --compare vgg16                   # ... against the paper's VGG16 FCN-8s
  depthseg-bench --model a.onnx b.onnx --runs 500 --json
  depthseg-bench --model a.onnx --torch                        # also PyTorch eager (imports torch; <= 50 runs)
  depthseg-bench --threads 1 2                                 # the default model at 1 and at 2 threads, interleaved
  depthseg-bench --rate 45                                     # frames paced as the sensor delivers them at 45 Hz
"""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG, description=DESCRIPTION, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_version(p, PROG)
    p.add_argument("--model", type=Path, nargs="+", default=None,
                   help="ONNX model(s) from depthseg-export (default: the shipped edge/models/default.onnx)")
    p.add_argument("--threads", type=int, nargs="+", default=[2],
                   help="onnxruntime intra-op threads (default 2); several counts time every model at each, "
                        "interleaved (e.g. --threads 1 2)")
    p.add_argument("--compare", action="append", default=[], metavar="ENCODER[:WIDTH]",
                   help="also time this architecture with random weights, 3 channels, fp32 (e.g. vgg16 = the paper's "
                        "FCN-8s; width 1 unless given); exported in-process to a temp file; repeatable")
    p.add_argument("--runs", type=int, default=200, help="timed runs per model (default 200)")
    p.add_argument("--warmup", type=int, default=20, help="untimed runs per model first (default 20)")
    p.add_argument("--data", type=Path, default=None, help="simulated MCAP file or directory to take frames from")
    p.add_argument("--block", type=int, default=None,
                   help="consecutive timed runs of one model before the next takes its turn (default 10: each model "
                        "times with warm caches, as it runs alone on the robot; 1: models alternate every frame)")
    p.add_argument("--rate", type=float, default=0.0, metavar="HZ",
                   help="start the timed frames 1/HZ s apart, as the sensor delivers them (e.g. 45, the pico flexx's "
                        "top rate; default 0: back to back, the best case: idle cores between frames are slower)")
    p.add_argument("--frames", type=int, default=8, help="distinct frames, cycled through the runs (default 8)")
    p.add_argument("--seed", type=int, default=0, help="seed of the synthetic frames (default 0)")
    p.add_argument("--spin", action="store_true",
                   help="let onnxruntime's worker threads busy-wait between kernels (off by default: on a CPU shared with "
                        "other work it made frames 3-4x slower here)")
    add_min_height_arg(p)
    p.add_argument("--torch", action="store_true", help="also time PyTorch eager for each model's architecture (imports torch)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    return p


def _fmt_table(res: dict[str, Any]) -> str:
    cols = [
        ("model", lambda m: m["name"], "<"),
        ("prec", lambda m: m["precision"], "<"),
        ("ch", lambda m: str(m["in_channels"]), ">"),
        ("thr", lambda m: str(m["threads"]), ">"),
        ("MB", lambda m: f"{m['size_mb']:.2f}", ">"),
        ("load", lambda m: f"{m['load_ms']:.0f}", ">"),
        ("first", lambda m: f"{m['first_run_ms']:.1f}", ">"),
        ("inf p50", lambda m: f"{m['p50_ms']:.2f}", ">"),
        ("p90", lambda m: f"{m['p90_ms']:.2f}", ">"),
        ("p99", lambda m: f"{m['p99_ms']:.2f}", ">"),
        ("mean", lambda m: f"{m['mean_ms']:.2f}", ">"),
        ("min", lambda m: f"{m['min_ms']:.2f}", ">"),
        ("max", lambda m: f"{m['max_ms']:.2f}", ">"),
        ("pre", lambda m: f"{m['timings']['pre']['p50']:.2f}", ">"),
        ("post", lambda m: f"{m['timings']['post']['p50']:.2f}", ">"),
        ("frame p50", lambda m: f"{m['whole_frame_p50_ms']:.2f}", ">"),
        ("p90", lambda m: f"{m['whole_frame_p90_ms']:.2f}", ">"),
        ("p99", lambda m: f"{m['whole_frame_p99_ms']:.2f}", ">"),
        ("fps", lambda m: f"{m['fps']:.0f}", ">"),
        ("x first", lambda m: f"{m['ratio_to_first']:.2f}", ">"),
    ]
    if any("torch_whole_frame_p50_ms" in m for m in res["models"]):
        cols.append(("torch frame p50", lambda m: f"{m.get('torch_whole_frame_p50_ms', float('nan')):.2f}", ">"))
    rows = [[c[0] for c in cols]] + [[c[1](m) for c in cols] for m in res["models"]]
    widths = [max(len(r[i]) for r in rows) for i in range(len(cols))]
    lines = []
    for j, r in enumerate(rows):
        lines.append("  ".join(f"{v:{cols[i][2]}{widths[i]}}" for i, v in enumerate(r)))
        if j == 0:
            lines.append("  ".join("-" * w for w in widths))
    return "\n".join(lines)


def format_report(res: dict[str, Any]) -> str:
    cpu = res["cpu"]
    head = [
        f"onnxruntime {res['runtime']['onnxruntime']}, intra-op threads {res['threads']}, inter-op 1, sequential, "
        f"thread spinning {'on' if res['spin'] else 'off'}",
        f"CPU: {cpu['model']} ({cpu['usable_cpus']} usable of {cpu['logical_cpus']} logical CPUs); ISA: {' '.join(cpu['isa'])}",
        f"frames: {res['frames']}; {res['runs']} timed runs per model after {res['warmup']} warm-up, round-robin"
        + (f" in blocks of {res['block']} runs" if res.get("block", 1) > 1 else " (models alternate every frame)")
        + (f", paced at {res['rate_hz']:g} frames/s" if res.get("rate_hz") else ", back to back")
        + (f"; every model's {describe_height_rule(res['min_height_m'])}" if res.get("min_height_m") else ""),
        "times in ms; 'inf' = session.run only; 'frame' = raw depth -> mask (pre + inf + post); fps = 1000 / mean frame ms; "
        "'x first' = frame p50 / the first model's",
    ]
    tail = [f"peak RSS of this process {res['peak_rss_mb']:.0f} MB"]
    if any(m["precision"] == "int8" for m in res["models"]) and "avx512_vnni" in cpu["isa"]:
        tail.append("note: this CPU has AVX-512 VNNI; int8 gains here exceed those on a typical AVX2 edge CPU")
    if any(m["weights"] == "random-init" for m in res["models"]):
        tail.append("note: random-init models are untrained: their latency is real, their masks are not")
    return "\n".join(head + ["", _fmt_table(res), ""] + tail)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)

    def body() -> int:
        from export.benchmark import benchmark

        bar = progress(total=args.runs, desc="bench")
        try:
            res = benchmark(args.model, compare=args.compare, threads=args.threads if len(args.threads) > 1 else args.threads[0], runs=args.runs,
                            warmup=args.warmup, data=args.data, frames=args.frames, seed=args.seed, spin=args.spin,
                            torch=args.torch, block=args.block, rate=args.rate,
                            min_height_m=args.min_height_m, on_round=lambda _r: bar.update(1))
        finally:
            bar.close()
        if args.json:
            print_json(res)
        else:
            print(format_report(res))
        return 0

    return run(PROG, body, parser)


if __name__ == "__main__":
    raise SystemExit(main())
