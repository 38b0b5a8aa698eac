"""Latency of exported models the way an edge engineer measures it.

Why it is built like this:
- The unit is the *whole frame*: raw depth in, mask out (`Segmenter.predict`), because that is
  what the robot waits for; preprocessing, inference and postprocessing are timed inside the
  same calls and reported separately, so a slow stage is visible.
- Several models are timed round-robin (the starting model rotates every round): a noisy
  neighbour (this machine shares its 2 cores with training) then hits every model alike, and
  the ratios between models stay meaningful even when absolute numbers wobble. A turn is
  ``DEFAULT_BLOCK`` consecutive frames, not one: on the robot a model runs alone with warm
  caches, and alternating every frame with the paper's VGG16 (135 ms a frame) made the small
  model's frames 1.26x slower (4.29 vs 3.41 ms p50, one run each, BENCHMARKS.md), which measures
  the benchmark, not the model. Drift on the scale of seconds still hits all models alike.
- Back-to-back frames are the best case. A sensor delivers a frame every 1/rate s and the CPU
  idles in between; on the 2-vCPU Xeon of 2026-12-02 the shipped model's inference took
  3.7-3.8 ms paced at 45 Hz against 2.8 ms back to back (cold caches, sleeping cores:
  BENCHMARKS.md). ``rate`` paces the timed frames like the sensor: the number the robot sees.
- Session load and the first run are reported on their own (the first run allocates and
  plans); percentiles come from the timed runs after warm-up only.
- The CPU model, its ISA flags, the onnxruntime version and the thread settings are recorded
  with the numbers: int8 and fp32 speed depend on them (AVX-512 VNNI makes int8 shine).

Torch-free (numpy + onnxruntime + psutil); PyTorch eager timing is `edge.train.timing.time_torch`.
"""

from __future__ import annotations

import gc
import os
import platform
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from edge.errors import ConfigError
from edge.infer import Segmenter

__all__ = [
    "DEFAULT_BLOCK",
    "check_block",
    "check_rate",
    "ModelSpec",
    "cpu_info",
    "runtime_info",
    "stats",
    "bench_models",
    "ISA_FLAGS",
]

DEFAULT_BLOCK = 10  # consecutive timed frames of one model per turn (module docstring)


def check_rate(rate: float | None) -> float | None:
    """The pacing to use: None (back to back) for None or 0, else ``rate`` frames/s if > 0."""
    if rate is None or float(rate) == 0.0:
        return None
    if not float(rate) > 0.0 or not np.isfinite(float(rate)):
        raise ConfigError(f"`rate` must be a frame rate > 0 (frames/s, e.g. 45), or 0 for back-to-back; got {rate}")
    return float(rate)


def check_block(block: int | None) -> int:
    """The turn length to use: ``DEFAULT_BLOCK`` for None, else ``block`` if >= 1 (one check for
    `bench_models` and `export.benchmark.benchmark`, which asks before its slow exports)."""
    block = DEFAULT_BLOCK if block is None else int(block)
    if block < 1:
        raise ConfigError(f"`block` must be >= 1, got {block}")
    return block


ISA_FLAGS = (
    "sse4_2", "avx", "avx2", "fma", "f16c", "avx512f", "avx512bw", "avx512vl", "avx512_vnni", "avx_vnni",
    "avx512_bf16", "avx512_fp16", "amx_tile", "amx_int8", "amx_bf16", "asimd", "asimddp", "sve",
)


@dataclass
class ModelSpec:
    """One model to time: file, display name, intra-op threads."""

    path: Path
    name: str = ""
    threads: int = 2
    extra: dict[str, Any] = field(default_factory=dict)  # copied into the result (e.g. variant labels)

    def __post_init__(self) -> None:
        self.path = Path(self.path)
        if not self.name:
            self.name = self.path.stem


def cpu_info() -> dict[str, Any]:
    """CPU model and the ISA flags that matter for onnxruntime kernels (Linux /proc/cpuinfo)."""
    model, flags = platform.processor() or platform.machine(), set()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                key, _, val = line.partition(":")
                key = key.strip()
                if key in ("model name", "Hardware", "CPU part") and model in ("", platform.machine(), platform.processor()):
                    model = val.strip()
                elif key in ("flags", "Features") and not flags:
                    flags = set(val.split())
    except OSError:
        pass
    try:
        affinity = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        affinity = os.cpu_count() or 0
    return {
        "model": model,
        "isa": [f for f in ISA_FLAGS if f in flags],
        "logical_cpus": os.cpu_count(),
        "usable_cpus": affinity,
        "machine": platform.machine(),
    }


def runtime_info() -> dict[str, Any]:
    import onnxruntime as ort

    return {
        "onnxruntime": ort.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
        "providers": ["CPUExecutionProvider"],
    }


def stats(ms: Sequence[float]) -> dict[str, float]:
    a = np.asarray(ms, dtype=np.float64)
    p50, p90, p99 = np.percentile(a, [50, 90, 99])
    return {
        "p50": float(p50),
        "p90": float(p90),
        "p99": float(p99),
        "mean": float(a.mean()),
        "min": float(a.min()),
        "max": float(a.max()),
    }


def _rss_mb() -> float:
    import psutil

    return psutil.Process().memory_info().rss / 2**20


