"""A simulated dataset: labelled pico flexx frames in sharded MCAP files, written in parallel (``depthseg-sim``).

Why shards of whole frames: shard k holds frames [k*K, (k+1)*K) and is written by one worker
through `edge.io.FrameWriter`, which writes a temporary file and renames it only when
complete. A killed run therefore leaves complete shards (kept) and temporary files (deleted
and regenerated on resume); since frame i depends only on (seed, i), a resumed run produces
exactly the frames an uninterrupted one would: none lost, none duplicated.

``manifest.json`` in the output folder records the seed, shard size, configuration (and its
digest) and the mesh library, so a resume with different options is refused instead of mixing
two datasets, plus per-shard statistics for the summary. It also records the versions of the
libraries whose arithmetic makes the frames (`engines`): a drop of a dozen objects is chaotic,
so mujoco 3.14, 3.17 and 4.0 settle the same seed's scene differently (measured 2026-12-01),
and a resume under other versions would mix two datasets under one seed.

`simulate` is the library call; `sim.cli` parses the flags and prints.
"""

from __future__ import annotations

import json
import os
import queue
import re
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from edge.cliutil import progress
from edge.errors import ConfigError, DataError
from edge.provenance import provenance

__all__ = ["simulate", "shard_name", "iter_shards", "check_size", "usable_cores", "engines", "engine_mismatch",
           "MANIFEST", "MAX_FRAMES", "MAX_SHARDS"]

TOOL = "depthseg-sim"  # recorded in the manifest
SIM_EXTRA = "install the simulator extra: pip install 'depthseg[sim]'"

MANIFEST = "manifest.json"
_SHARD_RE = re.compile(r"^frames_(\d{8})_(\d{8})\.mcap$")
_TMP_RE = re.compile(r"^\.frames_\d{8}_\d{8}\.mcap\.\d+\.tmp$")


ENGINES = ("mujoco", "open3d", "numpy", "scipy")  # the libraries a frame's numbers depend on


def engines() -> dict[str, str]:
    """Installed version of each of `ENGINES` (``"absent"`` when not installed)."""
    from importlib.metadata import PackageNotFoundError, version

    out: dict[str, str] = {}
    for name in ENGINES:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "absent"
    return out


def engine_mismatch(recorded: Any) -> tuple[str, str, str] | None:
    """The first of `ENGINES` whose version in ``recorded`` differs from the installed one, as
    ``(name, recorded, installed)``; None when all agree or nothing usable was recorded.

    One rule for both places frames could mix: a resumed folder (`_check_manifest`) and a Ray
    node (`sim.ray_runner`). A manifest from before the versions were recorded says nothing.

    Args:
        recorded: a ``{library: version}`` mapping (the manifest's or the driver's ``engines``).
    """
    if not isinstance(recorded, dict):
        return None
    here = engines()
    for name in ENGINES:
        if name in recorded and str(recorded[name]) != here[name]:
            return name, str(recorded[name]), here[name]
    return None


def shard_name(start: int, stop: int) -> str:
    return f"frames_{start:08d}_{stop:08d}.mcap"


# Shard names hold 8-digit frame numbers, and the manifest keeps one entry per shard: both bound
# a dataset (a bigger one is several --out folders with different seeds).
MAX_FRAMES = 99_999_999
MAX_SHARDS = 100_000
MANIFEST_EVERY_S = 10.0  # rewrite the manifest at most this often while shards complete
MAX_SEED = 2**128


def iter_shards(frames: int, shard_frames: int, start: int = 0, stop: int | None = None) -> Iterator[tuple[int, int]]:
    """[start, stop) of each shard lying in frames [start, stop), one at a time (nothing O(frames)).

    Shard k holds frames [k*K, min((k+1)*K, N)) for ``shard_frames`` K and ``frames`` N.
    """
    stop = frames if stop is None else stop
    for s in range(start, stop, shard_frames):
        yield s, min(s + shard_frames, frames)


