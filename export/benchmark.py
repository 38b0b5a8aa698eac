"""The benchmark as one library call: shipped or given ONNX models, plus random-init architectures.

`depthseg-bench` parses its flags into `benchmark`'s arguments and prints the result. It lives
in `export` because ``compare`` exports architectures (torch, in-process) before timing them;
without ``compare`` and ``torch`` it runs on the torch-free edge path (`edge.bench`).
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from edge.errors import ConfigError

__all__ = ["benchmark", "parse_compare"]


def parse_compare(item: str) -> tuple[str, float]:
    """``"vgg16"`` -> ("vgg16", 1.0); ``"vgg11_bn:0.125"`` -> ("vgg11_bn", 0.125).

    Raises:
        ConfigError: the width is not a number.
    """
    enc, _, w = item.partition(":")
    try:
        return enc, float(w) if w else 1.0
    except ValueError:
        raise ConfigError(f"`compare` {item}: width must be a number, e.g. vgg16:0.5") from None


def benchmark(
    models: Sequence[str | Path] | None = None,
    *,
    compare: Sequence[str] = (),
    threads: int | Sequence[int] = 2,
    runs: int = 200,
    warmup: int = 20,
    data: str | Path | None = None,
    frames: int = 8,
    seed: int = 0,
    spin: bool = False,
    torch: bool = False,
    on_round: Callable[[int], None] | None = None,
    block: int | None = None,
    rate: float | None = None,
    min_height_m: float | None = None,
) -> dict[str, Any]:
    """Time models round-robin on this CPU (`edge.bench.bench_models`); the ``depthseg-bench --json`` object.

    Args:
        models: ONNX files; None = the shipped default.
        compare: architectures ``ENCODER[:WIDTH]`` exported in-process with random weights and timed too.
        threads: onnxruntime intra-op threads, or several counts: every model is then timed at
            each (named ``"<model> t<N>"``), interleaved in the one run.
        runs: timed runs per model.
        warmup: untimed runs per model first.
        data: simulated MCAP file or directory to take frames from (None: synthetic frames).
        frames: distinct frames, cycled through the runs.
        seed: seed of the synthetic frames.
        spin: let onnxruntime's threads busy-wait between kernels.
        torch: also time PyTorch eager for each model's architecture (imports torch).
        on_round: called with the run index after each run of every model (progress).
        block: consecutive timed runs of one model before the next takes its turn (None:
            `edge.bench.DEFAULT_BLOCK`; see `edge.bench.bench_models`).
        rate: pace the timed frames at this many frames/s, as the sensor delivers them (None
            or 0: back to back).
        min_height_m: the height rule for every model of this run (None: each model's own;
            `edge.postprocess.remove_low_parts`).

    Returns:
        ``cpu``, ``runtime``, ``threads``, ``runs``, ``warmup``, ``rate_hz``, ``frames`` (their source), ``peak_rss_mb``,
        ``models`` (one dict per model: latencies, frames/s, size, ratio to the first...).

    Raises:
        ConfigError: threads or frames below 1, a rate below 0, or a bad ``compare`` item.
        ModelError: a model file is missing or unreadable.
    """
    from edge.bench import (
        ModelSpec,
        bench_models,
        check_block,
        check_rate,
        cpu_info,
        peak_rss_mb,
        runtime_info,
    )
    from edge.cliutil import require
    from edge.defaults import resolve_model
    from edge.io.paths import check_input_file
    from edge.sampleframes import sample_frames

    counts = [int(threads)] if isinstance(threads, int) else [int(t) for t in threads]
    if not counts or min(counts) < 1 or len(set(counts)) != len(counts):
        raise ConfigError(f"`threads` must be distinct counts >= 1, got {threads}")
    if frames < 1:
        raise ConfigError(f"`frames` must be >= 1, got {frames}")
    block = check_block(block)  # before the exports of `compare`, which take seconds
    rate = check_rate(rate)
    archs = [parse_compare(c) for c in compare]
    for m in models or ():
        check_input_file(m, "model")  # a FIFO would block onnxruntime's read forever
    if data is not None:
        check_input_file(data, "data", allow_dir=True)
    if archs:
        require("train", ("torch", "onnx", "onnxscript"), "`compare` (exports the architecture in-process)")
    if torch:
        require("train", ("torch",), "`torch` (PyTorch eager timing)")
    paths = list(models or [resolve_model(None, kinds=("onnx",))])
    sample = sample_frames(data, frames, seed)
    with tempfile.TemporaryDirectory(prefix="depthseg-bench-") as td:
        named = [(Path(p), Path(p).stem) for p in paths]
        for enc, width in archs:
            from export.api import export_random  # torch: only when comparing, before any timing

            out = export_random(enc, Path(td) / f"compare-{enc}-w{width:g}.onnx", width=width, threads=counts[0])
            named.append((out, f"{enc} w{width:g} (random, paper-style 3ch)"))
        suffix = (lambda t: f" t{t}") if len(counts) > 1 else (lambda t: "")
        specs = [ModelSpec(p, name=name + suffix(t), threads=t) for p, name in named for t in counts]
        results = bench_models(specs, sample.depth, runs=runs, warmup=warmup, spin=spin, on_round=on_round,
                               block=block, rate=rate, min_height_m=min_height_m)
        if torch:
            from edge.infer import Segmenter
            from edge.train.timing import time_torch

            segs = [Segmenter(spec.path, threads=spec.threads) for spec in specs]
            for m, t in zip(results, time_torch(segs, sample.depth, runs=min(runs, 50), warmup=max(3, min(warmup, 10)))):
                m.update(t)
    return {
        "cpu": cpu_info(),
        "runtime": runtime_info(),
        "threads": counts[0] if len(counts) == 1 else counts,
        "inter_op_threads": 1,
        "spin": bool(spin),
        "runs": runs,
        "warmup": warmup,
        "block": block,
        "rate_hz": rate,
        "min_height_m": min_height_m,  # None: each model's own height rule
        "frames": sample.source,
        "peak_rss_mb": peak_rss_mb(),
        "models": results,
    }