def peak_rss_mb() -> float:
    """Peak resident memory of this process so far (VmHWM; ru_maxrss where /proc is missing)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _sleep_until(t: float) -> None:
    """Sleep until ``time.perf_counter()`` reaches ``t`` (no-op when it has)."""
    dt = t - time.perf_counter()
    if dt > 0:
        time.sleep(dt)


def bench_models(
    specs: Sequence[ModelSpec],
    frames: Sequence[np.ndarray],
    runs: int = 200,
    warmup: int = 20,
    spin: bool = False,
    on_round: Callable[[int], None] | None = None,
    block: int = DEFAULT_BLOCK,
    rate: float | None = None,
    min_height_m: float | None = None,
) -> list[dict[str, Any]]:
    """Time every model on ``frames`` (cycled), interleaved round-robin; one result dict per model.

    Args:
        specs: the models and their threads.
        frames: depth frames, cycled through the runs.
        runs: timed runs per model.
        warmup: untimed runs per model first.
        spin: let onnxruntime's threads busy-wait between kernels.
        on_round: called with the run index after each run of every model (progress).
        block: consecutive timed runs of one model before the next takes its turn (1: models
            alternate every frame; see the module docstring for why the default is larger).
        rate: start the timed frames 1/rate s apart, as a sensor delivers them (None: back to
            back); a frame that takes longer than 1/rate starts the next one at once.
        min_height_m: every model's height rule for this run (None: each model's own;
            `edge.postprocess.remove_low_parts`), so its cost shows in the 'post' column.
    """
    if not specs:
        raise ConfigError("no model to benchmark")
    if runs < 1 or warmup < 0:
        raise ConfigError(f"need runs >= 1 and warmup >= 0, got runs={runs}, warmup={warmup}")
    block = check_block(block)
    period = 0.0 if check_rate(rate) is None else 1.0 / float(rate)
    if not frames:
        raise ConfigError("no frame to benchmark on")
    entries = []
    for spec in specs:
        gc.collect()
        rss0 = _rss_mb()
        t0 = time.perf_counter()
        seg = Segmenter(spec.path, threads=spec.threads, spin=spin, min_height_m=min_height_m)
        t1 = time.perf_counter()
        seg.predict(frames[0])
        t2 = time.perf_counter()
        entries.append(
            {
                "spec": spec,
                "seg": seg,
                "load_ms": (t1 - t0) * 1e3,
                "first_run_ms": (t2 - t1) * 1e3,
                "rss_delta_mb": _rss_mb() - rss0,
                "t": {"whole": [], "pre": [], "infer": [], "post": []},
            }
        )
    n = len(entries)
    for r in range(warmup):
        for e in entries:
            e["seg"].predict(frames[r % len(frames)])
    gc.collect()
    next_start = time.perf_counter()
    for start in range(0, runs, block):
        stop = min(start + block, runs)
        for k in range(n):
            e = entries[(start // block + k) % n]  # the order rotates, so no model always follows another
            t = e["t"]
            for r in range(start, stop):
                if period:
                    _sleep_until(next_start)
                t0 = time.perf_counter()
                next_start = t0 + period
                pred = e["seg"].predict(frames[r % len(frames)])
                t1 = time.perf_counter()
                t["whole"].append((t1 - t0) * 1e3)
                t["pre"].append(pred.timings["pre"])
                t["infer"].append(pred.timings["infer"])
                t["post"].append(pred.timings["post"])
        if on_round is not None:
            for r in range(start, stop):
                on_round(r)
    results = []
    for e in entries:
        seg: Segmenter = e["seg"]
        spec: ModelSpec = e["spec"]
        st = {k: stats(v) for k, v in e["t"].items()}
        m = seg.meta
        results.append(
            {
                "name": spec.name,
                "path": str(spec.path),
                "threads": spec.threads,
                "precision": seg.precision,
                "graph": "with-preprocessing" if seg.with_preprocessing else "logits",
                "encoder": m.encoder + ("_bn" if m.batch_norm and not m.encoder.endswith("_bn") else ""),
                "width": m.width,
                "in_channels": m.in_channels,
                "params": m.params,
                "weights": m.training.get("weights", "trained") if isinstance(m.training, dict) else "trained",
                "size_mb": spec.path.stat().st_size / 1e6,
                "load_ms": e["load_ms"],
                "first_run_ms": e["first_run_ms"],
                "rss_delta_mb": e["rss_delta_mb"],
                "runs": runs,
                "rate_hz": rate if period else None,
                "p50_ms": st["infer"]["p50"],
                "p90_ms": st["infer"]["p90"],
                "p99_ms": st["infer"]["p99"],
                "mean_ms": st["infer"]["mean"],
                "min_ms": st["infer"]["min"],
                "max_ms": st["infer"]["max"],
                "whole_frame_p50_ms": st["whole"]["p50"],
                "whole_frame_p90_ms": st["whole"]["p90"],
                "whole_frame_p99_ms": st["whole"]["p99"],
                "fps": 1000.0 / st["whole"]["mean"],
                "infer_fps": 1000.0 / st["infer"]["mean"],
                "timings": st,
            }
            | spec.extra
        )
    base = results[0]
    for res in results:
        res["ratio_to_first"] = res["whole_frame_p50_ms"] / base["whole_frame_p50_ms"]
        res["infer_ratio_to_first"] = res["p50_ms"] / base["p50_ms"]
    return results
