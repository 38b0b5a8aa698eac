"""A simulated dataset: labelled pico flexx frames in sharded MCAP files, written in parallel (``depthseg-sim``).

Why shards of whole frames: shard k holds frames [k*K, (k+1)*K) and is written by one worker
through `edge.io.FrameWriter`, which writes a temporary file and renames it only when
complete. A killed run therefore leaves complete shards (kept) and temporary files (deleted
and regenerated on resume); since frame i depends only on (seed, i), a resumed run produces
exactly the frames an uninterrupted one would: none lost, none duplicated.

``manifest.json`` in the output folder records the seed, shard size, configuration (and its
digest) and the mesh library, so a resume with different options is refused instead of mixing
two datasets, plus per-shard statistics for the summary.

`simulate` is the library call; `sim.cli` parses the flags and prints.
"""

from __future__ import annotations

import json
import os
import queue
import re
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from edge.cliutil import progress
from edge.errors import ConfigError, DataError
from edge.provenance import provenance

__all__ = ["simulate", "shard_name", "plan_shards", "MANIFEST"]

TOOL = "depthseg-sim"  # recorded in the manifest

MANIFEST = "manifest.json"
_SHARD_RE = re.compile(r"^frames_(\d{8})_(\d{8})\.mcap$")
_TMP_RE = re.compile(r"^\.frames_\d{8}_\d{8}\.mcap\.\d+\.tmp$")


def shard_name(start: int, stop: int) -> str:
    return f"frames_{start:08d}_{stop:08d}.mcap"


def plan_shards(frames: int, shard_frames: int) -> list[tuple[int, int]]:
    """[start, stop) of every shard: shard k holds frames [k*K, min((k+1)*K, N))."""
    return [(s, min(s + shard_frames, frames)) for s in range(0, frames, shard_frames)]


# --------------------------------------------------------------------------- worker side

_W: dict[str, Any] = {}


def _init_worker(config_dict: dict, seed: int, library_paths: list[str] | None, out: str, q, pooled: bool = True) -> None:
    from sim.generate import SimConfig
    from sim.shapes import MeshLibrary

    if pooled:
        os.dup2(2, 1)  # native-library chatter in a worker goes to stderr: stdout is for --json
    import open3d as o3d

    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)

    _W["config"] = SimConfig.from_dict(config_dict)
    _W["seed"] = seed
    _W["library"] = MeshLibrary([Path(p) for p in library_paths]) if library_paths else None
    _W["out"] = Path(out)
    _W["queue"] = q


def _write_shard(task: tuple[int, int]) -> dict[str, Any]:
    """Generate frames [start, stop) into one shard; the file appears only when complete."""
    import numpy as np

    from edge.io import FrameWriter
    from sim.generate import generate_frame

    start, stop = task
    t0 = time.perf_counter()
    obj = inv = pix = 0
    path = _W["out"] / shard_name(start, stop)
    with FrameWriter(path) as fw:
        for i in range(start, stop):
            f = generate_frame(i, _W["seed"], _W["config"], _W["library"])
            fw.write(f.stamp_ns, f.depth, f.label, f.intrinsics, f.clean, f.scene, f.distortion)
            obj += int(f.label.sum())
            inv += int(np.count_nonzero(f.depth == 0))
            pix += f.label.size
            if _W["queue"] is not None:
                _W["queue"].put(1)
    return {
        "file": path.name,
        "frames": stop - start,
        "object_pixels": obj,
        "invalid_pixels": inv,
        "pixels": pix,
        "seconds": round(time.perf_counter() - t0, 3),
    }


# --------------------------------------------------------------------------- main side


def _write_json_atomic(path: Path, obj: Any) -> None:
    from edge.io import write_json_atomic

    write_json_atomic(path, obj, indent=1)


