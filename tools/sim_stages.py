"""Per-stage cost of the simulator in one process: scene draw, physics, ray cast, sensor, MCAP write.

    .venv/bin/python tools/sim_stages.py --frames 200 --config tools/views4.json --json

Both wall time and CPU time (``time.process_time``) are reported per frame: on a shared machine
the wall time of a stage grows with the load, its CPU time much less, so CPU time is the number
to compare between runs, and ``2 / cpu_s_per_frame`` what two free cores could make (the upper
bound of ``depthseg-sim --workers 2``). Stages are timed by wrapping the functions
`sim.generate` calls; "ray cast" is open3d's ``cast_rays`` inside `sim.render.render` (BVH build
included), "render other" the rest of the render (analytic floor, candidate pixels, edges).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

STAGES = ("scene", "physics", "render", "ray cast", "sensor", "mcap write")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=200)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--config", help="depthseg-sim --config JSON")
    p.add_argument("--json", action="store_true")
    a = p.parse_args(argv)

    import open3d as o3d

    import sim.generate as G
    import sim.render as R
    from edge.io import FrameWriter

    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    cfg = G.SimConfig.from_dict(json.loads(Path(a.config).read_text())) if a.config else G.SimConfig()
    wall = dict.fromkeys(STAGES, 0.0)
    cpu = dict.fromkeys(STAGES, 0.0)

    def timed(mod, name, key):
        f = getattr(mod, name)

        def g(*args, **kw):
            t, c = time.perf_counter(), time.process_time()
            try:
                return f(*args, **kw)
            finally:
                wall[key] += time.perf_counter() - t
                cpu[key] += time.process_time() - c

        setattr(mod, name, g)

    timed(G, "sample_scene", "scene")
    timed(G, "drop", "physics")
    timed(G, "render", "render")
    timed(R, "_cast", "ray cast")
    timed(G, "apply_sensor", "sensor")
    timed(FrameWriter, "write", "mcap write")
    timed(FrameWriter, "close", "mcap write")
    for i in range(3):  # warm-up: imports, ray grids, MuJoCo
        G.generate_frame(10**6 + i, a.seed, cfg)
    for d in (wall, cpu):
        for k in d:
            d[k] = 0.0
    t0, c0 = time.perf_counter(), time.process_time()
    with tempfile.TemporaryDirectory() as tmp, FrameWriter(Path(tmp) / "f.mcap") as fw:
        for i in range(a.frames):
            f = G.generate_frame(i, a.seed, cfg)
            fw.write(f.stamp_ns, f.depth, f.label, f.intrinsics, f.clean, f.scene, f.distortion)
    total_w, total_c = time.perf_counter() - t0, time.process_time() - c0
    n = a.frames
    for d in (wall, cpu):
        d["render other"] = d.pop("render") - d["ray cast"]
        d["rest"] = (total_w if d is wall else total_c) - sum(d.values())
    out = {
        "frames": n,
        "views_per_scene": cfg.scene.views_per_scene,
        "wall_ms_per_frame": round(1000 * total_w / n, 2),
        "cpu_ms_per_frame": round(1000 * total_c / n, 2),
        "stages_wall_ms": {k: round(1000 * v / n, 2) for k, v in wall.items()},
        "stages_cpu_ms": {k: round(1000 * v / n, 2) for k, v in cpu.items()},
        "frames_per_second_1_process": round(n / total_w, 1),
        "cpu_bound_frames_per_second_2_cores": round(2 * n / total_c, 1),
        "loadavg_1min": float(Path("/proc/loadavg").read_text().split()[0]) if Path("/proc/loadavg").exists() else None,
    }
    if a.json:
        print(json.dumps(out))
    else:
        print(f"{n} frames, views_per_scene {out['views_per_scene']}: {out['wall_ms_per_frame']} ms/frame wall, "
              f"{out['cpu_ms_per_frame']} ms CPU (load {out['loadavg_1min']})")
        for k in wall:
            print(f"  {k:13s} {out['stages_wall_ms'][k]:7.2f} ms wall  {out['stages_cpu_ms'][k]:7.2f} ms CPU")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
