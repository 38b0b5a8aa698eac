#!/usr/bin/env python
"""Where an exported model's inference time goes: onnxruntime's own per-node profile.

Runs the model ``--runs`` times on one seeded random input of the model's sensor size (padded),
with the edge session options (`edge.infer.session_options`), and prints each node's median
kernel time, largest first, with its share of the sum. The node names are onnxruntime's after
its graph optimisations (``*_nchwc``: its blocked layout; ``ReorderOutput``: a layout change), so
this shows what the CPU provider really runs. It found the head fold (`export.fold`, BENCHMARKS.md).

    .venv/bin/python tools/ort_profile.py [MODEL.onnx] [--runs 200] [--threads 2] [--top 25] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from edge.infer import session_options  # noqa: E402
from edge.meta import ModelMeta  # noqa: E402
from edge.preprocess import padded_shape  # noqa: E402


def profile(model: Path, runs: int = 200, threads: int = 2) -> list[dict]:
    """One row per node: ``node``, ``op``, ``median_us``, ``share`` (of the sum of medians), largest first."""
    import onnxruntime as ort

    with tempfile.TemporaryDirectory(prefix="depthseg-ortprof-") as td:
        so = session_options(threads)
        so.enable_profiling = True
        so.profile_file_prefix = str(Path(td) / "prof")
        sess = ort.InferenceSession(str(model), so, providers=["CPUExecutionProvider"])
        meta = ModelMeta.from_onnx_props(dict(sess.get_modelmeta().custom_metadata_map))
        inp = sess.get_inputs()[0]
        s = meta.sensor
        if len(inp.shape) == 3:  # a --with-preprocessing graph takes the raw frame
            shape: tuple[int, ...] = (1, s.height, s.width)
        else:
            shape = (1, meta.net_channels, *padded_shape(s.height, s.width, meta.pad_multiple))
        x = np.random.default_rng(0).uniform(0.2, 0.5, shape).astype(np.float32)
        for _ in range(runs):
            sess.run(None, {inp.name: x})
        events = json.loads(Path(sess.end_profiling()).read_text())
    times: dict[tuple[str, str], list[float]] = defaultdict(list)
    for e in events:
        if e.get("cat") == "Node" and e.get("name", "").endswith("_kernel_time"):
            times[(e["name"][: -len("_kernel_time")], e["args"].get("op_name", "?"))].append(float(e["dur"]))
    rows = [{"node": n, "op": op, "median_us": float(np.median(v))} for (n, op), v in times.items()]
    total = sum(r["median_us"] for r in rows) or 1.0
    for r in rows:
        r["share"] = r["median_us"] / total
    return sorted(rows, key=lambda r: -r["median_us"])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", nargs="?", type=Path, default=ROOT / "edge/models/default.onnx")
    ap.add_argument("--runs", type=int, default=200, help="profiled runs (default 200)")
    ap.add_argument("--threads", type=int, default=2, help="intra-op threads (default 2)")
    ap.add_argument("--top", type=int, default=25, help="rows to print (default 25)")
    ap.add_argument("--json", action="store_true", help="print all rows as JSON")
    args = ap.parse_args(argv)
    if not args.model.is_file():
        print(f"ort_profile: {args.model}: no such model file; give an exported .onnx", file=sys.stderr)
        return 2
    if args.runs < 1 or args.threads < 1:
        print("ort_profile: --runs and --threads must be >= 1", file=sys.stderr)
        return 2
    rows = profile(args.model, args.runs, args.threads)
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    total = sum(r["median_us"] for r in rows)
    print(f"{args.model}: {len(rows)} nodes, sum of per-node medians {total:.0f} us ({args.runs} runs, {args.threads} threads)")
    for r in rows[: args.top]:
        print(f"{r['median_us']:8.1f} us {100 * r['share']:5.1f} %  {r['op']:<20} {r['node']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
