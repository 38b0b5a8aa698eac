"""PyTorch eager timing beside the ONNX numbers of `edge.bench` (``depthseg-bench --torch``)."""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from edge.bench import stats
from edge.infer import Segmenter

__all__ = ["time_torch"]


def time_torch(segs: Sequence[Segmenter], frames: Sequence[np.ndarray], runs: int, warmup: int) -> list[dict[str, Any]]:
    """PyTorch eager for each model's architecture, interleaved round-robin like `bench_models`.

    Same architecture, random weights (latency does not depend on them); no BatchNorm folding,
    as eager PyTorch runs it. OpenMP workers wait passively (``OMP_WAIT_POLICY=PASSIVE`` unless
    set) for the same reason onnxruntime does not spin: on a shared CPU spinning costs more than
    it saves. Imports torch: only for ``depthseg-bench --torch``, never on the edge path.
    """
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    import torch

    from edge.metrics import segmentation_mask
    from edge.preprocess import preprocess_for
    from edge.train.model import build_model

    def runner(seg: Segmenter):
        m = seg.meta
        model = build_model(m).eval()

        def whole(d: np.ndarray) -> tuple[float, float]:
            torch.set_num_threads(seg.threads)
            t0 = time.perf_counter()
            pre = preprocess_for(d, m)
            t1 = time.perf_counter()
            with torch.inference_mode():
                out = model(torch.from_numpy(pre.x[None])).numpy()
            t2 = time.perf_counter()
            h, w = pre.shape
            segmentation_mask(out[0, 0, :h, :w], pre.valid, seg.threshold, seg.min_object_px)
            t3 = time.perf_counter()
            return (t2 - t1) * 1e3, (t3 - t0) * 1e3

        return whole

    runners = [runner(s) for s in segs]
    for r in range(warmup):
        for run in runners:
            run(frames[r % len(frames)])
    inf: list[list[float]] = [[] for _ in segs]
    tot: list[list[float]] = [[] for _ in segs]
    n = len(segs)
    for r in range(runs):
        for k in range(n):
            j = (r + k) % n
            a, b = runners[j](frames[r % len(frames)])
            inf[j].append(a)
            tot[j].append(b)
    out = []
    for seg, i_ms, w_ms in zip(segs, inf, tot):
        si, sw = stats(i_ms), stats(w_ms)
        out.append(
            {
                "torch": torch.__version__,
                "torch_threads": seg.threads,
                "torch_omp_wait_policy": os.environ.get("OMP_WAIT_POLICY", ""),
                "torch_p50_ms": si["p50"],
                "torch_p90_ms": si["p90"],
                "torch_whole_frame_p50_ms": sw["p50"],
                "torch_fps": 1000.0 / sw["mean"],
            }
        )
    return out
