"""Whole training runs with frames preprocessed once against per batch, interleaved, on this CPU.

Why whole runs: the two modes differ in what happens around the training steps (preprocessing
before the first epoch, or in every batch of every epoch), which a step timer does not see
(`tools/train_step_bench.py` times forward + backward + Adam only). So this runs
`depthseg-train` itself, in this process, with the shipped recipe's flags, alternating the modes
``--repeats`` times so that a machine that speeds up or slows down affects both alike, and reports
the wall time of each run and its training epochs (``epoch_seconds`` of log.csv: the steps plus
validation, without loading and preprocessing).

    .venv/bin/python tools/preprocess_once_bench.py --data data/val4 --epochs 2 --repeats 3
"""

from __future__ import annotations

import argparse
import csv
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

RECIPE = ["--encoder", "vgg11", "--batch-norm", "--width", "0.125", "--in-channels", "3", "--cues", "height",
          "--standardize", "robust", "--extra-skip", "--full-skip", "--split", "0.85,0.1,0.05", "--split-unit",
          "frame", "--batch-size", "16", "--lr", "1e-3", "--lr-schedule", "cosine", "--seed", "0", "--ema", "0.999"]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", default="data/val4", help="simulated MCAP folder (default %(default)s)")
    p.add_argument("--frames", type=int, default=1000, help="frames loaded (--limit; default %(default)s)")
    p.add_argument("--epochs", type=int, default=2)
    p.add_argument("--repeats", type=int, default=3, help="runs of each mode, alternating (default %(default)s)")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--warmup", type=int, default=1, help="untimed runs first, one of each mode (default "
                   "%(default)s): the first run in a process pays imports and oneDNN's kernel set-up")
    args = p.parse_args(argv)
    if not Path(args.data).exists():
        print(f"preprocess_once_bench: no data at {args.data}; simulate some first, e.g. "
              f"depthseg-sim --out {args.data} --frames 1000 --seed 3", file=sys.stderr)
        return 2
    from edge.train_cli import main as train_main

    modes = ("per-batch", "once")
    wall: dict[str, list[float]] = {m: [] for m in modes}
    epochs: dict[str, list[float]] = {m: [] for m in modes}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(-args.warmup, args.repeats):
            for mode in modes:
                out = Path(tmp) / f"{mode}-{r}"
                t0 = time.perf_counter()
                rc = train_main(["--data", args.data, "--limit", str(args.frames), "--out", str(out), "--epochs",
                                 str(args.epochs), "--patience", str(args.epochs), "--threads", str(args.threads),
                                 "--preprocess", mode, *RECIPE])
                if rc != 0:
                    return rc
                if r < 0:
                    continue
                wall[mode].append(time.perf_counter() - t0)
                with open(out / "log.csv") as f:
                    epochs[mode].append(sum(float(row["epoch_seconds"]) for row in csv.DictReader(f)))
    print(f"{args.frames} frames of {args.data}, {args.epochs} epochs, {args.threads} threads, the shipped recipe; "
          f"{args.repeats} runs of each mode, alternating, after {args.warmup} untimed")
    print(f"{'mode':<10} {'run s (median)':>15} {'epochs s':>9}  runs")
    for m in modes:
        print(f"{m:<10} {np.median(wall[m]):>15.1f} {np.median(epochs[m]):>9.1f}  "
              + " ".join(f"{v:.1f}" for v in wall[m]))
    print(f"ratio once / per-batch: whole run x{np.median(wall['once']) / np.median(wall['per-batch']):.3f}, "
          f"epochs x{np.median(epochs['once']) / np.median(epochs['per-batch']):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
