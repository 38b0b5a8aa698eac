#!/usr/bin/env python
"""Time training steps of one architecture in each memory format and precision, interleaved, on this CPU.

Why: the retraining recipe has a 60-minute budget on 2 cores (issue 9), and the step (forward,
backward, Adam) is nearly all of an epoch. The compact models have 8-64 channels at up to full
resolution, where the layout of weights and inputs decides the speed of oneDNN's convolutions.
This tool runs the training loop's own pieces (`edge.train.data.make_batch`,
`edge.train.distributed.Dist.loss`, Adam) with ``--memory-format`` channels_last and contiguous
in alternating blocks, and with ``--precision bf16`` (bfloat16 autocast of the forward pass,
channels-last), so machine drift hits all alike, and prints ms per training frame, each variant's
ratio to the first, and how far the losses are apart after the same steps (the two float32
layouts are the same arithmetic in another order and agree to float rounding; bf16 agrees to
~0.1 %). ``--crops HxW ...`` adds channels-last float32 variants that step on random windows of the
frames, as ``depthseg-train --crop`` does (a step costs about what its pixels cost). The loss is
the recipe's (``--boundary-weight 2``); ``pool_band`` makes its boundary band by two max pools, as
before 2026-12-07 (the same band bit for bit, so the same loss); ``nchw_bn`` runs the batch norms over
at most 8 channels on NCHW copies (``depthseg-train --nchw-bn-channels 8``, `edge.train.layout`).

    .venv/bin/python tools/train_step_bench.py [--data data/val4] [--model edge/models/default.pt]
        [--steps 40] [--block 5] [--batch-size 16] [--threads 2] [--variants channels_last contiguous bf16]
        [--crops 128x160 160x192] [--boundary-weight 2]

Without --data (or when it is missing) the frames are the benchmark's seeded synthetic ones.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


# variant -> (depthseg-train --memory-format, --precision)
VARIANTS = {"channels_last": ("channels_last", "fp32"), "contiguous": ("contiguous", "fp32"),
            "bf16": ("channels_last", "bf16"), "pool_band": ("channels_last", "fp32"),
            "nchw_bn": ("channels_last", "fp32")}
# pool_band: channels_last with the boundary band of the loss made by two max pools, as before
# 2026-12-07 (`edge.train.losses.boundary_band_by_pooling`; the band and the weights are the same bit for bit);
# nchw_bn: channels_last with the batch norms over <= 8 channels on NCHW copies (depthseg-train --nchw-bn-channels 8)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", default="data/val4", help="simulated MCAP folder (default %(default)s)")
    p.add_argument("--frames", type=int, default=256, help="frames loaded from --data (default %(default)s)")
    p.add_argument("--model", default=str(ROOT / "edge" / "models" / "default.pt"),
                   help="checkpoint whose architecture is timed (its weights are not used)")
    p.add_argument("--steps", type=int, default=40, help="timed steps per format (default %(default)s)")
    p.add_argument("--warmup", type=int, default=3, help="untimed steps per format first (default %(default)s)")
    p.add_argument("--block", type=int, default=5, help="consecutive steps of one format per turn")
    p.add_argument("--batch-size", type=int, default=16)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--boundary-weight", type=float, default=2.0,
                   help="the loss's boundary weight, as depthseg-train --boundary-weight (default %(default)s: "
                   "the shipped recipe's; 0 = plain masked BCE)")
    p.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS),
                   help="what to time, in this order; the first is the reference of the ratio column "
                   "(default: all: %(default)s)")
    p.add_argument("--crops", nargs="+", default=[], metavar="HxW",
                   help="also time channels-last float32 steps on random HxW windows (depthseg-train --crop), "
                   "named cropHxW, after the variants")
    args = p.parse_args(argv)

    import torch

    import edge.train.distributed as distributed
    from edge.train.checkpoint import checkpoint_meta, read_checkpoint
    from edge.train.data import FrameSet, load_frames, make_batch
    from edge.train.distributed import Dist
    from edge.train.layout import nchw_batch_norms
    from edge.train.loop import MEMORY_FORMATS, TrainConfig
    from edge.train.losses import boundary_band, boundary_band_by_pooling
    from edge.train.model import build_model

    torch.set_num_threads(args.threads)
    meta = checkpoint_meta(args.model, read_checkpoint(args.model))
    if Path(args.data).exists():
        fs = load_frames([args.data], limit=args.frames)
        source = f"{len(fs)} frames of {args.data}"
    else:
        from edge.sampleframes import synthetic_frames

        sample = synthetic_frames(args.frames, seed=args.seed)
        fs = FrameSet(np.nan_to_num(np.stack(sample.depth)).astype(np.float32), np.stack(sample.label).astype(np.uint8))
        source = f"{len(fs)} synthetic frames (seed {args.seed})"
    dist = Dist()
    rng = np.random.default_rng(args.seed)
    total = args.warmup + args.steps
    batches = [rng.choice(len(fs), args.batch_size, replace=len(fs) < args.batch_size) for _ in range(total)]
    from edge.errors import DepthsegError
    from edge.train.data import check_crop, parse_crop

    try:
        crops = {f"crop{c.lower()}": parse_crop(c) for c in args.crops}
        for c in crops.values():
            check_crop(c, tuple(fs.label.shape[1:]), meta.pad_multiple)
    except DepthsegError as exc:
        print(f"train_step_bench: {exc}", file=sys.stderr)
        return 2
    runs = {}
    for name in dict.fromkeys(list(args.variants) + list(crops)):
        mf, precision = VARIANTS.get(name, VARIANTS["channels_last"])
        fmt = MEMORY_FORMATS[mf]
        torch.manual_seed(args.seed)
        model = build_model(meta).to(memory_format=fmt).train()
        if name == "nchw_bn":
            nchw_batch_norms(model, 8)
        runs[name] = {"name": name, "fmt": fmt, "model": model, "opt": torch.optim.Adam(model.parameters(), lr=1e-3),
                      "autocast": TrainConfig(memory_format=mf, precision=precision).autocast,
                      "precision": precision, "times": [], "loss": float("nan"), "done": 0,
                      "crop": crops.get(name)}

    def step(r: dict, k: int) -> None:
        x, t, m = dist.local(make_batch(fs, batches[k], meta, np.random.default_rng([args.seed, k]), crop=r["crop"]))
        t0 = time.perf_counter()
        with r["autocast"]():
            logits = r["model"](x.contiguous(memory_format=r["fmt"]))
        distributed.boundary_band = boundary_band_by_pooling if r["name"] == "pool_band" else boundary_band
        loss, lv = dist.loss(logits.float(), t, m, boundary=args.boundary_weight)  # as edge.train.loop does
        r["opt"].zero_grad(set_to_none=True)
        loss.backward()
        r["opt"].step()
        if k >= args.warmup:
            r["times"].append(time.perf_counter() - t0)
        r["loss"] = lv

    try:
        while any(r["done"] < total for r in runs.values()):
            for r in runs.values():
                for _ in range(args.block):
                    if r["done"] < total:
                        step(r, r["done"])
                        r["done"] += 1
    finally:  # the band is swapped in the module per step; leave it as the library ships it
        distributed.boundary_band = boundary_band
    print(f"torch {torch.__version__}, {args.threads} threads; {source}; architecture of {args.model} "
          f"({meta.encoder} x{meta.width:g}, {meta.in_channels} ch + cues {list(meta.cues)}); batch {args.batch_size}, "
          f"{args.steps} timed steps per format after {args.warmup} warm-up, alternating blocks of {args.block}; "
          f"boundary weight {args.boundary_weight:g}")
    print("step = forward + loss + backward + Adam, per training frame; the batch preparation (the same for all) is "
          "not included")
    first = None
    print(f"{'variant':<14} {'p50 ms/frame':>12} {'mean':>7} {'min':>7} {'x first':>8} {'last loss':>10}")
    for name, r in runs.items():
        a = np.asarray(r["times"]) * 1000 / args.batch_size
        first = first or float(np.median(a))
        print(f"{name:<14} {np.median(a):>12.2f} {a.mean():>7.2f} {a.min():>7.2f} {np.median(a) / first:>8.2f} "
              f"{r['loss']:>10.5f}")
    if "pool_band" in runs and "channels_last" in runs:
        same = runs["pool_band"]["loss"] == runs["channels_last"]["loss"]
        print(f"pool_band's loss after the same steps {'equals' if same else 'DIFFERS from'} channels_last's")
    fp32 = [r["loss"] for r in runs.values() if r["precision"] == "fp32" and r["crop"] is None
            and r["name"] in ("channels_last", "contiguous")]
    if "nchw_bn" in runs and "channels_last" in runs:
        rel = abs(runs["nchw_bn"]["loss"] / runs["channels_last"]["loss"] - 1)
        print(f"nchw_bn's loss after the same steps differs from channels_last's by {rel:.1e} (float rounding)")
    if len(fp32) == 2:
        print(f"loss after {total} identical steps differs by {abs(fp32[0] - fp32[1]):.2e} between the layouts "
              "(float rounding)")
    if "bf16" in runs and fp32:
        rel = abs(runs["bf16"]["loss"] / fp32[0] - 1)
        print(f"the loss of bf16 after the same steps differs from float32's by {100 * rel:.2f} % (8-bit mantissa)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
