#!/usr/bin/env python
"""Time the edge preprocessing of a model (`edge.preprocess.preprocess_for`), stage by stage.

Why a tool of its own: preprocessing is a third of the whole frame, and `depthseg-bench` shows it
as one number. This prints the p50 of each stage (valid mask, robust standardisation, dominant
plane fit, height cue, the whole call), and with ``--against REV`` times the same call of the
code at git revision REV interleaved with the working tree's on the same frames, and checks
that both give byte-identical input tensors (a speed-up must not change what the model sees).

    .venv/bin/python tools/bench_preprocess.py                       # stages, shipped model
    .venv/bin/python tools/bench_preprocess.py --against 0f2112e     # old vs new, interleaved
"""

from __future__ import annotations

import argparse
import importlib
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from edge import cues as C  # noqa: E402
from edge import preprocess as P  # noqa: E402
from edge.infer import Segmenter  # noqa: E402
from edge.sampleframes import sample_frames  # noqa: E402

SETS = ("data/test_default", "data/test_tray", "data/blensor.mcap", "data/royale_lab.mcap")


def _frames(per_set: int) -> list[np.ndarray]:
    out: list[np.ndarray] = []
    for s in SETS:
        if (ROOT / s).exists():
            out += sample_frames(ROOT / s, per_set, 0).depth
    return out or sample_frames(None, 8, 0).depth


def _hostile(frames: list[np.ndarray]) -> list[np.ndarray]:
    """Frames a driver can send: 40 saturated 16UC1 pixels (65.535 m), all NaN but a few, constant."""
    rng = np.random.default_rng(0)
    out = []
    for d in frames[:10]:
        sat = d.copy()
        sat[rng.integers(0, d.shape[0], 40), rng.integers(0, d.shape[1], 40)] = 65.535
        few = np.full_like(d, np.nan)
        few[5:7, 5:9] = 0.3
        out += [sat, few, np.full_like(d, 0.35)]
    return out


def _p50(fn, frames: list[np.ndarray], runs: int) -> float:
    ts = []
    for r in range(runs):
        d = frames[r % len(frames)]
        t0 = time.perf_counter()
        fn(d)
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts) * 1e3)


def _old_preprocess(rev: str, td: Path):
    """The ``edge.preprocess`` module of revision ``rev``, importing its own ``edge.cues``."""
    pkg = td / "oldedge"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    for name in ("cues", "preprocess"):
        src = subprocess.run(["git", "show", f"{rev}:edge/{name}.py"], cwd=ROOT, check=True, capture_output=True,
                             text=True).stdout
        (pkg / f"{name}.py").write_text(src.replace("from edge.cues import", "from oldedge.cues import"))
    sys.path.insert(0, str(td))
    return importlib.import_module("oldedge.preprocess")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default=None, help="ONNX model whose metadata says how to preprocess (default: shipped)")
    ap.add_argument("--runs", type=int, default=2000, help="timed calls per variant (default 2000)")
    ap.add_argument("--against", metavar="REV", default=None, help="git revision to compare with, interleaved")
    ap.add_argument("--frames-per-set", type=int, default=8,
                    help="frames taken from each data set (default 8); the identity check adds 30 hostile frames")
    args = ap.parse_args()
    meta = Segmenter(args.model, threads=1).meta
    frames = _frames(args.frames_per_set)
    print(f"{len(frames)} frames ({', '.join(s for s in SETS if (ROOT / s).exists()) or 'synthetic'}); "
          f"p50 of {args.runs} calls, ms")
    valid = lambda d: P.valid_for(d, meta)  # noqa: E731
    stages = {
        "valid mask": valid,
        "robust mean/std": lambda d: C.robust_mean_std(d, valid(d), P.STD_FLOOR),
        "standardise": lambda d: P.standardize(d, valid(d), meta.standardize),
        "plane fit": lambda d: C.fit_dominant_plane(d, valid(d)),
        "height cue": lambda d: C.height_cue(d, valid(d)),
        "preprocess_for": lambda d: P.preprocess_for(d, meta),
    }
    for name, fn in stages.items():
        print(f"  {name:16s} {_p50(fn, frames, args.runs):.3f}")
    if args.against is None:
        return 0
    with tempfile.TemporaryDirectory() as td:
        old = _old_preprocess(args.against, Path(td))
        checked = frames + _hostile(frames)
        same = all(np.array_equal(old.preprocess_for(d, meta).x, P.preprocess_for(d, meta).x) for d in checked)
        ts: dict[str, list[float]] = {"old": [], "new": []}
        for r in range(args.runs):
            d = frames[r % len(frames)]
            order = (("old", old), ("new", P)) if r % 2 else (("new", P), ("old", old))
            for name, mod in order:
                t0 = time.perf_counter()
                mod.preprocess_for(d, meta)
                ts[name].append(time.perf_counter() - t0)
    o, n = (float(np.median(ts[k]) * 1e3) for k in ("old", "new"))
    print(f"preprocess_for, interleaved: {args.against} {o:.3f} ms, working tree {n:.3f} ms, ratio {n / o:.2f}; "
          f"input tensors {'byte-identical' if same else 'DIFFER'} on all {len(checked)} frames "
          f"({len(checked) - len(frames)} of them hostile)")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