def _prepare_out(out: Path) -> None:
    if out.exists() and not out.is_dir():
        raise ConfigError(f"`out` {out}: exists and is not a folder; choose a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"`out` {out}: cannot create the folder ({exc.strerror}); choose a writable path") from None
    if not os.access(out, os.W_OK | os.X_OK):
        raise ConfigError(f"`out` {out}: folder is not writable; choose a writable path")


def _check_manifest(out: Path, ident: dict[str, Any]) -> dict[str, Any]:
    """The previous manifest if it describes the same dataset; raise if it does not."""
    path = out / MANIFEST
    if not path.exists():
        if any(_SHARD_RE.match(p.name) for p in out.iterdir()):
            raise ConfigError(f"`out` {out}: holds frame shards but no {MANIFEST}; use an empty folder")
        return {}
    try:
        old = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise DataError(f"{path}: unreadable manifest ({exc}); delete the folder or choose another `out`") from None
    for key in ("seed", "shard_frames", "config_digest", "objects"):
        if old.get(key) != ident[key]:
            raise ConfigError(
                f"`out` {out} holds frames made with a different {key} ({old.get(key)!r} vs {ident[key]!r}); "
                "resume with the same options or choose another `out`"
            )
    return old


def _stats_of_shard(path: Path) -> dict[str, Any]:
    """Statistics of a complete shard, read back (its wall time is unknown)."""
    import numpy as np

    from edge.io import iter_frames

    n = obj = inv = pix = 0
    for f in iter_frames(path):
        n += 1
        obj += int(f.label.sum())
        inv += int(np.count_nonzero(f.depth == 0))
        pix += f.label.size
    return {"file": path.name, "frames": n, "object_pixels": obj, "invalid_pixels": inv, "pixels": pix,
            "seconds": None}


def simulate(
    out: str | Path,
    frames: int,
    seed: int = 0,
    workers: int = 1,
    config: Any = None,
    objects: str | Path | None = None,
    shard_frames: int = 100,
    on_warning: Callable[[str], None] | None = None,
    show_progress: bool | None = None,
    ray: str | None = None,
    frames_range: tuple[int, int] | None = None,
) -> dict[str, Any]:
    """Generate (or finish) a dataset; returns the summary. All validation raises ConfigError.

    ``ray``: run the shards as Ray tasks ("" = a local Ray with ``workers`` CPUs, else a cluster
    address; `sim.ray_runner`). ``frames_range`` (start, stop): make only the shards in it, for
    array jobs; its bounds must fall on shard boundaries (see `sim.frames_range`).
    """
    import multiprocessing as mp

    from sim.generate import FRAME_PERIOD_NS, SimConfig
    from sim.shapes import MeshLibrary

    if int(frames) < 1:
        raise ConfigError(f"`frames` must be at least 1, got {frames}")
    if int(shard_frames) < 1:
        raise ConfigError(f"`shard_frames` must be at least 1, got {shard_frames}")
    if int(workers) < 1:
        raise ConfigError(f"--workers must be at least 1, got {workers}")
    if int(seed) < 0:
        raise ConfigError(f"--seed must be a non-negative integer, got {seed}")
    config = config or SimConfig()
    out = Path(out)
    if ray is not None:
        from sim.ray_runner import import_ray

        import_ray()  # before touching --out: a missing extra is a one-line error
    if frames_range is not None:
        from sim.frames_range import check_range

        check_range(frames_range, int(frames), int(shard_frames))
    library_paths: list[str] | None = None
    skipped: list[str] = []
    if objects is not None:

        def skip(p: Path, reason: str) -> None:
            skipped.append(p.name)
            if on_warning is not None:
                on_warning(f"skipping mesh {reason}")

        lib = MeshLibrary.scan(objects, on_skip=skip)
        library_paths = [str(p) for p in lib.paths]
    _prepare_out(out)
    ident = {
        "seed": int(seed),
        "shard_frames": int(shard_frames),
        "config_digest": config.digest(),
        "objects": None if library_paths is None else sorted(Path(p).name for p in library_paths),
    }
    old = _check_manifest(out, ident)
    plan = plan_shards(int(frames), int(shard_frames))
    wanted = {shard_name(a, b) for a, b in plan}
    removed = 0
    if frames_range is not None:  # an array job: touch only its own shards and temporary files
        from sim.frames_range import in_range, tmp_in_range

        plan = [(a, b) for a, b in plan if in_range((a, b), frames_range)]
        for p in out.iterdir():
            if tmp_in_range(p.name, frames_range):
                p.unlink(missing_ok=True)
    else:
        for p in out.iterdir():
            if _TMP_RE.match(p.name):  # left by a killed run: never complete, regenerate
                p.unlink(missing_ok=True)
            elif _SHARD_RE.match(p.name) and p.name not in wanted:  # from a run of another length
                p.unlink(missing_ok=True)
                removed += 1
    done = {p.name for p in out.iterdir() if p.name in {shard_name(a, b) for a, b in plan}}
    todo = [(a, b) for a, b in plan if shard_name(a, b) not in done]
    if frames_range is None:
        from sim.frames_range import merge_part_stats

        old = dict(old, shards=merge_part_stats(out, old.get("shards") or {}))
    shard_stats: dict[str, dict] = {k: v for k, v in (old.get("shards") or {}).items() if k in done}
    for name in sorted(done - set(shard_stats)):  # completed, but the run died before recording it
        shard_stats[name] = _stats_of_shard(out / name)
    manifest = {
        "tool": TOOL,
        **ident,
        "frames": int(frames),
        "frame_period_ns": FRAME_PERIOD_NS,
        "config": config.to_dict(),
        "objects_folder": None if objects is None else str(objects),
        "objects_skipped": skipped,
        "provenance": provenance(),  # depthseg version and git commit that wrote it
        "shards": shard_stats,
    }
    manifest_path = out / MANIFEST
    if frames_range is not None:  # jobs of one array share manifest.json: each writes its own part
        from sim.frames_range import part_name, write_identity_once

        write_identity_once(out / MANIFEST, {k: v for k, v in manifest.items() if k != "shards"} | {"shards": {}},
                            _write_json_atomic)
        manifest_path = out / part_name(frames_range)
        manifest["frames_range"] = list(frames_range)
    _write_json_atomic(manifest_path, manifest)

    n_todo = sum(b - a for a, b in todo)
    t0 = time.perf_counter()
    if todo:
        ctx = mp.get_context("spawn")  # no fork after open3d/MuJoCo threads exist
        q = ctx.Queue()
        bar = progress(total=int(frames), initial=int(frames) - n_todo, desc=TOOL, unit="frame", disable=None if show_progress is None else not show_progress)
        stop = threading.Event()

        def pump() -> None:
            while not stop.is_set():
                try:
                    bar.update(q.get(timeout=0.2))
                except queue.Empty:
                    continue
                except (EOFError, OSError):
                    return

        th = threading.Thread(target=pump, daemon=True)
        th.start()

        def record(stats: dict[str, Any]) -> None:
            shard_stats[stats["file"]] = stats
            manifest["shards"] = shard_stats
            _write_json_atomic(manifest_path, manifest)
            if ray is not None:
                bar.update(stats["frames"])

        try:
            if ray is not None:
                from sim.ray_runner import run_shards

                run_shards(todo, config.to_dict(), int(seed), library_paths, str(out), record,
                           address=ray or None, workers=int(workers))
            elif int(workers) == 1:  # in this process: no start-up cost for small runs and tests
                _init_worker(config.to_dict(), int(seed), library_paths, str(out), q, pooled=False)
                for task in todo:
                    record(_write_shard(task))
            else:
                with ctx.Pool(
                    min(int(workers), len(todo)),
                    initializer=_init_worker,
                    initargs=(config.to_dict(), int(seed), library_paths, str(out), q),
                ) as pool:
                    for stats in pool.imap_unordered(_write_shard, todo):
                        record(stats)
        finally:
            stop.set()
            th.join(timeout=1.0)
            bar.close()
        if frames_range is None:  # complete: what is left was written by killed (and retried) workers
            from sim.frames_range import remove_orphan_tmp

            remove_orphan_tmp(out)
    seconds = time.perf_counter() - t0
    pix = sum(s["pixels"] for s in shard_stats.values())
    summary = {
        "out": str(out),
        "frames": int(frames),
        "generated": n_todo,
        "resumed_shards": len(done),
        "removed_stale_shards": removed,
        "shards": len(plan),
        "workers": int(workers),
        **({"ray": ray or "local"} if ray is not None else {}),
        **({"frames_range": list(frames_range)} if frames_range is not None else {}),
        "seed": int(seed),
        "seconds": round(seconds, 3),
        "frames_per_second": round(n_todo / seconds, 2) if n_todo and seconds > 0 else 0.0,
        "object_pixel_fraction": round(sum(s["object_pixels"] for s in shard_stats.values()) / pix, 4) if pix else None,
        "invalid_pixel_fraction": round(sum(s["invalid_pixels"] for s in shard_stats.values()) / pix, 4) if pix else None,
        "objects_skipped": len(skipped),
    }
    manifest["summary"] = summary
    _write_json_atomic(manifest_path, manifest)
    return summary
