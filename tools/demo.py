"""`make demo`: the main job on the shipped defaults, end to end, in about a minute.

1. simulate a short labelled recording (seed 2026, never used in training),
2. replay it through the shipped single-channel ONNX model (the edge path: no torch),
   writing an MCAP with mask and overlay topics for Foxglove,
3. evaluate the same frames against the RANSAC floor-plane baseline and draw Fig. 5-style
   overlays a person can open.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "out" / "demo"


def step(title: str) -> None:
    print(f"\n== {title}", flush=True)


def main() -> int:
    from edge.defaults import DEFAULT_ONNX
    from edge.eval_cli import main as eval_main
    from replay.cli import main as replay_main
    from sim.cli import main as sim_main

    OUT.mkdir(parents=True, exist_ok=True)
    sim_dir = OUT / "sim"
    step(f"simulating 60 labelled pico flexx frames -> {sim_dir.relative_to(ROOT)}")
    rc = sim_main(["--out", str(sim_dir), "--frames", "60", "--seed", "2026", "--workers", "2",
                   "--shard-frames", "60"])
    if rc:
        return rc
    rec = sorted(sim_dir.glob("*.mcap"))[0]
    step(f"replaying {rec.relative_to(ROOT)} through {DEFAULT_ONNX.relative_to(ROOT)}")
    out_mcap = OUT / "replay.mcap"
    rc = replay_main([str(rec), "--model", str(DEFAULT_ONNX), "--out", str(out_mcap), "--threads", "2"])
    if rc:
        return rc
    step("evaluating against the RANSAC floor-plane baseline (Fig. 5-style overlays)")
    figs = OUT / "figures"
    rc = eval_main(["--model", str(DEFAULT_ONNX), "--data", str(sim_dir), "--baseline", "--figures", str(figs),
                    "--max-figures", "6"])
    if rc:
        return rc
    step("open these")
    print(f"  overlays:  {figs.relative_to(ROOT)}/*.png")
    print(f"  recording: {out_mcap.relative_to(ROOT)} (Foxglove: /depthseg/overlay, /depthseg/mask)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
