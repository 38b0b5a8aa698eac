"""``depthseg-sim``: parse the flags, call `sim.dataset.simulate`, print the summary.

``depthseg-sim import ...`` dispatches to `sim.importers` (BlenSor scans and royaleviewer PLY
captures into the same MCAP layout).
"""

from __future__ import annotations

import argparse
import json
import os
import sys

from edge.cliutil import add_version, cli_message, flag_names, print_json, require, run
from edge.errors import ConfigError
from edge.io.paths import check_input_file, check_output_dir
from sim.dataset import MANIFEST, simulate
from sim.frames_range import parse_range

__all__ = ["main"]

PROG = "depthseg-sim"


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description=(
            "Generate labelled PMD pico flexx depth frames: random objects (paper Table I) dropped with "
            "MuJoCo, ray-cast with open3d, passed through a ToF sensor model, written as ROS 2 MCAP "
            "(depth 32FC1 m 0=invalid, labels mono8 1=object, camera_info, clean depth, scene JSON). "
            "Frame i depends only on (--seed, i); an interrupted run resumes when restarted with the same "
            "options. 'depthseg-sim import ...' converts BlenSor scans and royaleviewer PLY captures."
        ),
    )
    add_version(p, PROG)
    p.add_argument("--out", required=True, help="output folder (created); shards frames_<start>_<stop>.mcap + manifest.json")
    p.add_argument("--frames", type=int, required=True, help="number of frames in the dataset")
    p.add_argument("--seed", type=int, default=0, help="dataset seed (default 0); same seed, same frames")
    p.add_argument("--workers", type=int, default=max(len(os.sched_getaffinity(0)), 1), help="worker processes (default: all cores)")
    p.add_argument("--objects", help="folder of .obj/.stl/.off/.ply meshes to drop instead of the procedural shapes "
                   "(scene.library_fraction sets the share); unreadable files are reported and skipped")
    p.add_argument("--shard-frames", type=int, default=100, help="frames per MCAP shard (default 100, ~25 MB)")
    p.add_argument("--config", help="JSON file overriding settings: {\"scene\": {...}, \"physics\": {...}, "
                   "\"sensor\": {...}, \"camera\": {\"fx\":..., \"distortion\": [k1,k2,p1,p2,k3]}}; see sim/scene.py, "
                   "sim/physics.py, sim/sensor.py for every key")
    p.add_argument("--ray", nargs="?", const="", metavar="ADDRESS",
                   help="run the shards as Ray tasks, one shard a task: on the cluster at ADDRESS (e.g. 'auto' or "
                        "'ray://head:10001'; --out must be a shared folder) or, without ADDRESS, on a local Ray with "
                        "--workers CPUs. Same frames as --workers. Needs the extra: pip install 'depthseg[ray]'")
    p.add_argument("--frames-range", metavar="A:B",
                   help="make only the shards of frames [A, B) (A, B on shard boundaries; B may be --frames), for "
                        "array jobs of a batch scheduler writing into one --out; a last run without it writes the "
                        "complete manifest")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    return p


SIM_MODULES = ("open3d", "mujoco", "scipy")  # the 'sim' extra (pyproject.toml optional-dependencies)


MAX_CONFIG_BYTES = 1 << 20  # a simulator config is a few hundred bytes; more is not a config


def _load_config(path: str | None):
    """The `SimConfig` of ``--config``: a JSON object in a small UTF-8 text file, else one line."""
    from sim.generate import SimConfig

    if path is None:
        return SimConfig()
    p = check_input_file(path, "config")
    size = p.stat().st_size
    if size > MAX_CONFIG_BYTES:
        raise ConfigError(f"`config` {p}: {size} bytes is too large for a simulator config (limit {MAX_CONFIG_BYTES})")
    try:
        text = p.read_bytes().decode("utf-8")
    except UnicodeDecodeError:
        raise ConfigError(f"`config` {p}: not a UTF-8 text file; give a JSON file") from None
    try:
        d = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ConfigError(f"`config` {p}: not valid JSON ({exc})") from None
    except RecursionError:
        raise ConfigError(f"`config` {p}: JSON nested too deeply to be a simulator config") from None
    except ValueError:  # Python refuses integers of more than 4300 digits
        raise ConfigError(f"`config` {p}: holds a number too long to be a setting") from None
    if not isinstance(d, dict):
        kind = {list: "an array", str: "a string", type(None): "null", bool: "a boolean"}.get(type(d), "a number")
        raise ConfigError(f"`config` {p}: must hold a JSON object {{\"scene\": ...}}, not {kind}")
    return SimConfig.from_dict(d)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "import":
        from sim.importers import import_main  # owned by the importers; loaded only when asked

        return import_main(argv[1:])
    parser = _parser()
    args = parser.parse_args(argv)

    flags = flag_names(parser)

    def warn(message: str) -> None:
        print(f"{PROG}: warning: {cli_message(message, flags)}", file=sys.stderr)

    def body() -> int:
        require("sim", SIM_MODULES, "the simulator", load=False)  # workers import them
        config = _load_config(args.config)
        # The folder's manifest stands for every file written into it (shards share its folder).
        check_output_dir(args.out, "out", {"config": args.config, "objects": args.objects}, probes=(MANIFEST,))
        summary = simulate(
            out=args.out,
            frames=args.frames,
            seed=args.seed,
            workers=args.workers,
            config=config,
            objects=args.objects,
            shard_frames=args.shard_frames,
            ray=args.ray,
            frames_range=None if args.frames_range is None else parse_range(args.frames_range),
            on_warning=warn,
        )
        if args.json:
            print_json(summary)
        else:
            s = summary
            opf = "n/a" if s["object_pixel_fraction"] is None else f"{100 * s['object_pixel_fraction']:.1f} %"
            ipf = "n/a" if s["invalid_pixel_fraction"] is None else f"{100 * s['invalid_pixel_fraction']:.1f} %"
            print(
                f"{PROG}: {s['frames']} frames in {s['out']} ({s['generated']} generated, {s['resumed_shards']} "
                f"shards kept) in {s['seconds']:.1f} s = {s['frames_per_second']:.1f} frames/s with "
                f"{s['workers']} workers; object pixels {opf}, invalid pixels {ipf}"
            )
        return 0

    return run(PROG, body, parser)


if __name__ == "__main__":
    sys.exit(main())
