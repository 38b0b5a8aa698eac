"""Relabel a recording by the geometric rule used for the real capture's labels.

Why: the real pico flexx frames have no hand labels; their labels come from a rule ("object =
more than 10 mm above the RANSAC floor plane", `depthseg-sim import ply --label-above-plane 10`).
That rule and the simulator's labels (which object a ray hit) disagree by design at the base of
every object (its side surfaces less than 10 mm above the table) and on objects thinner than
10 mm. Applying the *same* rule to held-out simulated frames measures, on data we may choose
models by, what the real-capture check measures; the real frames stay a report-once number.

    .venv/bin/python tools/relabel_geometric.py data/test_crisp data/test_crisp_geo10 --above-plane-mm 10

Writes a new recording (the depth, intrinsics and scene of every frame; labels replaced; no clean
depth) and prints how many object pixels the rule moved. Needs the `baseline` extra (open3d).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from edge.baseline import Intrinsics, PlaneBaseline  # noqa: E402
from edge.cliutil import run  # noqa: E402
from edge.errors import DataError  # noqa: E402
from edge.io import FrameWriter, open_frames  # noqa: E402
from edge.io.paths import check_outputs  # noqa: E402
from edge.preprocess import valid_mask  # noqa: E402


def relabel(data: Path, out: Path, above_plane_m: float, limit: int | None = None) -> dict[str, float]:
    """Write ``out``: the frames of ``data`` labelled by `PlaneBaseline` at ``above_plane_m``.

    Args:
        data: a labelled recording (file or folder).
        out: the new recording (.mcap file).
        above_plane_m: the rule's height threshold in metres (the real capture: 0.010).
        limit: stop after this many frames (None = all).

    Returns:
        Frame count and, over valid pixels, the share of simulator-object pixels the rule calls
        table and of simulator-table pixels it calls object.
    """
    check_outputs({"out": out}, {"data": data})
    frames, _ = open_frames(data)
    labeller = PlaneBaseline(height_threshold_m=above_plane_m)
    n = obj = obj_lost = tab = tab_gained = 0
    with FrameWriter(out) as wr:
        for f in frames:
            if limit is not None and n >= limit:
                break
            if f.info is None or f.label is None:
                raise DataError(f"{data}: frame {n} has no camera info or labels; relabel a labelled recording with intrinsics")
            k = (f.info["fx"], f.info["fy"], f.info["cx"], f.info["cy"])
            geo = labeller.predict(f.depth, Intrinsics(*k)).astype(np.uint8)
            valid = valid_mask(f.depth)
            sim = (f.label == 1) & valid
            obj += int(sim.sum())
            obj_lost += int((sim & (geo == 0)).sum())
            tab += int(((f.label == 0) & valid).sum())
            tab_gained += int(((f.label == 0) & valid & (geo == 1)).sum())
            scene = dict(f.scene or {})
            scene["labels"] = f"geometric: > {above_plane_m * 1000:g} mm above the RANSAC floor plane"
            wr.write(f.stamp_ns, f.depth, label=geo, intrinsics=k, scene=scene)
            n += 1
    return {
        "frames": n,
        "object_to_table_pct": 100.0 * obj_lost / max(obj, 1),
        "table_to_object_pct": 100.0 * tab_gained / max(tab, 1),
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="relabel_geometric", description=__doc__.split("\n\n")[0])
    p.add_argument("data", type=Path, help="labelled recording (file or folder)")
    p.add_argument("out", type=Path, help="new recording (.mcap)")
    p.add_argument("--above-plane-mm", type=float, default=10.0, help="height threshold (default 10, the real capture's)")
    p.add_argument("--limit", type=int, default=None, help="first N frames only")
    args = p.parse_args(argv)

    def body() -> int:
        s = relabel(args.data, args.out, args.above_plane_mm / 1000.0, args.limit)
        print(
            f"{s['frames']} frames -> {args.out}; the rule calls {s['object_to_table_pct']:.2f} % of simulated object "
            f"pixels table and {s['table_to_object_pct']:.2f} % of table pixels object"
        )
        return 0

    return run("relabel_geometric", body, p)


if __name__ == "__main__":
    sys.exit(main())
