#!/usr/bin/env python
"""The README results table: a model against the plane-fit baseline on every held-out data set.

Why one tool: issue 9 asks for one row per data set (fresh frames of our own simulator, each
scene family where a plane fit fails, crisp-edge frames, the paper's BlenSor scans, the real
capture with geometric labels), model vs baseline, with the error breakdown near boundaries.
Each row is a plain ``depthseg-eval --baseline --json`` run, so every number can be rerun
alone with the command printed under the table. ``--make-data`` first creates the data sets
that are missing (simulated from seed 2 or 4, never used in training or tuning; BlenSor and
the real capture are imported from ``../shared/data``).

    .venv/bin/python tools/results_table.py [--model M] [--make-data] [--only NAME ...] [--out FILE.md]
    .venv/bin/python tools/results_table.py --min-height-mm 10   # the model with the height rule on

``--min-height-mm`` passes the minimum-object-height rule to every ``depthseg-eval`` run (the
model's masks only; `edge.postprocess.remove_low_parts`): the meaning of the real capture's labels.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BIN = ROOT / ".venv" / "bin"
SHARED = ROOT.parent / "shared" / "data"
FAMILIES = ROOT / "tools" / "scene_families"
CRISP = ROOT / "tools" / "test_configs" / "crisp_edges.json"
BLURRED = ROOT / "tools" / "test_configs" / "blurred_edges.json"
ONE_VIEW = ROOT / "tools" / "test_configs" / "one_view.json"  # test sets: one camera pose a scene, as made


def _sim(out: str, frames: int, seed: int, config: Path | None = None) -> list[str]:
    cmd = [str(BIN / "depthseg-sim"), "--out", out, "--frames", str(frames), "--seed", str(seed), "--workers", "2"]
    return cmd + (["--config", str(config.relative_to(ROOT))] if config else [])


# (name, data path, command(s) that make it, run in order)
DATASETS: list[tuple[str, str, list[str]] | tuple[str, str, list[str], list[str]]] = [
    ("own sim, fresh frames (default config)", "data/test_default", _sim("data/test_default", 1000, 2, ONE_VIEW)),
    ("crisp-edge sim (no PSF, no mixed pixels)", "data/test_crisp", _sim("data/test_crisp", 300, 4, CRISP)),
    ("blurred-edge sim (PSF 0.7-1.1 px, the old fit)", "data/test_blurred", _sim("data/test_blurred", 300, 4, BLURRED)),
    *[
        (f"family: {f.replace('_', ' ')}", f"data/test_{f}", _sim(f"data/test_{f}", 300, 2, FAMILIES / f"{f}.json"))
        for f in ("thin", "table_edge", "tilted", "curved", "tray", "stacked", "long")
    ],
    (
        "unseen household-like shapes (bowls, plates, mugs, bottles, fruit, spoons, stars, ...)",
        "data/test_household",
        [str(BIN / "python"), "tools/household_meshes.py", "data/household_meshes"],
        _sim("data/test_household", 300, 2, ONE_VIEW) + ["--objects", "data/household_meshes"],
    ),
    (
        "own sim, labelled by the real capture's rule (> 10 mm above the floor plane)",
        "data/test_default_geo10.mcap",
        [str(BIN / "python"), "tools/relabel_geometric.py", "data/test_default", "data/test_default_geo10.mcap"],
    ),
    (
        "BlenSor scans (the 10 in ../shared)",
        "data/blensor.mcap",
        [str(BIN / "depthseg-sim"), "import", "blensor", str(SHARED / "blensor"), "--out", "data/blensor.mcap"],
    ),
    (
        "real pico flexx capture, labels > 10 mm above the floor plane",
        "data/royale_lab.mcap",
        [str(BIN / "depthseg-sim"), "import", "ply", str(SHARED / "royale"), "--out", "data/royale_lab.mcap",
         "--label-above-plane", "10"],
    ),
]

BREAKDOWN = ("fp_boundary", "fp_far", "fn_boundary", "fn_far")


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.2f}"


def evaluate(model: str | None, data: str, threshold: float | None, min_height_mm: float | None = None) -> dict:
    cmd = [str(BIN / "depthseg-eval"), "--data", data, "--baseline", "--json"]
    if min_height_mm is not None:
        cmd += ["--min-height-mm", f"{min_height_mm:g}"]
    if model:
        cmd += ["--model", model]
    if threshold is not None:
        cmd += ["--threshold", str(threshold)]
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(f"results_table: {' '.join(cmd)} failed: {res.stderr.strip().splitlines()[-1:]}")
    return json.loads(res.stdout)


def row(name: str, r: dict) -> str:
    b = r["baseline"]
    m_bd, b_bd = r.get("breakdown", {}), b.get("breakdown", {})
    margin = 100 * (r["iou"] - b["iou"])
    return (
        f"| {name} | {r['frames']} | **{_pct(r['iou'])}** | {_pct(b['iou'])} | {margin:+.2f} | "
        f"{_pct(r['pooled_iou'])} | {_pct(b['pooled_iou'])} | "
        + " / ".join(_pct(m_bd.get(k)) for k in BREAKDOWN)
        + " | "
        + " / ".join(_pct(b_bd.get(k)) for k in BREAKDOWN)
        + " |"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", help="model file (default: the shipped model)")
    ap.add_argument("--threshold", type=float, help="decision boundary (default: the model's stored one)")
    ap.add_argument("--min-height-mm", type=float, metavar="MM",
                    help="the model's minimum object height for every row (default: the model's rule)")
    ap.add_argument("--make-data", action="store_true", help="create missing data sets first")
    ap.add_argument("--only", nargs="+", metavar="PREFIX", help="only data sets whose name starts with one of these")
    ap.add_argument("--out", type=Path, help="also write the markdown table here")
    args = ap.parse_args(argv)
    lines = [
        "| data set | frames | model IoU | plane-fit IoU | margin | model pooled IoU | plane-fit pooled IoU "
        "| model FP near / FP far / FN near / FN far | plane-fit FP near / FP far / FN near / FN far |",
        "|---|---:|---:|---:|---:|---:|---:|---|---|",
    ]
    for name, path, *makes in DATASETS:
        if args.only and not any(name.startswith(p) for p in args.only):
            continue
        if not (ROOT / path).exists():
            if not args.make_data:
                how = " && ".join(" ".join(m) for m in makes)
                print(f"skipping '{name}': {path} is missing (make it with --make-data or: {how})", file=sys.stderr)
                continue
            for make in makes:
                subprocess.run(make, cwd=ROOT, check=True, stdout=subprocess.DEVNULL)
        lines.append(row(name, evaluate(args.model, path, args.threshold, args.min_height_mm)))
        print(lines[-1], flush=True)
    text = "\n".join(lines) + "\n"
    print("\n" + text)
    if args.out:
        tmp = args.out.with_suffix(args.out.suffix + ".tmp")
        tmp.write_text(text)
        tmp.replace(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
