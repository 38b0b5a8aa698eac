#!/usr/bin/env python
"""Digests of everything the edge path computes, to prove a speed-up changed no value.

Why: `tools/bench_preprocess.py --against REV` checks the network input of 55 frames; a change of
the postprocessing, the plane fit's refinement or the valid mask needs more: the masks the user
gets, on more frames, from both shipped models and with the height rule, on frames a driver can
send. This hashes, per frame, the valid mask, the fitted plane, the input tensor and its
statistics, and the published mask of the default, of the fast option and of the default with
``--min-height-mm 10``; on 40 frames of each of up to eight sets and three hostile variants of each
(40 saturated 16UC1 pixels, 97 % of the pixels dead, a third of the frame NaN). Torch-free.

``--root DIR`` imports the ``edge`` package of another checkout (a ``git worktree`` of the old
revision), so both sides run the same frames through their own code:

    git worktree add /tmp/old 4901867
    .venv/bin/python tools/edge_path_digest.py --root /tmp/old --out /tmp/old.json
    .venv/bin/python tools/edge_path_digest.py --compare /tmp/old.json     # exit 1 if any differ
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parents[1]
SETS = ("data/test_default", "data/test_tray", "data/test_table_edge", "data/test_tilted", "data/test_crisp",
        "data/test_empty", "data/blensor.mcap", "data/royale_lab.mcap")


def _variants(d: np.ndarray, rng: np.random.Generator) -> list[np.ndarray]:
    sat = d.copy()
    sat[rng.integers(0, d.shape[0], 40), rng.integers(0, d.shape[1], 40)] = 65.535
    dead = d.copy()
    dead[rng.random(d.shape) < 0.97] = 0
    nan = d.copy()
    nan[:, : d.shape[1] // 3] = np.nan
    return [d, sat, dead, nan]


def _h(a) -> str:
    a = np.ascontiguousarray(a)
    return hashlib.sha256(str(a.dtype).encode() + str(a.shape).encode() + a.tobytes()).hexdigest()[:16]


def digests(root: Path, per_set: int, sets: list[Path]) -> dict[str, str]:
    """{"set:frame:variant:what": digest} with the ``edge`` package of ``root``.

    Args:
        root: the checkout whose ``edge`` package computes (its first import wins).
        per_set: frames read from each set.
        sets: MCAP files or directories; missing ones are skipped.
    """
    sys.path.insert(0, str(root))
    from edge import cues as C
    from edge import preprocess as P
    from edge.infer import Segmenter
    from edge.sampleframes import load_frames

    models = HERE / "edge" / "models"
    segs = {"default": Segmenter(models / "default.onnx"), "fast": Segmenter(models / "fast.onnx"),
            "default+rule": Segmenter(models / "default.onnx", min_height_m=0.01)}
    meta = segs["default"].meta
    rng = np.random.default_rng(0)
    out: dict[str, str] = {}
    for s in sets:
        if not s.exists():
            continue
        tag = s.resolve().relative_to(HERE) if s.resolve().is_relative_to(HERE) else s  # the same key from any root
        for i, d in enumerate(load_frames(s, per_set).depth):
            for j, v in enumerate(_variants(np.asarray(d), rng)):
                key = f"{tag}:{i}:{j}"
                valid = P.valid_for(v, meta)
                fit = C.fit_dominant_plane(v, valid)
                pre = P.preprocess_for(v, meta)
                out[key + ":valid"] = _h(valid)
                out[key + ":plane"] = _h(np.array([fit.a, fit.b, fit.c, fit.ok, fit.inlier_share]))
                out[key + ":x"] = _h(pre.x)
                out[key + ":stats"] = _h(np.array([pre.mean, pre.std]))
                for name, seg in segs.items():
                    out[f"{key}:mask:{name}"] = _h(seg.predict(v).mask)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, default=HERE, help="checkout whose edge package runs (default: this one)")
    ap.add_argument("--data", type=Path, nargs="+", default=[HERE / s for s in SETS],
                    help="sets to read (default: eight held-out, BlenSor and real sets under data/)")
    ap.add_argument("--frames-per-set", type=int, default=40, help="frames of each set (default 40)")
    ap.add_argument("--out", type=Path, default=None, help="write the digests here (JSON)")
    ap.add_argument("--compare", type=Path, default=None, help="digests of the other side; exit 1 if any differ")
    args = ap.parse_args(argv)
    got = digests(args.root.resolve(), args.frames_per_set, args.data)
    if args.out is not None:
        tmp = args.out.with_suffix(args.out.suffix + ".tmp")
        tmp.write_text(json.dumps(got, indent=0, sort_keys=True))
        tmp.replace(args.out)
    frames = len({k.rsplit(":", 2)[0] for k in got if k.endswith(":x")})  # source frames, 4 variants each
    if args.compare is None:
        print(f"{len(got)} digests of {frames} frames x 4 variants")
        return 0
    other = json.loads(args.compare.read_text())
    keys = sorted(set(got) | set(other))
    differ = [k for k in keys if got.get(k) != other.get(k)]
    print(f"{len(keys)} digests of {frames} frames x 4 variants: {len(differ)} differ" + (f" (first: {differ[:5]})" if differ else ""))
    return 1 if differ else 0


if __name__ == "__main__":
    raise SystemExit(main())