def check_size(frames: int, shard_frames: int) -> None:
    """Refuse a dataset larger than the shard names and the manifest can describe."""
    if frames > MAX_FRAMES:
        raise ConfigError(
            f"`frames` {frames} is above the limit of {MAX_FRAMES} frames per output folder (8-digit shard "
            "names); split the dataset into several `out` folders, each with its own `seed`"
        )
    shards = -(-frames // shard_frames)
    if shards > MAX_SHARDS:
        raise ConfigError(
            f"`frames` {frames} in shards of `shard_frames` {shard_frames} makes {shards} shards, above the limit "
            f"of {MAX_SHARDS} (one manifest entry each); raise `shard_frames` to at least {-(-frames // MAX_SHARDS)}"
        )


def usable_cores() -> int:
    """CPUs this process may run on (its affinity mask, as a container or taskset sets it)."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return max(os.cpu_count() or 1, 1)


# --------------------------------------------------------------------------- worker side

_W: dict[str, Any] = {}


def _init_worker(config_dict: dict, seed: int, library_paths: list[str] | None, out: str, q, pooled: bool = True) -> None:
    """Set up a worker: its config, mesh library, output folder and progress queue.

    In a pool (`sim.workers`) a missing open3d becomes the one-line error naming the extra,
    which the parent prints; in this process (``pooled=False``) the import error is the caller's.
    """
    try:
        _setup_worker(config_dict, seed, library_paths, out, q, pooled)
    except ImportError as exc:
        if not pooled:
            raise
        raise ConfigError(f"a worker cannot import {exc.name or 'a module'} ({exc}); {SIM_EXTRA}") from None


def _setup_worker(config_dict: dict, seed: int, library_paths: list[str] | None, out: str, q, pooled: bool) -> None:
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
                _W["queue"].put(task)  # which shard: a retried shard's frames are not counted twice
    return {
        "file": path.name,
        "frames": stop - start,
        "object_pixels": obj,
        "invalid_pixels": inv,
        "pixels": pix,
        "seconds": round(time.perf_counter() - t0, 3),
    }


# --------------------------------------------------------------------------- main side


def count_frame_once(counted: dict[int, int], task: tuple[int, int]) -> bool:
    """Whether a frame reported by a worker for shard ``task`` = (start, stop) is new progress.

    A killed worker's shard is made again from its first frame (`sim.workers`), so its first
    frames are reported twice; counting at most ``stop - start`` per shard keeps the progress
    bar at or below the total. ``counted`` maps shard start to frames counted so far.
    """
    start, stop = task
    n = counted.get(start, 0) + 1
    counted[start] = n
    return n <= stop - start


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


def _planned(name: str, frames: int, shard_frames: int) -> tuple[int, int] | None:
    """(start, stop) if ``name`` is a shard of this dataset's plan, else None."""
    m = _SHARD_RE.match(name)
    if m is None:
        return None
    a, b = int(m.group(1)), int(m.group(2))
    ok = a % shard_frames == 0 and a < frames and b == min(a + shard_frames, frames)
    return (a, b) if ok else None


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
    bad = engine_mismatch(old.get("engines"))
    if bad is not None:
        name, was, now = bad
        raise ConfigError(
            f"`out` {out} holds frames made with {name} {was}, this is {name} {now}, and its frames would "
            f"differ; resume with pip install '{name}=={was}' or choose another `out`"
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
        raise ConfigError(f"`workers` must be at least 1, got {workers}")
    if int(seed) < 0:
        raise ConfigError(f"`seed` must be a non-negative integer, got {seed}")
    if int(seed) >= MAX_SEED:
        raise ConfigError(f"`seed` must be below 2**128, got a number of {len(str(int(seed)))} digits")
    frames, shard_frames, workers, seed = int(frames), int(shard_frames), int(workers), int(seed)
    check_size(frames, shard_frames)
    if not ray:  # a local pool or a local Ray: more processes than cores only cost memory
        cores = usable_cores()
        if workers > cores:
            if on_warning is not None:
                on_warning(f"`workers` {workers} capped at the {cores} usable cores")
            workers = cores
    config = config or SimConfig()
    if not str(out).strip():
        raise ConfigError("`out` is empty; name the output folder")
    out = Path(out)
    if ray is not None:
        from sim.ray_runner import check_address, import_ray

        import_ray()  # before touching --out: a missing extra is a one-line error
        if ray:
            check_address(ray)  # an address nobody answers on: one line now, not Ray's ten minutes of retries
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
        "engines": engines(),
    }
    old = _check_manifest(out, ident)
    lo, hi = (0, frames) if frames_range is None else frames_range
    n_plan = -(-(hi - lo) // shard_frames)  # lo is on a shard boundary; hi on one or at the end
    removed = 0
    if frames_range is not None:  # an array job: touch only its own shards and temporary files
        from sim.frames_range import tmp_in_range

        for p in out.iterdir():
            if tmp_in_range(p.name, frames_range):
                p.unlink(missing_ok=True)
    else:
        for p in out.iterdir():
            if _TMP_RE.match(p.name):  # left by a killed run: never complete, regenerate
                p.unlink(missing_ok=True)
            elif _SHARD_RE.match(p.name) and _planned(p.name, frames, shard_frames) is None:  # another length
                p.unlink(missing_ok=True)
                removed += 1
    done: set[str] = set()
    n_done = 0
    for p in out.iterdir():
        shard = _planned(p.name, frames, shard_frames)
        if shard is not None and lo <= shard[0] and shard[1] <= hi:
            done.add(p.name)
            n_done += shard[1] - shard[0]
    todo = (t for t in iter_shards(frames, shard_frames, lo, hi) if shard_name(*t) not in done)  # lazy
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

    n_todo = (hi - lo) - n_done
    t0 = time.perf_counter()
    if n_todo:
        ctx = mp.get_context("spawn")  # no fork after open3d/MuJoCo threads exist
        q = ctx.Queue()
        bar = progress(total=int(frames), initial=int(frames) - n_todo, desc=TOOL, unit="frame", disable=None if show_progress is None else not show_progress)
        stop = threading.Event()

        counted: dict[int, int] = {}  # frames counted per shard start (<= MAX_SHARDS entries)

        def pump() -> None:
            while not stop.is_set():
                try:
                    task = q.get(timeout=0.2)  # (start, stop) of the frame's shard
                except queue.Empty:
                    continue
                except (EOFError, OSError):
                    return
                if count_frame_once(counted, task):
                    bar.update(1)

        th = threading.Thread(target=pump, daemon=True)
        th.start()

        last_write = [time.monotonic()]

        def record(stats: dict[str, Any]) -> None:
            shard_stats[stats["file"]] = stats
            manifest["shards"] = shard_stats
            # Throttled: with many small shards, rewriting the manifest per shard would cost more
            # than the frames. A shard completed but not yet recorded is read back on resume.
            if time.monotonic() - last_write[0] >= MANIFEST_EVERY_S:
                _write_json_atomic(manifest_path, manifest)
                last_write[0] = time.monotonic()
            if ray is not None:
                bar.update(stats["frames"])

        try:
            if ray is not None:
                from sim.ray_runner import run_shards

                run_shards(todo, config.to_dict(), seed, library_paths, str(out), record,
                           address=ray or None, workers=workers)
            elif workers == 1:  # in this process: no start-up cost for small runs and tests
                _init_worker(config.to_dict(), seed, library_paths, str(out), q, pooled=False)
                for task in todo:
                    record(_write_shard(task))
            else:
                from sim.workers import run_tasks

                for stats in run_tasks(ctx, workers, _write_shard, todo, initializer=_init_worker,
                                       initargs=(config.to_dict(), seed, library_paths, str(out), q),
                                       on_retry=on_warning):
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
        "shards": n_plan,
        "workers": workers,
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
